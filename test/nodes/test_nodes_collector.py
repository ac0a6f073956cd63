"""Collector node: fed the raw test bag it takes exactly the replay's samples (directly and over
DDS), records them to the campaign file, drops bad messages per cause and keeps running."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("robocal_uncertainty.msg", reason="robocal_uncertainty is not built with colcon")

from geometry_msgs.msg import PointStamped
from nodes_support import BASE_BAG, JOINT_TOPIC, POINT_TOPIC, bag_messages, spin_until
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from robocal_uncertainty.msg import CalibrationSample as CalibrationSampleMsg
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from robocal_uncertainty.bagio import read_campaign
from robocal_uncertainty.bagio.messages import msg_to_sample
from robocal_uncertainty.core import load_robot_model
from robocal_uncertainty.nodes.collector_node import CollectorNode
from robocal_uncertainty.nodes.common import robot_config_path
from robocal_uncertainty.nodes.qos import SAMPLE_QOS
from robocal_uncertainty.pipeline import CollectorSettings, replay_bag

# The test bags dwell only 0.3 s per pose: a short window and guard (as test/pipeline).
WINDOW = {"window_s": 0.1, "guard_s": 0.025}
_STREAM = {JOINT_TOPIC: 0, POINT_TOPIC: 1}


@pytest.fixture(scope="module")
def replay():
    model = load_robot_model(robot_config_path("paper_arm"))
    return replay_bag(BASE_BAG, model, collector=CollectorSettings(**WINDOW, min_points=10), calibrate=False)


def _collector(context, tmp_path: Path, **params) -> CollectorNode:
    values = {"campaign_path": str(tmp_path / "campaign.mcap"), "fsync": False, "auto_window": False, **WINDOW}
    values.update(params)
    overrides = [Parameter(name, value=value) for name, value in values.items()]
    return CollectorNode(context=context, parameter_overrides=overrides)


def _capture(node: CollectorNode) -> Trigger.Response:
    return node._capture_now(Trigger.Request(), Trigger.Response())


def test_fed_in_recorded_order_the_node_takes_the_replays_samples(ros_context, tmp_path, replay) -> None:
    node = _collector(ros_context, tmp_path)
    try:
        for log_time, topic, msg in bag_messages():
            node._push(_STREAM[topic], msg, log_time)
        _capture(node)  # the replay flushes the dwell the bag ends in
        campaign = node.recorder.campaign
        expected = replay.campaign
        assert campaign.n_poses == expected.n_poses == len(replay.samples)
        for name in ("joint_positions", "points", "point_std", "stamps_ns"):
            assert np.array_equal(getattr(campaign, name), getattr(expected, name)), name
        assert sum(node.collector.dropped.values()) == 0
    finally:
        node.destroy_node()
    on_disk = read_campaign(tmp_path / "campaign.mcap")
    assert np.array_equal(on_disk.points, expected.points)
    assert np.array_equal(on_disk.point_std, expected.point_std)


def test_with_the_defaults_the_node_finds_what_replay_finds_with_its_defaults(ros_context, tmp_path) -> None:
    """One static-pose detector, one set of defaults: the shipped raw bag (0.3 s dwells, shorter
    than the default 0.5 s window) gives the node with its defaults the 30 samples the offline
    replay finds with its defaults (window learnt from the first dwells), bit for bit."""
    model = load_robot_model(robot_config_path("paper_arm"))
    offline = replay_bag(BASE_BAG, model, calibrate=False, auto_window=True)
    assert len(offline.samples) == 30
    assert offline.collector.window_s < 0.5
    overrides = [Parameter("campaign_path", value=str(tmp_path / "c.mcap")), Parameter("fsync", value=False)]
    node = CollectorNode(context=ros_context, parameter_overrides=overrides)
    try:
        assert node.collector.learning
        messages = bag_messages()
        for log_time, topic, msg in messages:
            node._push(_STREAM[topic], msg, log_time)
        node._merger.drain()
        assert not node.collector.learning
        assert node.collector.settings == offline.collector
        # The base bag ends at home after its last dwell: every sample is out without a flush.
        campaign = node.recorder.campaign
        assert campaign.n_poses == 30
        for name in ("joint_positions", "points", "point_std", "stamps_ns"):
            assert np.array_equal(getattr(campaign, name), getattr(offline.campaign, name)), name
        status = node.status()
        assert status["window_s"] == offline.collector.window_s
        assert status["input_gaps"]["joint_states"] == 0
    finally:
        node.destroy_node()


def test_restart_resumes_the_campaign_file(ros_context, tmp_path, replay) -> None:
    messages = bag_messages()
    half = len(messages) // 2
    first = _collector(ros_context, tmp_path)
    for log_time, topic, msg in messages[:half]:
        first._push(_STREAM[topic], msg, log_time)
    first._merger.drain()
    before = first.recorder.n_samples
    assert before > 0
    # The second node opens the file while the first still has it open and unfinished, as
    # a killed collector leaves it (every appended pose is flushed).
    restarted = _collector(ros_context, tmp_path)
    first.destroy_node()  # finishes the replaced, unlinked file only
    try:
        assert restarted.recorder.n_samples == before
        for log_time, topic, msg in messages[half:]:
            restarted._push(_STREAM[topic], msg, log_time)
        _capture(restarted)
        stamps = restarted.recorder.campaign.stamps_ns
        assert np.array_equal(stamps[:before], replay.campaign.stamps_ns[:before])
        assert len(stamps) >= len(replay.campaign.stamps_ns) - 1  # at most the dwell cut by the restart is lost
    finally:
        restarted.destroy_node()
    assert read_campaign(tmp_path / "campaign.mcap").n_poses == len(stamps)


def _joint_state(stamp_ns: int, names: list[str], positions: list[float]) -> JointState:
    msg = JointState()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    msg.name = names
    msg.position = positions
    return msg


def _point(stamp_ns: int, frame_id: str, xyz: tuple[float, float, float]) -> PointStamped:
    msg = PointStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    msg.header.frame_id = frame_id
    msg.point.x, msg.point.y, msg.point.z = xyz
    return msg


def test_bad_messages_are_counted_per_cause_and_dropped(ros_context, tmp_path) -> None:
    node = _collector(ros_context, tmp_path)
    try:
        names = list(node.model.joint_names)
        t0 = 1_700_000_000_000_000_000
        node._push(0, _joint_state(t0, names, [0.1] * len(names)), 1)
        node._push(0, _joint_state(t0 + 10**7, names, [math.nan] + [0.1] * (len(names) - 1)), 2)
        node._push(0, _joint_state(t0 + 2 * 10**7, [*names[:-1], "elbow_typo"], [0.1] * len(names)), 3)
        node._push(0, _joint_state(t0 - 10**7, names, [0.1] * len(names)), 4)
        node._push(1, _point(t0, "base_link", (1.0, 0.0, 0.5)), 5)
        node._push(1, _point(t0 + 10**7, "somewhere_else", (1.0, 0.0, 0.5)), 6)
        node._push(1, _point(t0 + 2 * 10**7, "base_link", (math.inf, 0.0, 0.5)), 7)
        node._merger.drain()
        dropped = node.collector.dropped
        assert dropped["nan"] == 2
        assert dropped["unknown_joint"] == 1
        assert dropped["backwards_time"] == 1
        assert dropped["wrong_frame"] == 1
        assert {"nan", "unknown_joint", "backwards_time", "wrong_frame"} <= set(node._causes._loggers)
        # Still running: good data after the bad still make a sample.
        for k in range(1, 40):
            node._push(0, _joint_state(t0 + k * 10**7 + 5, names, [0.1] * len(names)), 100 + 2 * k)
            node._push(1, _point(t0 + k * 10**7 + 7, "base_link", (1.0, 0.0, 0.5)), 101 + 2 * k)
        assert _capture(node).success
        assert node.recorder.n_samples == 1
        assert node.status()["dropped"]["nan"] == 2
    finally:
        node.destroy_node()


def test_over_dds_a_sample_comes_out_equal_to_the_replays(ros_context, tmp_path, replay) -> None:
    node = _collector(ros_context, tmp_path)
    peer = rclpy.create_node("bag_player", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(peer)
    received: list[CalibrationSampleMsg] = []
    peer.create_subscription(CalibrationSampleMsg, "robocal/samples", received.append, SAMPLE_QOS)
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    publishers = {
        JOINT_TOPIC: peer.create_publisher(JointState, JOINT_TOPIC, qos),
        POINT_TOPIC: peer.create_publisher(PointStamped, POINT_TOPIC, qos),
    }
    try:
        assert spin_until(executor, lambda: all(p.get_subscription_count() for p in publishers.values()))
        end_of_third = replay.samples[2].stamp_ns + 200_000_000
        for published, (_, topic, msg) in enumerate(bag_messages(until_ns=end_of_third), start=1):
            publishers[topic].publish(msg)
            # Lockstep: a best-effort queue must not overflow while this thread publishes.
            assert spin_until(executor, lambda n=published: sum(node.received.values()) >= n, timeout_s=5.0)
        assert spin_until(executor, lambda: len(received) >= 2)
        for msg, expected in zip(received, replay.samples):
            assert msg_to_sample(msg) == expected
    finally:
        executor.shutdown()
        peer.destroy_node()
        node.destroy_node()


def test_parameters_are_validated(ros_context, tmp_path) -> None:
    node = _collector(ros_context, tmp_path)
    try:
        read_only = node.set_parameters([Parameter("window_s", value=0.2)])[0]
        assert not read_only.successful
        ok = node.set_parameters([Parameter("save_copy_path", value=str(tmp_path / "copy.mcap"))])[0]
        assert ok.successful
        descriptor = node.describe_parameter("window_s")
        assert "[s]" in descriptor.description
        assert descriptor.read_only
        assert descriptor.floating_point_range[0].from_value > 0
    finally:
        node.destroy_node()
    from robocal_uncertainty.errors import ConfigError

    with pytest.raises(ConfigError, match="robot_config"):
        _collector(ros_context, tmp_path, robot_config="  ")
