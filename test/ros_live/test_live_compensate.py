"""``~/compensate_targets`` live: the nodes launched, a raw recording played, then a PoseArray of
targets sent to the running uncertainty node; its joints and stated uncertainty equal the
offline ``calibrate --json`` + ``compensate`` on the campaign the nodes wrote."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip("rclpy", reason="live ROS tests: rclpy is not importable (ROS 2 not sourced)")

from live_support import (
    PAPER_TEST_JOINTS_DEG,
    add_installed_msg_module,
    call,
    installed_share,
    play_every_message,
    run,
    spin_until,
    started,
)

N_POSES = 30  # simulated; the collector finds most of them
TRIALS = 500


def test_compensate_targets_live(ros_env, tmp_path) -> None:
    add_installed_msg_module()
    from geometry_msgs.msg import Pose, PoseArray
    from rclpy.executors import SingleThreadedExecutor
    from robocal_uncertainty.srv import CompensateTargets
    from std_msgs.msg import String

    from robocal_uncertainty.bagio.raw_bag_simulator import RawBagSettings, write_raw_bag
    from robocal_uncertainty.core import SimulationSettings, load_robot_model, simulate_campaign
    from robocal_uncertainty.nodes.common import robot_config_path
    from robocal_uncertainty.nodes.qos import latched_qos

    model = load_robot_model(robot_config_path("paper_arm"))
    simulated = simulate_campaign(model, SimulationSettings(n_poses=N_POSES, frame="base"), seed=6)
    bag = tmp_path / "raw.mcap"
    write_raw_bag(
        bag, simulated, RawBagSettings(joint_rate_hz=125.0, tracker_rate_hz=250.0, dwell_s=0.3, move_s=0.15), seed=8
    )
    config = yaml.safe_load((installed_share() / "config" / "robocal.yaml").read_text())
    config["uncertainty_node"]["ros__parameters"]["trials"] = TRIALS
    config_file = tmp_path / "robocal.yaml"
    config_file.write_text(yaml.safe_dump(config))
    campaign = tmp_path / "campaign.mcap"
    # Targets: the simulated robot's points at three campaign poses moved by 0.5 mm, in the base frame.
    seeds = simulated.campaign.joint_positions[:3]
    targets = simulated.campaign.points[:3] + 5e-4

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=int(ros_env["ROS_DOMAIN_ID"]))
    node = rclpy.create_node("live_compensate_test", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    last: dict[str, object] = {}
    node.create_subscription(
        String, "robocal/uncertainty_status", lambda m: last.__setitem__("status", m), latched_qos()
    )
    command = ["ros2", "launch", "robocal_uncertainty", "robocal.launch.py", "robot_config:=paper_arm"]
    command += [f"config_file:={config_file}", f"campaign_path:={campaign}", "input_reliability:=reliable"]
    command += [f"test_joints_deg:={PAPER_TEST_JOINTS_DEG}"]
    try:
        with started(command, ros_env, tmp_path / "launch.log"):
            spin_until(executor, lambda: "status" in last, 90, "the nodes to start")
            play_every_message(bag, ("/joint_states", "/tracker/point"), ros_env, tmp_path)

            def done() -> int | None:
                state = json.loads(last["status"].data)
                return int(state["sample_count"]) if state.get("state") == "done" else None

            # The collector keeps the poses it finds static (not always every one of the recording):
            # wait for the last evaluation, a count that stays for 5 s.
            spin_until(executor, lambda: done() is not None, 240, "a first evaluation")
            seen = done()
            while True:
                deadline = time.monotonic() + 5.0
                while time.monotonic() < deadline:
                    executor.spin_once(timeout_sec=0.05)
                if seen is not None and done() == seen:
                    break
                seen = done()
            request = CompensateTargets.Request(trials=TRIALS, seed=3)
            request.targets = PoseArray()
            request.targets.header.frame_id = model.base_frame_id  # the simulated points are in the base frame
            for x, y, z in targets:
                pose = Pose()
                pose.position.x, pose.position.y, pose.position.z = float(x), float(y), float(z)
                request.targets.poses.append(pose)
            request.seed_joints = seeds.reshape(-1).tolist()
            client = node.create_client(CompensateTargets, "/uncertainty_node/compensate_targets")
            answered = call(executor, client, request, timeout_s=120.0)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    assert answered.success, answered.message
    assert list(answered.status) == ["ok"] * 3

    # Offline: the campaign the nodes wrote, calibrated and compensated from the command line.
    cal = tmp_path / "cal.json"
    cli = ["ros2", "run", "robocal_uncertainty", "robocal-uncertainty"]
    run([*cli, "calibrate", str(campaign), "--robot", "paper_arm", "--json", str(cal)], ros_env, 120)
    points = tmp_path / "targets.csv"
    points.write_text("x_m,y_m,z_m\n" + "".join(f"{x!r},{y!r},{z!r}\n" for x, y, z in targets.tolist()))
    seeds_file = tmp_path / "seeds.csv"
    seeds_file.write_text("".join(" ".join(repr(v) for v in row) + "\n" for row in seeds.tolist()))
    out = tmp_path / "compensation.json"
    command = [*cli, "compensate", str(cal), str(points), "--robot", "paper_arm", "--campaign", str(campaign)]
    command += ["--seed-joints-file", str(seeds_file), "--trials", str(TRIALS), "--seed", "3", "--json", str(out)]
    run(command, ros_env, 300)
    offline = json.loads(out.read_text())
    joints = np.reshape(answered.joint_positions, (3, -1))
    assert np.abs(joints - np.array([t["joints"] for t in offline["targets"]])).max() < 1e-12
    u = np.reshape(answered.standard_uncertainty, (3, 3))
    assert np.allclose(u, [t["reached"]["standard_uncertainty_m"] for t in offline["targets"]], rtol=1e-9, atol=0)
