"""Helpers of the node tests: the raw test bag as rclpy messages, spinning until a condition."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
BASE_BAG = REPO / "test" / "data" / "paper_arm_base_raw.mcap"
JOINT_TOPIC, POINT_TOPIC = "/joint_states", "/tracker/point"


def bag_messages(path: Path = BASE_BAG, *, until_ns: int | None = None) -> list[tuple[int, str, Any]]:
    """(log time [ns], topic, rclpy message) of the raw bag's inputs, in log-time order."""
    from geometry_msgs.msg import PointStamped
    from sensor_msgs.msg import JointState

    from robocal_uncertainty.bagio.mcap_stream import read_mcap_file
    from robocal_uncertainty.bagio.ros_messages import JOINT_STATE, POINT_STAMPED, ros_typestore
    from robocal_uncertainty.nodes.common import to_ros

    store = ros_typestore()
    contents = read_mcap_file(path)
    out = []
    for message in sorted(contents.messages, key=lambda m: m.log_time_ns):
        topic = message.channel.topic
        if topic not in (JOINT_TOPIC, POINT_TOPIC):
            continue
        if until_ns is not None and message.log_time_ns > until_ns:
            break
        if topic == JOINT_TOPIC:
            ros = to_ros(store.deserialize_cdr(message.data, JOINT_STATE), JointState)
        else:
            ros = to_ros(store.deserialize_cdr(message.data, POINT_STAMPED), PointStamped)
        out.append((message.log_time_ns, topic, ros))
    return out


def spin_until(executor: Any, condition: Callable[[], bool], timeout_s: float = 20.0) -> bool:
    """Spin `executor` until `condition()` holds or `timeout_s` passes; whether it held."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        executor.spin_once(timeout_sec=0.05)
    return condition()
