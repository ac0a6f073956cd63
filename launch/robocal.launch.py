"""Start the collector, calibration and uncertainty nodes.

Usage::

    ros2 launch robocal_uncertainty robocal.launch.py robot_config:=ur10 \\
        campaign_path:=/data/cal/campaign.mcap \\
        test_joints:="[0, -90, 90, 0, 90, 0]" test_joints_in_degrees:=true

Arguments left empty keep the value of ``config_file`` (default: the installed
``config/robocal.yaml``). ``test_joints`` takes n_joints numbers per configuration,
flattened, separated by commas and/or spaces, with or without brackets; radians unless
``test_joints_in_degrees:=true``. Remap the inputs with ``joint_states_topic`` and
``tracker_point_topic``.
"""

from __future__ import annotations

import os
import tempfile

import yaml
from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchContext, LaunchDescription

PACKAGE = "robocal_uncertainty"


def _numbers(text: str) -> list[float]:
    cleaned = text.replace("[", " ").replace("]", " ").replace(",", " ").split()
    try:
        return [float(v) for v in cleaned]
    except ValueError as err:
        msg = f"test_joints: not a list of numbers: {text!r}"
        raise ValueError(msg) from err


def _bool(text: str, name: str) -> bool:
    lowered = text.strip().lower()
    if lowered in ("true", "1", "yes", "on"):
        return True
    if lowered in ("false", "0", "no", "off"):
        return False
    msg = f"{name}: expected true or false, got {text!r}"
    raise ValueError(msg)


def _override_file(per_node: dict[str, dict[str, object]]) -> str:
    """The launch arguments as a parameter file keyed by node name.

    A parameter dict given to a launch_ros Node is written under ``/**``, and rcl lets a
    node-name section (as in config_file) win over ``/**`` whatever the file order; an
    override file with node-name sections, given after config_file, wins over it.
    """
    content = {name: {"ros__parameters": params} for name, params in per_node.items() if params}
    with tempfile.NamedTemporaryFile("w", prefix="robocal_launch_", suffix=".yaml", delete=False) as file:
        yaml.safe_dump(content or {"/**": {"ros__parameters": {}}}, file)
    return file.name


def _nodes(context: LaunchContext) -> list[Node]:
    def arg(name: str) -> str:
        return LaunchConfiguration(name).perform(context).strip()

    shared: dict[str, object] = {}
    if arg("robot_config"):
        shared["robot_config"] = arg("robot_config")
    if arg("campaign_path"):
        shared["campaign_path"] = os.path.abspath(os.path.expanduser(arg("campaign_path")))
    collector: dict[str, object] = dict(shared)
    if arg("tracker_frame_id"):
        collector["tracker_frame_id"] = arg("tracker_frame_id")
    uncertainty: dict[str, object] = dict(shared)
    if arg("test_joints"):
        uncertainty["test_joints"] = _numbers(arg("test_joints"))
    if arg("test_joints_in_degrees"):
        uncertainty["test_joints_in_degrees"] = _bool(arg("test_joints_in_degrees"), "test_joints_in_degrees")
    config = arg("config_file")
    overrides = _override_file(
        {"collector_node": collector, "calibration_node": shared, "uncertainty_node": uncertainty}
    )
    log_level = arg("log_level") or "info"
    common = {"package": PACKAGE, "output": "screen", "arguments": ["--ros-args", "--log-level", log_level]}
    return [
        Node(
            executable="collector_node",
            name="collector_node",
            parameters=[config, overrides],
            remappings=[
                ("/joint_states", arg("joint_states_topic") or "/joint_states"),
                ("/tracker/point", arg("tracker_point_topic") or "/tracker/point"),
            ],
            **common,
        ),
        Node(executable="calibration_node", name="calibration_node", parameters=[config, overrides], **common),
        Node(executable="uncertainty_node", name="uncertainty_node", parameters=[config, overrides], **common),
    ]


def generate_launch_description() -> LaunchDescription:
    default_config = os.path.join(get_package_share_directory(PACKAGE), "config", "robocal.yaml")
    arguments = [
        ("robot_config", "", "robot model YAML or shipped name (paper_arm, ur10); empty = config_file's"),
        ("campaign_path", "", "campaign MCAP (appended to, resumed); empty = config_file's"),
        ("test_joints", "", "test configurations, n_joints numbers each, flattened; empty = config_file's"),
        ("test_joints_in_degrees", "", "true: test_joints in degrees, false: radians; empty = config_file's"),
        ("tracker_frame_id", "", "frame_id of the tracker points; empty = config_file's"),
        ("joint_states_topic", "/joint_states", "sensor_msgs/JointState input"),
        ("tracker_point_topic", "/tracker/point", "geometry_msgs/PointStamped input"),
        ("config_file", default_config, "parameter file of the three nodes"),
        ("log_level", "info", "log level of the nodes"),
    ]
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=text) for name, default, text in arguments]
        + [OpaqueFunction(function=_nodes)]
    )
