"""Calibration node ``~/verify``: the check measurement of ``robocal-uncertainty verify`` on the
samples the node holds. The node's verdict, statistic and tracker move equal the command line's
on the same check campaign (read from its file, the node's built from sample messages); a
known joint-offset drift is called drifted by both; refusals answer success=false in one line
and leave the node working; /diagnostics says OK / WARN / ERROR."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("robocal_uncertainty.msg", reason="robocal_uncertainty is not built with colcon")

from nodes_support import spin_until
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from robocal_uncertainty.msg import CalibrationSample as CalibrationSampleMsg
from std_msgs.msg import String
from std_srvs.srv import Trigger

from robocal_uncertainty.bagio import read_campaign, write_campaign
from robocal_uncertainty.bagio.messages import sample_to_msg
from robocal_uncertainty.cli import main
from robocal_uncertainty.core import SimulationSettings, load_robot_model, simulate_campaign
from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.sample import CalibrationSample
from robocal_uncertainty.nodes.calibration_node import CalibrationNode
from robocal_uncertainty.nodes.common import robot_config_path, to_ros
from robocal_uncertainty.nodes.qos import latched_qos
from robocal_uncertainty.pipeline.diagnostics import DiagnosticLevel

NULL_TRIALS = 4000
DRIFT_DEG = 0.02  # joint 2 offset: the CLI test's power study detects 0.01 deg every time


@pytest.fixture(scope="module")
def sessions(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A UR10 calibrated in session 1 (53 poses, calibrate --json); session 2 is a 10-pose check
    with the tracker placed anew and nothing else changed."""
    out = tmp_path_factory.mktemp("verify_sessions")
    args = ["simulate", "--robot", "ur10", "--sessions", "2", "--session-poses", "53", "10", "--seed", "4"]
    args += ["--joint-drift-deg", "0", "--temperature-k", "0", "--tool-remount-um", "0"]
    args += ["--out", str(out / "ur10.mcap")]
    assert main(args) == 0
    assert main(["calibrate", str(out / "ur10.session1.mcap"), "--robot", "ur10", "--json", str(out / "cal.json")]) == 0
    drifted = read_campaign(out / "ur10.session2.mcap")
    q = drifted.joint_positions.copy()
    q[:, 1] += np.radians(DRIFT_DEG)  # the encoder of joint 2 now reads 0.02 deg more
    write_campaign(out / "drifted.mcap", _with_joints(drifted, q))
    return out


def _with_joints(campaign: Campaign, q: np.ndarray) -> Campaign:
    return Campaign(
        joint_names=campaign.joint_names,
        joint_positions=q,
        points=campaign.points,
        frame=campaign.frame,
        frame_id=campaign.frame_id,
        stamps_ns=campaign.stamps_ns,
    )


def _messages(campaign: Campaign) -> list[CalibrationSampleMsg]:
    stamps = campaign.stamps_ns if campaign.stamps_ns is not None else 10**9 * np.arange(1, campaign.n_poses + 1)
    out = []
    for i in range(campaign.n_poses):
        sample = CalibrationSample(
            stamp_ns=int(stamps[i]),
            frame_id=campaign.frame_id,
            joint_names=campaign.joint_names,
            joint_positions=campaign.joint_positions[i],
            joint_position_std=np.zeros(len(campaign.joint_names)),
            point=campaign.points[i],
            point_covariance=np.zeros((3, 3)),
            joint_state_count=50,
            tracker_point_count=100,
        )
        out.append(to_ros(sample_to_msg(sample), CalibrationSampleMsg))
    return out


def _node(context, tmp_path: Path, **params) -> CalibrationNode:
    params = {
        "robot_config": "ur10",
        "campaign_path": str(tmp_path / "check.mcap"),
        "min_samples": 1000,  # a check campaign is not calibrated from
        "verify_null_trials": NULL_TRIALS,
        **params,
    }
    return CalibrationNode(context=context, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])


def _cli(sessions: Path, check: Path, report: Path) -> tuple[int, dict]:
    args = ["verify", str(sessions / "cal.json"), str(check), "--robot", "ur10", "--null-trials", str(NULL_TRIALS)]
    status = main([*args, "--out", str(report)])
    return status, json.loads((report / "verify.json").read_text())


def _call(node: CalibrationNode) -> Trigger.Response:
    return node._verify_service(Trigger.Request(), Trigger.Response())


@pytest.mark.parametrize("check_name", ["ur10.session2.mcap", "drifted.mcap"])
def test_verify_service_gives_the_command_lines_verdict(ros_context, tmp_path, sessions, check_name, capsys) -> None:
    check = sessions / check_name
    status, expected = _cli(sessions, check, tmp_path / "cli")
    cli_out = capsys.readouterr().out
    node = _node(ros_context, tmp_path, verify_calibration=str(sessions / "cal.json"))
    peer = rclpy.create_node("verification_listener", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(peer)
    got: list[String] = []
    peer.create_subscription(String, "robocal/verification", got.append, latched_qos())
    try:
        for msg in _messages(read_campaign(check)):
            node._on_sample(msg)
        assert node.latest is None  # min_samples: the check is not calibrated from
        response = _call(node)
        assert response.success, response.message
        assert "\n" not in response.message
        written = json.loads((tmp_path / "check.verify" / "verify.json").read_text())
        # The same check: the node's campaign (from sample messages) and the CLI's (from the file).
        assert written["consistent"] is expected["consistent"]
        assert written["test"] == expected["test"]
        assert np.allclose(written["registration"], expected["registration"], rtol=0, atol=1e-12)
        assert written["tracker_move"].keys() == expected["tracker_move"].keys()
        for key, value in expected["tracker_move"].items():  # approx takes no lists inside a dict
            assert np.allclose(written["tracker_move"][key], value, rtol=1e-12, atol=1e-15), key
        assert (tmp_path / "check.verify" / "verify.md").is_file()
        assert (tmp_path / "check.verify" / "verify.png").stat().st_size > 1000
        move = expected["tracker_move"]
        mm = f"tracker moved {move['distance_m'] * 1e3:.3f} ± {move['distance_std_m'] * 1e3:.3f} mm"
        assert mm in response.message and f"turned {move['angle_rad'] * 1e3:.3f} ±" in response.message
        p_text = f"p = {expected['test']['p_value']:.3g}"
        assert p_text in response.message and p_text in cli_out
        diagnostic = node.verification_diagnostic_status()
        if check_name == "drifted.mcap":
            assert status == 3 and not expected["consistent"]
            assert response.message.startswith("drifted by about") and response.message.endswith("re-calibrate")
            assert diagnostic.level == DiagnosticLevel.WARN
        else:
            assert status == 0 and expected["consistent"]
            assert response.message.startswith(f"consistent ({p_text} >= 0.05")
            assert diagnostic.level == DiagnosticLevel.OK
        assert diagnostic.value("verdict") == ("consistent" if expected["consistent"] else "drifted")
        spin_until(executor, lambda: bool(got), timeout_s=10.0)
        published = json.loads(got[-1].data)
        assert published["summary"] == response.message and published["test"] == expected["test"]
    finally:
        executor.shutdown()
        peer.destroy_node()
        node.destroy_node()


def test_verify_refusals_answer_one_line_and_keep_the_node(ros_context, tmp_path, sessions) -> None:
    six_dof = tmp_path / "six_dof.mcap"
    model = load_robot_model(robot_config_path("ur10"))
    simulation = simulate_campaign(model, SimulationSettings(n_poses=30, orientation_std=1e-4), seed=3)
    write_campaign(six_dof, simulation.campaign)
    assert main(["calibrate", str(six_dof), "--robot", "ur10", "--json", str(tmp_path / "six_dof.json")]) == 0
    garbage = tmp_path / "garbage.json"
    garbage.write_text("{not json")
    node = _node(ros_context, tmp_path)
    messages = _messages(read_campaign(sessions / "ur10.session2.mcap"))
    try:
        refused = _call(node)
        assert not refused.success and refused.message.startswith("refused: no calibration to check against")
        assert node.verification_diagnostic_status().level == DiagnosticLevel.ERROR
        assert node.set_parameters([Parameter("verify_calibration", value=str(sessions / "cal.json"))])[0].successful
        refused = _call(node)
        assert not refused.success and "no samples held" in refused.message
        for msg in messages[:3]:
            node._on_sample(msg)
        refused = _call(node)
        assert not refused.success and refused.message.startswith("refused: check campaign too small: 3 poses")
        for msg in messages[3:]:
            node._on_sample(msg)
        reasons = {
            str(tmp_path / "missing.json"): "missing.json",
            str(garbage): "garbage.json",
        }
        for path, reason in reasons.items():
            assert node.set_parameters([Parameter("verify_calibration", value=path)])[0].successful
            refused = _call(node)
            assert not refused.success and reason in refused.message, refused.message
            assert "\n" not in refused.message
            status = node.verification_diagnostic_status()
            assert status.level == DiagnosticLevel.ERROR and reason in status.message
        assert not node.set_parameters([Parameter("verify_significance", value=0.9)])[0].successful
        assert not node.set_parameters([Parameter("verify_null_trials", value=10)])[0].successful
        # The node still answers, and a good check after the refusals is OK again.
        assert node.set_parameters([Parameter("verify_calibration", value=str(sessions / "cal.json"))])[0].successful
        started = time.monotonic()
        answer = _call(node)
        print(f"~/verify of 10 poses with {NULL_TRIALS} null draws: {time.monotonic() - started:.2f} s")
        assert answer.success and answer.message.startswith("consistent"), answer.message
        assert node.verification_diagnostic_status().level == DiagnosticLevel.OK
    finally:
        node.destroy_node()


def test_six_dof_calibrations_are_verified(ros_context, tmp_path, sessions) -> None:
    """A 6-DOF calibration's file has a session record (from the positions of its poses)."""
    six_dof = tmp_path / "six_dof.mcap"
    model = load_robot_model(robot_config_path("ur10"))
    simulation = simulate_campaign(model, SimulationSettings(n_poses=30, orientation_std=1e-4), seed=3)
    write_campaign(six_dof, simulation.campaign)
    assert main(["calibrate", str(six_dof), "--robot", "ur10", "--json", str(tmp_path / "six_dof.json")]) == 0
    node = _node(ros_context, tmp_path, verify_calibration=str(tmp_path / "six_dof.json"))
    try:
        for msg in _messages(read_campaign(sessions / "ur10.session2.mcap")):
            node._on_sample(msg)
        answer = _call(node)
        # Another simulated robot than the one calibrated: it runs, and the verdict says how far.
        assert answer.success, answer.message
        assert answer.message.startswith(("consistent", "drifted")) and "the calibration session's" in answer.message
    finally:
        node.destroy_node()


def test_the_node_writes_a_session_record_its_later_verify_uses(ros_context, tmp_path, sessions) -> None:
    """Session 1: ~/calibrate calibrates from the samples and writes the session record. Session 2:
    a node given that record checks 10 poses, no command line between them; the verdict is the
    one of ``verify`` on the same record and check."""
    first = _node(ros_context, tmp_path / "s1", campaign_path=str(tmp_path / "s1" / "ur10.mcap"), min_samples=53)
    try:
        for msg in _messages(read_campaign(sessions / "ur10.session1.mcap")):
            first._on_sample(msg)
        assert first.latest is not None
        record = tmp_path / "s1" / "ur10.session.json"
        assert not record.exists()  # automatic calibrations do not write it (seconds each)
        assert first._calibrate_service(Trigger.Request(), Trigger.Response()).success
        assert record.is_file() and first.session_record_path == record
    finally:
        first.destroy_node()
    data = json.loads(record.read_text())
    assert data["session"]["validated_level"]["folds"] == 5 and data["session"]["n_poses"] == 53
    second = _node(ros_context, tmp_path, verify_calibration=str(record))
    try:
        for msg in _messages(read_campaign(sessions / "ur10.session2.mcap")):
            second._on_sample(msg)
        answer = _call(second)
        assert answer.success and answer.message.startswith("consistent"), answer.message
        assert "errors " in answer.message and "x the calibration session's" in answer.message
    finally:
        second.destroy_node()
    args = ["verify", str(record), str(sessions / "ur10.session2.mcap"), "--robot", "ur10"]
    assert main([*args, "--null-trials", str(NULL_TRIALS)]) == 0
