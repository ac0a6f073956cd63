"""Calibration and uncertainty nodes: the replayed samples in, a calibration (topic and YAML)
and an uncertainty bit-identical to the offline evaluation out; parameters validated."""

from __future__ import annotations

import time

import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("robocal_uncertainty.msg", reason="robocal_uncertainty is not built with colcon")

from geometry_msgs.msg import PoseWithCovarianceStamped
from nodes_support import BASE_BAG, spin_until
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from robocal_uncertainty.msg import CalibrationResult as CalibrationResultMsg
from robocal_uncertainty.msg import CalibrationSample as CalibrationSampleMsg
from robocal_uncertainty.msg import PoseUncertainty as PoseUncertaintyMsg
from std_srvs.srv import Trigger

from robocal_uncertainty.bagio import write_campaign
from robocal_uncertainty.bagio.messages import calibration_to_msg, sample_to_msg
from robocal_uncertainty.core import EncoderNoise, TrackerNoise, identify, load_robot_model
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.nodes.calibration_node import CalibrationNode
from robocal_uncertainty.nodes.common import robot_config_path, to_ros
from robocal_uncertainty.nodes.qos import latched_qos
from robocal_uncertainty.nodes.uncertainty_node import UncertaintyNode
from robocal_uncertainty.pipeline import CollectorSettings, replay_bag
from robocal_uncertainty.uncertainty import EvaluationSettings, UncertaintySettings, evaluate_uncertainty

TEST_JOINTS_DEG = [-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451, 30.0, -180.0, 45.0, 10.0, -20.0, 5.0]
TRIALS, SEED = 400, 7


@pytest.fixture(scope="module")
def model():
    return load_robot_model(robot_config_path("paper_arm"))


@pytest.fixture(scope="module")
def replay(model):
    return replay_bag(BASE_BAG, model, collector=CollectorSettings(window_s=0.1, guard_s=0.025), calibrate=False)


def _node(cls, context, node_name=None, **params):
    extra = {} if node_name is None else {"node_name": node_name}
    return cls(context=context, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()], **extra)


def _sample_msgs(replay):
    return [to_ros(sample_to_msg(s), CalibrationSampleMsg) for s in replay.samples]


def test_calibration_node_identifies_and_writes_yaml(ros_context, tmp_path, model, replay) -> None:
    campaign_path = tmp_path / "campaign.mcap"
    n = len(replay.samples)
    node = _node(CalibrationNode, ros_context, campaign_path=str(campaign_path), min_samples=n)
    try:
        for msg in _sample_msgs(replay)[: n - 1]:
            node._on_sample(msg)
        assert node.latest is None  # fewer than min_samples
        msgs = _sample_msgs(replay)
        node._on_sample(msgs[-1])
        node._on_sample(msgs[-1])  # a duplicate counts once
        expected = identify(model, replay.campaign)
        assert node.latest is not None
        assert node.latest.n_poses == n
        assert np.array_equal(node.latest.estimate, expected.estimate)
        data = yaml.safe_load((tmp_path / "campaign.calibration.yaml").read_text())
        assert data["units"] == {"length": "m", "angle": "rad"}
        assert data["n_poses"] == n
        response = node._calibrate_service(Trigger.Request(), Trigger.Response())
        assert response.success, response.message
        refused = node.set_parameters([Parameter("lambda", value="sometimes")])[0]
        assert not refused.successful
        assert "lambda" in refused.reason
        assert not node.set_parameters([Parameter("min_samples", value=0)])[0].successful
        assert node.set_parameters([Parameter("recalibrate_every", value=5)])[0].successful
    finally:
        node.destroy_node()


def test_calibration_node_starts_from_the_campaign_file(ros_context, tmp_path, model, replay) -> None:
    campaign_path = tmp_path / "campaign.mcap"
    write_campaign(campaign_path, replay.campaign)
    node = _node(CalibrationNode, ros_context, campaign_path=str(campaign_path), min_samples=10)
    try:
        assert len(node.store) == len(replay.samples)
        assert node.latest is not None
        assert np.array_equal(node.latest.estimate, identify(model, replay.campaign).estimate)
    finally:
        node.destroy_node()


def test_uncertainty_node_publishes_the_offline_numbers(ros_context, tmp_path, model, replay) -> None:
    node = _node(
        UncertaintyNode,
        ros_context,
        campaign_path=str(tmp_path / "none.mcap"),
        test_joints_deg=TEST_JOINTS_DEG,
        trials=TRIALS,
        seed=SEED,
    )
    peer = rclpy.create_node("listener", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(peer)
    got: list[PoseUncertaintyMsg] = []
    poses: list[PoseWithCovarianceStamped] = []
    peer.create_subscription(PoseUncertaintyMsg, "robocal/uncertainty", got.append, latched_qos(2))
    peer.create_subscription(PoseWithCovarianceStamped, "robocal/pose_with_covariance", poses.append, latched_qos(2))
    try:
        for msg in _sample_msgs(replay):
            node._on_sample(msg)
        calibration = identify(model, replay.campaign)
        node._on_calibration(to_ros(calibration_to_msg(calibration, stamp_ns=1), CalibrationResultMsg))
        assert spin_until(executor, lambda: len(got) >= 2 and len(poses) >= 2, timeout_s=120.0)
        # The node's units (um, deg) converted as the command line converts them.
        settings = UncertaintySettings(
            tracker_noise=TrackerNoise(a=5.0 * 1e-6, b=0.0 * 1e-6),
            encoder_noise=EncoderNoise(half_width=float(np.radians(0.005))),
        )
        options = EvaluationSettings(
            uncertainty=settings,
            test_joints=np.radians(np.reshape(TEST_JOINTS_DEG, (-1, 6))),
            trials=TRIALS,
            seed=SEED,
            # The node's default backend, as the command line's (numba's sums differ from
            # numpy's in the last bits).
            backend="auto",
        )
        expected = evaluate_uncertainty(model, replay.campaign, options.test_joints, options, calibration=calibration)
        for msg, pose, pose_msg in zip(got, expected.poses, poses):
            assert np.array_equal(np.array(msg.covariance), pose.covariance.reshape(-1))
            assert [msg.mean.x, msg.mean.y, msg.mean.z] == pose.mean.tolist()
            assert list(msg.standard_uncertainty) == [a.standard_uncertainty for a in pose.axes]
            assert list(msg.expanded_uncertainty) == [a.expanded_uncertainty for a in pose.axes]
            assert msg.trials == TRIALS
            covariance = np.reshape(pose_msg.pose.covariance, (6, 6))
            assert np.array_equal(covariance[:3, :3], pose.covariance)
            # Points on joint 6's axis determine no rotation: exactly 1e6 rad^2, uncorrelated
            # (was 1e6 + 2e-10 with cross terms up to 2.5e-10, issue 17 item 8).
            assert np.array_equal(covariance[3:, 3:], 1e6 * np.eye(3))
            assert not covariance[:3, 3:].any() and not covariance[3:, :3].any()
            assert not msg.has_orientation
            assert np.isnan(msg.orientation_standard_uncertainty).all()
            assert np.array_equal(np.reshape(msg.orientation_covariance, (3, 3)), 1e6 * np.eye(3))
        assert not node.set_parameters([Parameter("coverage", value=1.5)])[0].successful
        refused = node.set_parameters([Parameter("sources", value="tracker,telepathy")])[0]
        assert not refused.successful
        assert "telepathy" in refused.reason
        assert not node.set_parameters([Parameter("test_joints_deg", value=[0.0] * 6)])[0].successful  # read-only
    finally:
        executor.shutdown()
        peer.destroy_node()
        node.destroy_node()


def test_a_newer_calibration_supersedes_the_running_one(ros_context, tmp_path, model, replay) -> None:
    node = _node(
        UncertaintyNode,
        ros_context,
        campaign_path=str(tmp_path / "none.mcap"),
        trials=40_000,
        seed=SEED,
    )
    try:
        for msg in _sample_msgs(replay):
            node._on_sample(msg)
        first = identify(model, replay.campaign)
        node._on_calibration(to_ros(calibration_to_msg(first, stamp_ns=1), CalibrationResultMsg))
        node.set_parameters([Parameter("trials", value=TRIALS)])
        node._after_parameter_change()  # what the timer does
        deadline = time.monotonic() + 120.0
        while node.completed < 1 and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.5)
        assert node.completed == 1  # the 40 000-trial run was abandoned, only the newer one finished
    finally:
        node.destroy_node()


def test_bad_test_joints_stop_the_node_at_start(ros_context, tmp_path) -> None:
    with pytest.raises(ConfigError, match="multiple"):
        _node(UncertaintyNode, ros_context, campaign_path=str(tmp_path / "x.mcap"), test_joints_deg=[0.0] * 7)
    with pytest.raises(ConfigError, match="both set"):
        _node(
            UncertaintyNode,
            ros_context,
            campaign_path=str(tmp_path / "x.mcap"),
            test_joints_deg=[0.0] * 6,
            test_joints_rad=[0.0] * 6,
        )


def test_test_joints_in_degrees_and_in_radians_name_the_same_configuration(ros_context, tmp_path) -> None:
    q_deg = [10.0, -45.0, 90.0, 0.0, 30.0, -60.0]
    by_deg = _node(UncertaintyNode, ros_context, campaign_path=str(tmp_path / "x.mcap"), test_joints_deg=q_deg)
    by_rad = _node(
        UncertaintyNode,
        ros_context,
        node_name="uncertainty_rad",
        campaign_path=str(tmp_path / "x.mcap"),
        test_joints_rad=list(np.radians(q_deg)),
    )
    default = _node(UncertaintyNode, ros_context, node_name="uncertainty_seed", campaign_path=str(tmp_path / "x.mcap"))
    try:
        assert np.array_equal(by_deg.test_joints, by_rad.test_joints)
        assert np.array_equal(by_deg.test_joints, np.radians([q_deg]))
        seed_deg = [-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451]  # the seed's Table 2
        assert np.array_equal(default.test_joints, np.radians([seed_deg]))
        # The README's example value in degrees is far outside what radians would be read as.
        assert by_deg.describe_parameter("test_joints_deg").description.endswith("[deg]")
        assert by_rad.describe_parameter("test_joints_rad").description.endswith("[rad]")
    finally:
        for node in (by_deg, by_rad, default):
            node.destroy_node()


def _status_after_evaluation(context, tmp_path, samples, calibration, *, sim_now_ns: int | None) -> dict:
    """The node's final status JSON; with `sim_now_ns`, on use_sim_time with /clock at that time."""
    import json

    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import String

    node = _node(
        UncertaintyNode,
        context,
        node_name=f"uncertainty_sim_{sim_now_ns is not None}",
        campaign_path=str(tmp_path / "none.mcap"),
        trials=TRIALS,
        use_sim_time=sim_now_ns is not None,
    )
    peer = rclpy.create_node("clock_source", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(peer)
    status: list[dict] = []
    peer.create_subscription(String, "robocal/uncertainty_status", lambda m: status.append(json.loads(m.data)), 10)
    clock = peer.create_publisher(Clock, "/clock", 10)
    try:
        if sim_now_ns is not None:
            message = Clock()
            message.clock.sec, message.clock.nanosec = divmod(sim_now_ns, 1_000_000_000)

            def on_bag_clock() -> bool:
                clock.publish(message)
                return node.get_clock().now().nanoseconds == sim_now_ns

            assert spin_until(executor, on_bag_clock)
        for msg in samples:
            node._on_sample(msg)
        node._on_calibration(calibration)
        assert spin_until(executor, lambda: bool(status) and status[-1]["state"] == "done", timeout_s=120.0)
        return status[-1]
    finally:
        executor.shutdown()
        peer.destroy_node()
        node.destroy_node()


def test_sample_to_result_on_sim_time_and_none_on_another_clock(ros_context, tmp_path, model, replay) -> None:
    """Playing a recording (2023 stamps): with use_sim_time and /clock from the bag the latency is
    stated on the bag's clock; on the wall clock it is left out (was 3 years)."""
    samples = _sample_msgs(replay)
    newest = max(s.stamp_ns for s in replay.samples)
    calibration = to_ros(calibration_to_msg(identify(model, replay.campaign), stamp_ns=1), CalibrationResultMsg)
    # The bag's clock 0.25 s after the newest sample.
    on_sim = _status_after_evaluation(ros_context, tmp_path, samples, calibration, sim_now_ns=newest + 250_000_000)
    assert on_sim["sample_to_result_s"] == 0.25
    on_wall = _status_after_evaluation(ros_context, tmp_path, samples, calibration, sim_now_ns=None)
    assert on_wall["sample_to_result_s"] is None


def test_a_result_that_is_no_statement_is_not_published(ros_context, tmp_path, model, replay, monkeypatch) -> None:
    # The command line refuses a run whose spread disagrees with its own GUM statement; the
    # node must not publish it either. The app's evaluate is wrapped to mark its (honest)
    # result as such, so the node's handling is tested, not the guard (tested offline).
    import dataclasses
    import json

    from std_msgs.msg import String

    from robocal_uncertainty.nodes import uncertainty_node

    real = uncertainty_node.evaluate
    problem = "test configuration 1: Monte Carlo u = 1e+11 mm against its first-order (GUM) u = 1 mm along x"

    def not_converged(*args, **kwargs):
        evaluation = real(*args, **kwargs)
        marked = dataclasses.replace(evaluation.uncertainty, not_converged=(problem,))
        return dataclasses.replace(evaluation, uncertainty=marked)

    monkeypatch.setattr(uncertainty_node, "evaluate", not_converged)
    node = _node(
        UncertaintyNode,
        ros_context,
        node_name="uncertainty_no_statement",
        campaign_path=str(tmp_path / "none.mcap"),
        test_joints_deg=TEST_JOINTS_DEG,
        trials=TRIALS,
        seed=SEED,
    )
    peer = rclpy.create_node("listener_no_statement", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(peer)
    got: list[PoseUncertaintyMsg] = []
    status: list[dict] = []
    peer.create_subscription(PoseUncertaintyMsg, "robocal/uncertainty", got.append, latched_qos(2))
    peer.create_subscription(String, "robocal/uncertainty_status", lambda m: status.append(json.loads(m.data)), 10)
    try:
        for msg in _sample_msgs(replay):
            node._on_sample(msg)
        node._on_calibration(
            to_ros(calibration_to_msg(identify(model, replay.campaign), stamp_ns=1), CalibrationResultMsg)
        )
        assert spin_until(executor, lambda: bool(status) and status[-1]["state"] in ("failed", "done"), timeout_s=120.0)
        assert status[-1]["state"] == "failed"
        assert "did not converge to a statement" in status[-1]["error"] and "nothing published" in status[-1]["error"]
        executor.spin_once(timeout_sec=0.5)
        assert got == []
    finally:
        executor.shutdown()
        peer.destroy_node()
        node.destroy_node()


def test_too_few_trials_for_the_interval_are_refused(ros_context, tmp_path, model, replay) -> None:
    # 11 trials cannot state a 95 % interval (below 2/(1-p) = 40): refused with the reason in
    # the status, nothing evaluated or published, as the command line refuses --trials 11.
    import json

    from std_msgs.msg import String

    node = _node(
        UncertaintyNode,
        ros_context,
        node_name="uncertainty_eleven_trials",
        campaign_path=str(tmp_path / "none.mcap"),
        test_joints_deg=TEST_JOINTS_DEG,
        trials=11,
    )
    peer = rclpy.create_node("listener_eleven_trials", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(peer)
    status: list[dict] = []
    got: list[PoseUncertaintyMsg] = []
    peer.create_subscription(String, "robocal/uncertainty_status", lambda m: status.append(json.loads(m.data)), 10)
    peer.create_subscription(PoseUncertaintyMsg, "robocal/uncertainty", got.append, latched_qos(2))
    try:
        for msg in _sample_msgs(replay):
            node._on_sample(msg)
        node._on_calibration(
            to_ros(calibration_to_msg(identify(model, replay.campaign), stamp_ns=1), CalibrationResultMsg)
        )
        assert spin_until(executor, lambda: any(s["state"] == "failed" for s in status), timeout_s=30.0)
        error = next(s for s in status if s["state"] == "failed")["error"]
        assert "trials 11 cannot state a 95 % coverage interval" in error and "40" in error
        assert got == []
    finally:
        executor.shutdown()
        peer.destroy_node()
        node.destroy_node()


def test_samples_outside_the_joint_limits_are_refused(ros_context, tmp_path, model, replay) -> None:
    # One sample's readings sent in degrees instead of radians: the node refuses the campaign
    # with the command line's message (campaign pose, joint limits, the degrees hint) in its
    # status and publishes nothing, as `evaluate` refuses such a campaign file.
    import dataclasses
    import json

    from std_msgs.msg import String

    samples = list(replay.samples)
    first = samples[0]
    samples[0] = dataclasses.replace(first, joint_positions=np.degrees(np.asarray(first.joint_positions)))
    node = _node(
        UncertaintyNode,
        ros_context,
        node_name="uncertainty_degrees_as_radians",
        campaign_path=str(tmp_path / "none.mcap"),
        test_joints_deg=TEST_JOINTS_DEG,
        trials=TRIALS,
    )
    peer = rclpy.create_node("listener_degrees_as_radians", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(peer)
    status: list[dict] = []
    got: list[PoseUncertaintyMsg] = []
    peer.create_subscription(String, "robocal/uncertainty_status", lambda m: status.append(json.loads(m.data)), 10)
    peer.create_subscription(PoseUncertaintyMsg, "robocal/uncertainty", got.append, latched_qos(2))
    try:
        for sample in samples:
            node._on_sample(to_ros(sample_to_msg(sample), CalibrationSampleMsg))
        node._on_calibration(
            to_ros(calibration_to_msg(identify(model, replay.campaign), stamp_ns=1), CalibrationResultMsg)
        )
        assert spin_until(executor, lambda: any(s["state"] == "failed" for s in status), timeout_s=60.0)
        error = next(s for s in status if s["state"] == "failed")["error"]
        assert "campaign pose 1 of" in error and "limit" in error and "degrees" in error, error
        assert got == []
    finally:
        executor.shutdown()
        peer.destroy_node()
        node.destroy_node()
