"""A 6-DOF calibration verified live: a UR10 calibrated 6-DOF in session 1 (``robocal-uncertainty
calibrate --json`` on positions and orientations: the point session record and the validated
orientation level); in session 2 a 10-pose 6-DOF check is recorded raw (joint states + tracker
PoseStamped) and played with ``ros2 bag play`` into the launched nodes (``tracker_pose_topic``,
``verify_calibration:=``). ``/calibration_node/verify`` tests the positions and the orientations
(each half at half the level) and its verdict and published report equal ``robocal-uncertainty
verify`` on the campaign the collector wrote."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip("rclpy", reason="live ROS tests: rclpy is not importable (ROS 2 not sourced)")

from live_support import add_installed_msg_module, call, installed_share, play_every_message, run, spin_until, started

N_CAL = 30
N_CHECK = 10
NULL_TRIALS = 1000


def test_six_dof_verify_service_live_equals_the_command_line(ros_env, tmp_path) -> None:
    add_installed_msg_module()
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import String
    from std_srvs.srv import Trigger

    from robocal_uncertainty.bagio import read_campaign, write_campaign
    from robocal_uncertainty.bagio.raw_bag_simulator import RawBagSettings, write_raw_bag
    from robocal_uncertainty.core import SimulationSettings, load_robot_model, simulate_campaign
    from robocal_uncertainty.nodes.common import robot_config_path
    from robocal_uncertainty.nodes.qos import latched_qos

    model = load_robot_model(robot_config_path("ur10"))
    # One robot, one tracker set-up: the first poses calibrate, the others are the check
    # (recorded raw, its tracker pose re-registered as for any later check).
    settings = SimulationSettings(n_poses=N_CAL + N_CHECK, frame="tracker", orientation_std=1e-4)
    simulated = simulate_campaign(model, settings, seed=4)
    write_campaign(tmp_path / "session1.mcap", simulated.campaign.subset(np.arange(N_CAL)))
    cli = ["ros2", "run", "robocal_uncertainty", "robocal-uncertainty"]
    calibration = tmp_path / "cal.json"
    run([*cli, "calibrate", str(tmp_path / "session1.mcap"), "--robot", "ur10", "--json", str(calibration)], ros_env)
    assert json.loads(calibration.read_text())["session"]["orientation_level"]["folds"] == 5
    keep = np.arange(N_CAL, N_CAL + N_CHECK)
    check = dataclasses.replace(
        simulated,
        campaign=simulated.campaign.subset(keep),
        true_joint_positions=simulated.true_joint_positions[keep],
        true_points=simulated.true_points[keep],
        settings=dataclasses.replace(settings, n_poses=N_CHECK),
    )
    bag = tmp_path / "check_raw.mcap"
    write_raw_bag(bag, check, RawBagSettings(joint_rate_hz=125.0, tracker_rate_hz=250.0, dwell_s=0.3, move_s=0.15))
    config = yaml.safe_load((installed_share() / "config" / "robocal.yaml").read_text())
    params = config["calibration_node"]["ros__parameters"]
    params["min_samples"] = 1000  # a check session is verified, not calibrated from
    params["verify_null_trials"] = NULL_TRIALS
    config_file = tmp_path / "robocal.yaml"
    config_file.write_text(yaml.safe_dump(config))
    campaign = tmp_path / "campaign.mcap"

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=int(ros_env["ROS_DOMAIN_ID"]))
    node = rclpy.create_node("live_verify_six_dof_test", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    last: dict[str, object] = {}
    node.create_subscription(
        String, "robocal/collector_status", lambda m: last.__setitem__("collector", m), latched_qos()
    )
    node.create_subscription(
        String, "robocal/verification", lambda m: last.__setitem__("verification", m), latched_qos()
    )
    command = ["ros2", "launch", "robocal_uncertainty", "robocal.launch.py", "robot_config:=ur10"]
    command += [f"config_file:={config_file}", f"campaign_path:={campaign}", "input_reliability:=reliable"]
    command += ["tracker_pose_topic:=/tracker/pose", f"tracker_frame_id:={check.campaign.frame_id}"]
    command += [f"verify_calibration:={calibration}"]
    try:
        with started(command, ros_env, tmp_path / "launch.log") as launch:
            spin_until(executor, lambda: "collector" in last, 90, "the nodes to start")
            client = node.create_client(Trigger, "/calibration_node/verify")
            play_every_message(bag, ("/joint_states", "/tracker/pose"), ros_env, tmp_path)

            def samples() -> int:
                return int(json.loads(last["collector"].data).get("samples", -1)) if "collector" in last else -1

            spin_until(executor, lambda: samples() == N_CHECK, 60, f"{N_CHECK} check samples")
            answer = call(executor, client, Trigger.Request(), timeout_s=60)
            spin_until(executor, lambda: "verification" in last, 20, "robocal/verification")
            log = launch.text()
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    assert "Traceback" not in log, log[-3000:]
    held = read_campaign(campaign)
    assert held.n_poses == N_CHECK and held.measurement.measures_orientation
    # The installed command line on the campaign the collector wrote (the node's samples).
    report = tmp_path / "offline"
    verify = [*cli, "verify", str(calibration), str(campaign), "--robot", "ur10"]
    out = run([*verify, "--null-trials", str(NULL_TRIALS), "--out", str(report)], ros_env)
    expected = json.loads((report / "verify.json").read_text())
    published = json.loads(last["verification"].data)
    print(f"~/verify: {answer.message}\nCLI: {out.splitlines()[0]}")
    assert answer.success, answer.message
    # Both halves tested, at half the level each, and the same numbers as the command line.
    assert expected["orientation"] is not None and published["orientation"] == expected["orientation"]
    assert expected["orientation"]["significance"] == pytest.approx(0.025)
    assert published["test"] == expected["test"] and published["registration"] == expected["registration"]
    ratio = expected["orientation"]["error_ratio"]
    assert f"orientations consistent: errors {ratio:.2f}x the calibration session's" in answer.message
    assert expected["consistent"] and answer.message.startswith("consistent (p = ")
    assert out.startswith("consistent: the robot agrees with its calibration")
