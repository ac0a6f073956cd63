"""What the three nodes share: robot model and campaign file lookup, the sample store the
calibration and uncertainty nodes rebuild their campaign from, message conversion, the
per-cause throttled log and the ``main`` loop.

Where the downstream nodes get their samples (the documented choice): the collector records
every sample to the campaign MCAP *before* publishing it on ``robocal/samples``. The
calibration and uncertainty nodes subscribe to ``robocal/samples`` and, at start, also read
the campaign file (read-only; a file still being written reads up to its last complete
pose). Samples are keyed by their stamp, so a sample seen both ways counts once, and a node
started late or restarted still has every sample taken so far. Both nodes order samples by
stamp, so "the first n samples" names the same campaign in both.
"""

from __future__ import annotations

import os
import sys
import warnings
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from robocal_uncertainty.core import load_robot_model
from robocal_uncertainty.core.robot_config import resolve_robot_config
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.sample import CalibrationSample
from robocal_uncertainty.errors import CalibError, InputError
from robocal_uncertainty.pipeline.calibration_pipeline import CalibrationPipeline

__all__ = [
    "CauseLogger",
    "SampleStore",
    "campaign_file",
    "load_model",
    "robot_config_path",
    "run_node",
    "stamp_ns",
    "to_ros",
]

_NS_PER_S = 1_000_000_000
DEFAULT_CAMPAIGN = Path("robocal") / "campaign.mcap"
"""Campaign file below ``$ROS_HOME`` (default ``~/.ros``) when ``campaign_path`` is empty."""


def robot_config_path(name: str) -> Path:
    """A robot YAML path, or the name of a shipped model; see :func:`resolve_robot_config`."""
    return resolve_robot_config(name)


def load_model(robot_config: str, *, base_unknown: bool = False) -> RobotModel:
    """Load the robot model; `base_unknown` forces identification of the base transform."""
    model = load_robot_model(robot_config_path(robot_config))
    if base_unknown:
        from dataclasses import replace

        model = replace(model, base_known=False)
    return model


def campaign_file(text: str) -> Path:
    """The campaign MCAP path of a ``campaign_path`` parameter ("" = the default)."""
    if text.strip():
        return Path(text).expanduser().resolve()
    home = os.environ.get("ROS_HOME") or str(Path("~/.ros").expanduser())
    return (Path(home) / DEFAULT_CAMPAIGN).resolve()


def stamp_ns(header: Any) -> int:
    """``header.stamp`` in ns."""
    return int(header.stamp.sec) * _NS_PER_S + int(header.stamp.nanosec)


def to_ros(source: Any, ros_type: type) -> Any:
    """Copy a rosbags message (see :mod:`robocal_uncertainty.bagio.messages`) into the
    rosidl-generated class `ros_type`, field by field (nested messages recursively)."""
    out = ros_type()
    for name in ros_type.get_fields_and_field_types():
        value = getattr(source, name)
        current = getattr(out, name)
        if hasattr(type(current), "get_fields_and_field_types"):
            setattr(out, name, to_ros(value, type(current)))
        elif isinstance(value, np.ndarray):
            if value.dtype == np.bool_:
                setattr(out, name, [bool(v) for v in value])
            else:
                setattr(out, name, value.tolist())
        elif isinstance(value, (list, tuple)):
            setattr(out, name, list(value))
        else:
            setattr(out, name, value)
    return out


class CauseLogger:
    """Warn at most once per `period_s` (wall time) per cause, each cause on its own.

    rclpy's ``throttle_duration_sec`` keys its memory on the call site and the logger
    object, so each cause gets a child logger (``<node>.<cause>``) of its own.
    """

    def __init__(self, node: Node, period_s: float) -> None:
        self._node = node
        self.period_s = float(period_s)
        self._loggers: dict[str, Any] = {}

    def warning(self, cause: str, message: str) -> None:
        logger = self._loggers.get(cause)
        if logger is None:
            logger = self._loggers[cause] = self._node.get_logger().get_child(cause)
        logger.warning(message, throttle_duration_sec=self.period_s)


class SampleStore:
    """Calibration samples keyed by stamp: from the campaign file and from the topic.

    Parameters
    ----------
    model : RobotModel
        Samples must carry exactly its joints.
    """

    def __init__(self, model: RobotModel) -> None:
        self.model = model
        self._samples: dict[int, CalibrationSample] = {}
        self._frame_id: str | None = None
        self.duplicates = 0
        self.refused = 0

    def __len__(self) -> int:
        return len(self._samples)

    @property
    def latest_stamp_ns(self) -> int | None:
        return max(self._samples) if self._samples else None

    def add(self, sample: CalibrationSample) -> bool:
        """Add a sample; False for one already held (same stamp).

        Raises
        ------
        InputError
            Other joints than the model's, or another frame than the samples held.
        """
        if sample.stamp_ns in self._samples:
            self.duplicates += 1
            return False
        if set(sample.joint_names) != set(self.model.joint_names):
            self.refused += 1
            msg = f"sample joints {list(sample.joint_names)} differ from the model's {list(self.model.joint_names)}"
            raise InputError(msg)
        if self._frame_id is not None and sample.frame_id != self._frame_id:
            self.refused += 1
            msg = f"sample in frame {sample.frame_id!r}, the campaign is in {self._frame_id!r}"
            raise InputError(msg)
        self._frame_id = sample.frame_id
        self._samples[sample.stamp_ns] = sample
        return True

    def load_campaign_file(self, path: Path) -> tuple[int, tuple[str, ...]]:
        """Add the poses of a campaign MCAP (read-only); returns (added, reader warnings).

        A pose carries no per-reading statistics: it becomes a sample with the point
        covariance diag(point_std^2) (so ``point_std`` is the recorded one exactly),
        zero joint scatter and counts of 1.
        """
        from robocal_uncertainty.bagio.campaign_mcap import read_campaign

        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            campaign = read_campaign(path)
        if campaign.stamps_ns is None:
            msg = f"campaign {path} has no pose stamps; cannot merge it with live samples"
            raise InputError(msg)
        added = 0
        for i in range(campaign.n_poses):
            std = np.zeros(3) if campaign.point_std is None else campaign.point_std[i]
            sample = CalibrationSample(
                stamp_ns=int(campaign.stamps_ns[i]),
                frame_id=campaign.frame_id,
                joint_names=campaign.joint_names,
                joint_positions=campaign.joint_positions[i],
                joint_position_std=np.zeros(len(campaign.joint_names)),
                point=campaign.points[i],
                point_covariance=np.diag(np.square(std)),
                joint_state_count=1,
                tracker_point_count=1,
            )
            added += self.add(sample)
        return added, tuple(str(w.message) for w in caught)

    def first(self, n: int | None = None) -> list[CalibrationSample]:
        """The `n` earliest samples (all when None), in stamp order."""
        stamps = sorted(self._samples)
        if n is not None:
            stamps = stamps[:n]
        return [self._samples[s] for s in stamps]

    def pipeline(self, n: int | None = None, **options: Any) -> CalibrationPipeline:
        """A fresh in-memory :class:`CalibrationPipeline` of the `n` earliest samples."""
        return self.pipeline_of(self.model, self.first(n), **options)

    @staticmethod
    def pipeline_of(model: RobotModel, samples: Iterable[CalibrationSample], **options: Any) -> CalibrationPipeline:
        """A fresh in-memory :class:`CalibrationPipeline` (`options` as its keywords) of `samples`."""
        pipeline = CalibrationPipeline(model, **options)
        for sample in samples:
            pipeline.add_sample(sample)
        return pipeline


def run_node(factory: Callable[[], Node], args: Iterable[str] | None = None) -> int:
    """Init, build the node, spin until Ctrl-C or shutdown, clean up; the exit status.

    A :class:`CalibError` while building the node (bad parameter, missing robot file)
    ends it with its message and status 1.
    """
    rclpy.init(args=args)
    node = None
    status = 0
    try:
        node = factory()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except CalibError as err:
        print(f"[FATAL] {err}", file=sys.stderr)
        status = 1
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return status
