"""The collector node as a process: bad messages live (counted by cause, the node keeps
running), SIGKILL mid-recording and a restart (no sample taken before the kill is lost; the
final campaign equals an uninterrupted replay's), ``~/save_copy``. The raw bag is published
by this test at 2x its pace over reliable, kept-all QoS (``input_reliability:=reliable``), so
every reading arrives and the samples are bit-equal to the offline replay's."""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="live ROS tests: rclpy is not importable (ROS 2 not sourced)")

from live_support import BASE_BAG, add_installed_msg_module, call, spin_until, started

WINDOW = {"window_s": 0.1, "guard_s": 0.025}
RATE = 2.0  # times the recorded pace


def _bag_messages():
    from geometry_msgs.msg import PointStamped
    from sensor_msgs.msg import JointState

    from robocal_uncertainty.bagio.mcap_stream import read_mcap_file
    from robocal_uncertainty.bagio.ros_messages import JOINT_STATE, POINT_STAMPED, ros_typestore
    from robocal_uncertainty.nodes.common import to_ros

    store = ros_typestore()
    out = []
    for message in sorted(read_mcap_file(BASE_BAG).messages, key=lambda m: m.log_time_ns):
        if message.channel.topic == "/joint_states":
            out.append((message.log_time_ns, 0, to_ros(store.deserialize_cdr(message.data, JOINT_STATE), JointState)))
        elif message.channel.topic == "/tracker/point":
            point = to_ros(store.deserialize_cdr(message.data, POINT_STAMPED), PointStamped)
            out.append((message.log_time_ns, 1, point))
    return out


def test_bad_messages_kill_and_restart(ros_env, tmp_path) -> None:
    add_installed_msg_module()
    from geometry_msgs.msg import PointStamped
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String
    from std_srvs.srv import Trigger

    from robocal_uncertainty.bagio import read_campaign
    from robocal_uncertainty.core import load_robot_model
    from robocal_uncertainty.nodes.common import robot_config_path
    from robocal_uncertainty.nodes.qos import latched_qos
    from robocal_uncertainty.pipeline import CollectorSettings, replay_bag

    model = load_robot_model(robot_config_path("paper_arm"))
    offline = replay_bag(BASE_BAG, model, collector=CollectorSettings(**WINDOW), calibrate=False)
    assert len(offline.samples) == 30
    campaign = tmp_path / "campaign.mcap"
    parameters = {"campaign_path": str(campaign), "auto_window": "false", "input_reliability": "reliable", **WINDOW}
    command = ["ros2", "run", "robocal_uncertainty", "collector_node", "--ros-args"]
    for name, value in parameters.items():
        command += ["-p", f"{name}:={value}"]

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=int(ros_env["ROS_DOMAIN_ID"]))
    node = rclpy.create_node("live_collector_test", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    status: list[dict] = []
    node.create_subscription(
        String, "robocal/collector_status", lambda m: status.append(json.loads(m.data)), latched_qos()
    )
    qos = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)
    publishers = (
        node.create_publisher(JointState, "/joint_states", qos),
        node.create_publisher(PointStamped, "/tracker/point", qos),
    )
    save = node.create_client(Trigger, "/collector_node/save_copy")
    messages = _bag_messages()
    # Kill in the move after the 15th pose: half-way between its sample and the next.
    kill_ns = (offline.samples[14].stamp_ns + offline.samples[15].stamp_ns) // 2
    split = next(
        i for i, (_, _, msg) in enumerate(messages) if msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec > kill_ns
    )

    def publish(chunk) -> None:
        t0, w0 = chunk[0][0], time.monotonic()
        for log_time, stream, msg in chunk:
            delay = (log_time - t0) / 1e9 / RATE - (time.monotonic() - w0)
            if delay > 0:
                executor.spin_once(timeout_sec=delay)
            publishers[stream].publish(msg)

    def fresh_status(after: int):
        spin_until(executor, lambda: len(status) > after, 60, "the collector's status")

    try:
        with started(command, ros_env, tmp_path / "first.log") as first:
            fresh_status(0)
            spin_until(executor, lambda: all(p.get_subscription_count() for p in publishers), 60, "subscriptions")
            publish(messages[:split])
            spin_until(executor, lambda: status[-1]["samples"] == 15, 60, "15 samples before the kill")
            first.kill()  # SIGKILL: no cleanup, the campaign file has no footer
        killed = read_campaign(campaign)
        assert killed.n_poses == 15  # every sample taken before the kill is on disk
        assert np.array_equal(killed.points, offline.campaign.points[:15])

        seen = len(status)
        with started(command, ros_env, tmp_path / "second.log") as second:
            spin_until(
                executor, lambda: len(status) > seen and status[-1]["received"]["joint_states"] == 0, 60, "restart"
            )
            assert status[-1]["samples"] == 15  # resumed from the file
            time.sleep(1.0)
            publish(messages[split:])
            # Bad messages after the recording: each dropped and counted by its cause.
            names = list(model.joint_names)
            last_stamp = messages[-1][2].header.stamp

            def joint_state(sec, names, positions):
                msg = JointState(name=names, position=positions)
                msg.header.stamp.sec = sec
                return msg

            publishers[0].publish(joint_state(last_stamp.sec + 1, names, [math.nan] * 6))
            publishers[0].publish(joint_state(last_stamp.sec + 2, [*names[:5], "elbow_typo"], [0.1] * 6))
            publishers[0].publish(joint_state(last_stamp.sec - 100, names, [0.1] * 6))
            wrong = PointStamped()
            wrong.header.frame_id = "somewhere_else"
            wrong.header.stamp.sec = last_stamp.sec + 3
            publishers[1].publish(wrong)

            def counted() -> bool:
                d = status[-1]["dropped"]
                return d["nan"] == 1 and d["unknown_joint"] == 1 and d["backwards_time"] == 1 and d["wrong_frame"] == 1

            spin_until(executor, counted, 60, f"the bad messages counted (status {status[-1]})")
            assert status[-1]["samples"] == 30
            answer = call(executor, save, Trigger.Request())
            assert answer.success and "wrote 30 samples" in answer.message, answer.message
            assert second.alive()
            final = status[-1]
        assert second.popen.returncode == 0, second.text()[-2000:]
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    print(
        f"collector after restart: {final['received']} received, dropped {final['dropped']}, gaps {final['input_gaps']}"
    )
    resumed = read_campaign(campaign)
    assert resumed.n_poses == 30
    for name in ("joint_positions", "points", "point_std", "stamps_ns"):
        assert np.array_equal(getattr(resumed, name), getattr(offline.campaign, name)), name
