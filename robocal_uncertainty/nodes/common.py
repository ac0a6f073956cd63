"""What the three nodes share: robot model and campaign file lookup, message conversion, the
per-cause throttled log and the ``main`` loop. The sample store the calibration and
uncertainty nodes rebuild their campaign from is ROS-free and lives in
:mod:`robocal_uncertainty.pipeline.sample_store` (re-exported here).

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
from robocal_uncertainty.errors import CalibError
from robocal_uncertainty.pipeline.sample_store import SampleStore

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
