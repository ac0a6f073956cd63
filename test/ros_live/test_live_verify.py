"""The check measurement live (issue 19 item 1): a UR10 calibrated in session 1
(``robocal-uncertainty calibrate --json``); in session 2 the tracker stands elsewhere and a
10-pose check is recorded raw (joint states + tracker points) and played with ``ros2 bag play``
into the launched nodes (``verify_calibration:=``); ``/calibration_node/verify`` answers the
verdict, equal to ``ros2 run robocal_uncertainty robocal-uncertainty verify`` on the campaign the
collector wrote; the verdict is on /diagnostics and on the latched ``robocal/verification``."""

from __future__ import annotations

import json

import pytest
import yaml

rclpy = pytest.importorskip("rclpy", reason="live ROS tests: rclpy is not importable (ROS 2 not sourced)")

from live_support import add_installed_msg_module, call, installed_share, play_every_message, run, spin_until, started

N_CHECK = 10
NULL_TRIALS = 4000


def test_verify_service_live_equals_the_command_line(ros_env, tmp_path) -> None:
    add_installed_msg_module()
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import String
    from std_srvs.srv import Trigger

    from robocal_uncertainty.bagio import read_campaign, write_campaign
    from robocal_uncertainty.bagio.raw_bag_simulator import RawBagSettings, write_raw_bag
    from robocal_uncertainty.core import load_robot_model
    from robocal_uncertainty.core.simulation import SessionSimulationSettings, simulate_sessions
    from robocal_uncertainty.nodes.common import robot_config_path
    from robocal_uncertainty.nodes.qos import DIAGNOSTICS_QOS, latched_qos

    model = load_robot_model(robot_config_path("ur10"))
    settings = SessionSimulationSettings(
        n_sessions=2, n_poses=(53, N_CHECK), tool_remount_std=0.0, joint_offset_std=0.0, temperature_std=0.0
    )
    sessions = simulate_sessions(model, settings, seed=8)
    write_campaign(tmp_path / "session1.mcap", sessions.sessions[0].campaign)
    cli = ["ros2", "run", "robocal_uncertainty", "robocal-uncertainty"]
    calibration = tmp_path / "cal.json"
    run([*cli, "calibrate", str(tmp_path / "session1.mcap"), "--robot", "ur10", "--json", str(calibration)], ros_env)
    check = sessions.sessions[1]
    bag = tmp_path / "check_raw.mcap"
    raw = RawBagSettings(joint_rate_hz=125.0, tracker_rate_hz=250.0, dwell_s=0.3, move_s=0.15)
    write_raw_bag(bag, check, raw, seed=22)
    config = yaml.safe_load((installed_share() / "config" / "robocal.yaml").read_text())
    params = config["calibration_node"]["ros__parameters"]
    params["min_samples"] = 1000  # a check session is verified, not calibrated from
    params["verify_null_trials"] = NULL_TRIALS
    config_file = tmp_path / "robocal.yaml"
    config_file.write_text(yaml.safe_dump(config))
    campaign = tmp_path / "campaign.mcap"

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=int(ros_env["ROS_DOMAIN_ID"]))
    node = rclpy.create_node("live_verify_test", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    last: dict[str, object] = {}
    diagnostics: dict[str, object] = {}

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for status in msg.status:
            diagnostics[status.name] = status

    node.create_subscription(
        String, "robocal/collector_status", lambda m: last.__setitem__("collector", m), latched_qos()
    )
    node.create_subscription(
        String, "robocal/verification", lambda m: last.__setitem__("verification", m), latched_qos()
    )
    node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, DIAGNOSTICS_QOS)
    command = ["ros2", "launch", "robocal_uncertainty", "robocal.launch.py", "robot_config:=ur10"]
    command += [f"config_file:={config_file}", f"campaign_path:={campaign}", "input_reliability:=reliable"]
    command += [f"tracker_frame_id:={check.campaign.frame_id}", f"verify_calibration:={calibration}"]
    try:
        with started(command, ros_env, tmp_path / "launch.log") as launch:
            spin_until(executor, lambda: "collector" in last, 90, "the nodes to start")
            client = node.create_client(Trigger, "/calibration_node/verify")
            early = call(executor, client, Trigger.Request())
            assert not early.success and "no samples held" in early.message, early.message
            play_every_message(bag, ("/joint_states", "/tracker/point"), ros_env, tmp_path)

            def samples() -> int:
                return int(json.loads(last["collector"].data).get("samples", -1)) if "collector" in last else -1

            spin_until(executor, lambda: samples() == N_CHECK, 60, f"{N_CHECK} check samples")
            answer = call(executor, client, Trigger.Request(), timeout_s=60)
            spin_until(executor, lambda: "verification" in last, 20, "robocal/verification")
            spin_until(
                executor,
                lambda: (
                    "calibration_node: verify" in diagnostics
                    and diagnostics["calibration_node: verify"].message == answer.message
                ),
                20,
                "the verdict on /diagnostics",
            )
            log = launch.text()
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    assert "Traceback" not in log, log[-3000:]
    assert read_campaign(campaign).n_poses == N_CHECK
    # The installed command line on the campaign the collector wrote (the node's samples).
    report = tmp_path / "offline"
    verify = [*cli, "verify", str(calibration), str(campaign), "--robot", "ur10"]
    out = run([*verify, "--null-trials", str(NULL_TRIALS), "--out", str(report)], ros_env)
    expected = json.loads((report / "verify.json").read_text())
    published = json.loads(last["verification"].data)
    print(f"~/verify: {answer.message}\nCLI: {out.splitlines()[0]}")
    assert answer.success, answer.message
    assert expected["consistent"] and answer.message.startswith("consistent (p = ")
    assert out.startswith("consistent: the robot agrees with its calibration")
    assert published["test"] == expected["test"] and published["registration"] == expected["registration"]
    assert published["tracker_move"] == expected["tracker_move"] and published["summary"] == answer.message
    move = expected["tracker_move"]
    assert f"tracker moved {move['distance_m'] * 1e3:.3f} ± {move['distance_std_m'] * 1e3:.3f} mm" in answer.message
    assert f"p = {expected['test']['p_value']:.3g}" in out
    assert diagnostics["calibration_node: verify"].level == b"\x00"
    written = json.loads((tmp_path / "campaign.verify" / "verify.json").read_text())
    assert written["test"] == expected["test"]
