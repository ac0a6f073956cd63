"""Start the collector, calibration and uncertainty nodes.

Usage::

    ros2 launch robocal_uncertainty robocal.launch.py robot_config:=ur10 \\
        campaign_path:=/data/cal/campaign.mcap test_joints_deg:="0 -90 90 0 90 0"

Arguments left empty keep the value of ``config_file`` (default: the installed
``config/robocal.yaml``). The test configurations are given in degrees
(``test_joints_deg``) or in radians (``test_joints_rad``), never both: n_joints numbers per
configuration, flattened, separated by commas and/or spaces, with or without brackets;
neither = the seed's test configuration. Remap the inputs with ``joint_states_topic`` and
``tracker_point_topic``; ``input_reliability:=reliable`` delivers every message of a
played recording (default best effort, for live sensors); ``tracker_pose_topic`` subscribes
a 6-DOF tracker's poses instead of points. ``use_sim_time:=true`` puts the nodes on
``/clock`` (``ros2 bag play --clock``). ``verify_calibration:=cal.json`` (a calibration
written by ``robocal-uncertainty calibrate --json`` in an earlier session) lets
``/calibration_node/verify`` check this session's samples against it.

The launch arguments reach the nodes through a small parameter file with node-name
sections (a node-name section of ``config_file`` would win over ``-p`` overrides); it is
removed when the launch shuts down.
"""

from __future__ import annotations

import os
import shutil
import tempfile

import yaml
from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, OpaqueFunction, RegisterEventHandler
from launch.event_handlers import OnShutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchContext, LaunchDescription

PACKAGE = "robocal_uncertainty"


def _numbers(text: str, name: str) -> list[float]:
    cleaned = text.replace("[", " ").replace("]", " ").replace(",", " ").split()
    try:
        return [float(v) for v in cleaned]
    except ValueError as err:
        msg = f"{name}: not a list of numbers: {text!r}"
        raise ValueError(msg) from err


def _bool(text: str, name: str) -> bool:
    lowered = text.strip().lower()
    if lowered in ("true", "1", "yes", "on"):
        return True
    if lowered in ("false", "0", "no", "off"):
        return False
    msg = f"{name}: expected true or false, got {text!r}"
    raise ValueError(msg)


def _override_file(per_node: dict[str, dict[str, object]], folder: str) -> str:
    """The launch arguments as a parameter file keyed by node name, in `folder`.

    A parameter dict given to a launch_ros Node is written under ``/**``, and rcl lets a
    node-name section (as in config_file) win over ``/**`` whatever the file order; an
    override file with node-name sections, given after config_file, wins over it.
    """
    content = {name: {"ros__parameters": params} for name, params in per_node.items() if params}
    path = os.path.join(folder, "overrides.yaml")
    with open(path, "w", encoding="utf-8") as file:
        yaml.safe_dump(content or {"/**": {"ros__parameters": {}}}, file)
    return path


def _nodes(context: LaunchContext) -> list[Node | RegisterEventHandler]:
    def arg(name: str) -> str:
        return LaunchConfiguration(name).perform(context).strip()

    shared: dict[str, object] = {}
    if arg("robot_config"):
        shared["robot_config"] = arg("robot_config")
    if arg("campaign_path"):
        shared["campaign_path"] = os.path.abspath(os.path.expanduser(arg("campaign_path")))
    if arg("use_sim_time"):
        shared["use_sim_time"] = _bool(arg("use_sim_time"), "use_sim_time")
    collector: dict[str, object] = dict(shared)
    if arg("tracker_frame_id"):
        collector["tracker_frame_id"] = arg("tracker_frame_id")
    if arg("tracker_pose_topic"):
        collector["tracker_pose_topic"] = arg("tracker_pose_topic")
    if arg("input_reliability"):
        collector["input_reliability"] = arg("input_reliability")
    calibration: dict[str, object] = dict(shared)
    if arg("verify_calibration"):
        calibration["verify_calibration"] = os.path.abspath(os.path.expanduser(arg("verify_calibration")))
    uncertainty: dict[str, object] = dict(shared)
    if arg("test_joints_deg") and arg("test_joints_rad"):
        raise ValueError("give test_joints_deg or test_joints_rad, not both")
    for name in ("test_joints_deg", "test_joints_rad"):
        if arg(name):
            uncertainty[name] = _numbers(arg(name), name)
    config = arg("config_file")
    folder = tempfile.mkdtemp(prefix="robocal_launch_")
    overrides = _override_file(
        {"collector_node": collector, "calibration_node": calibration, "uncertainty_node": uncertainty}, folder
    )
    cleanup = RegisterEventHandler(OnShutdown(on_shutdown=lambda event, context: shutil.rmtree(folder, True)))
    log_level = arg("log_level") or "info"
    common = {"package": PACKAGE, "output": "screen", "arguments": ["--ros-args", "--log-level", log_level]}
    return [
        cleanup,
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
        ("test_joints_deg", "", "test configurations in DEGREES, n_joints numbers each, flattened; empty = none"),
        ("test_joints_rad", "", "test configurations in RADIANS, n_joints numbers each, flattened; empty = none"),
        ("tracker_frame_id", "", "frame_id of the tracker points; empty = config_file's"),
        ("tracker_pose_topic", "", "6-DOF tracker: PoseStamped topic used instead of points; empty = points"),
        (
            "input_reliability",
            "",
            "collector inputs: best_effort (sensors) or reliable (bag play); empty = config's",
        ),
        (
            "verify_calibration",
            "",
            "calibration JSON (calibrate --json) that /calibration_node/verify checks this session against; "
            "empty = config_file's",
        ),
        ("use_sim_time", "", "true: the nodes use /clock (ros2 bag play --clock); empty = config_file's"),
        ("joint_states_topic", "/joint_states", "sensor_msgs/JointState input"),
        ("tracker_point_topic", "/tracker/point", "geometry_msgs/PointStamped input"),
        ("config_file", default_config, "parameter file of the three nodes"),
        ("log_level", "info", "log level of the nodes"),
    ]
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=text) for name, default, text in arguments]
        + [OpaqueFunction(function=_nodes)]
    )
