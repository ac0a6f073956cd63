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
import signal
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from visualization_msgs.msg import Marker, MarkerArray

from robocal_uncertainty.core.robot_formats import load_robot_source, robot_format_of
from robocal_uncertainty.core.robot_formats.robot_yaml import resolve_robot_config
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.errors import CalibError, ConfigError
from robocal_uncertainty.pipeline.diagnostics import DiagnosticStatus as Status
from robocal_uncertainty.pipeline.markers import MarkerSpec
from robocal_uncertainty.pipeline.sample_store import SampleStore

__all__ = [
    "CauseLogger",
    "SampleStore",
    "campaign_file",
    "diagnostic_array",
    "load_model",
    "marker_array",
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
    """Load the robot model of a node without chain parameters (a robot YAML or a shipped model
    name, read by the package's one robot loader); `base_unknown` forces identification of the
    base transform.

    A URDF is refused here: its chain ends and measured point are parameters of the calibration
    node only, and a URDF read with default ones could silently be another chain than the one
    the calibration node reads.
    """
    if robot_format_of(robot_config).chain_ends:
        msg = (
            f"robot_config {robot_config} is a URDF, which this node does not read: give it a robot YAML or a "
            "shipped model name (the calibration node reads a URDF, with base_link and tip_link)"
        )
        raise ConfigError(msg)
    return load_robot_source(robot_config, base_known=False if base_unknown else None).model


def campaign_file(text: str) -> Path:
    """The campaign MCAP path of a ``campaign_path`` parameter ("" = the default)."""
    if text.strip():
        return Path(text).expanduser().resolve()
    home = os.environ.get("ROS_HOME") or str(Path("~/.ros").expanduser())
    return (Path(home) / DEFAULT_CAMPAIGN).resolve()


def stamp_ns(header: Any) -> int:
    """``header.stamp`` in ns."""
    return int(header.stamp.sec) * _NS_PER_S + int(header.stamp.nanosec)


def to_ros(source: Any, ros_type: Any) -> Any:
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


def diagnostic_array(node: Node, statuses: Iterable[Status]) -> DiagnosticArray:
    """``diagnostic_msgs/DiagnosticArray`` of ROS-free statuses, stamped now (node clock)."""
    out = DiagnosticArray()
    out.header.stamp = node.get_clock().now().to_msg()
    for status in statuses:
        item = DiagnosticStatus()
        item.level = bytes([int(status.level)])
        item.name = status.name
        item.message = status.message
        item.hardware_id = status.hardware_id
        item.values = [KeyValue(key=key, value=value) for key, value in status.values]
        out.status.append(item)
    return out


_MARKER_TYPES = {"sphere": Marker.SPHERE, "sphere_list": Marker.SPHERE_LIST, "text": Marker.TEXT_VIEW_FACING}


def marker_array(specs: Iterable[MarkerSpec], stamp: Any) -> MarkerArray:
    """``visualization_msgs/MarkerArray`` of ROS-free marker descriptions.

    The first marker is a DELETEALL, so markers of an earlier result with more test
    configurations or points do not linger in RViz.
    """
    out = MarkerArray()
    clear = Marker()
    clear.action = Marker.DELETEALL
    out.markers.append(clear)
    for spec in specs:
        marker = Marker()
        marker.header.stamp = stamp
        marker.header.frame_id = spec.frame_id
        marker.ns = spec.namespace
        marker.id = int(spec.marker_id)
        marker.type = _MARKER_TYPES[spec.kind]
        marker.action = Marker.ADD
        position = marker.pose.position
        position.x, position.y, position.z = (float(v) for v in spec.position)
        orientation = marker.pose.orientation
        orientation.x, orientation.y, orientation.z, orientation.w = (float(v) for v in spec.orientation)
        marker.scale.x, marker.scale.y, marker.scale.z = (float(v) for v in spec.scale)
        marker.color.r, marker.color.g, marker.color.b, marker.color.a = (float(v) for v in spec.color)
        marker.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in spec.points]
        marker.text = spec.text
        marker.frame_locked = True
        out.markers.append(marker)
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
        # Ctrl-C in a terminal reaches a launched node twice (from the terminal's process group
        # and forwarded by ros2 launch): the second must not interrupt the cleanup, which closes
        # the campaign file and the worker processes.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return status
