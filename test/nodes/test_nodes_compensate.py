"""Uncertainty node ``~/compensate_targets``: a PoseArray of targets in, the compensated joints
and the reached positions' uncertainty out, equal to :func:`robocal_uncertainty.app.compensate`
on the node's evaluated campaign and settings."""

from __future__ import annotations

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("robocal_uncertainty.msg", reason="robocal_uncertainty is not built with colcon")

from geometry_msgs.msg import Pose, PoseArray
from nodes_support import BASE_BAG, spin_until
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from robocal_uncertainty.msg import CalibrationResult as CalibrationResultMsg
from robocal_uncertainty.msg import CalibrationSample as CalibrationSampleMsg
from robocal_uncertainty.srv import CompensateTargets

from robocal_uncertainty.app.compensation import compensate
from robocal_uncertainty.bagio.messages import calibration_to_msg, sample_to_msg
from robocal_uncertainty.core import forward_points, identify, load_robot_model
from robocal_uncertainty.core.calibration_file import apply_calibration, calibration_to_dict
from robocal_uncertainty.importers.targets import Targets
from robocal_uncertainty.nodes.common import robot_config_path, to_ros
from robocal_uncertainty.nodes.uncertainty_node import UncertaintyNode
from robocal_uncertainty.pipeline import CollectorSettings, replay_bag

TEST_JOINTS_DEG = [-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451]


def test_compensate_targets_service(ros_context, tmp_path) -> None:
    model = load_robot_model(robot_config_path("paper_arm"))
    replay = replay_bag(BASE_BAG, model, collector=CollectorSettings(window_s=0.1, guard_s=0.025), calibrate=False)
    params = [("campaign_path", str(tmp_path / "none.mcap")), ("test_joints_deg", TEST_JOINTS_DEG), ("trials", 300)]
    node = UncertaintyNode(context=ros_context, parameter_overrides=[Parameter(k, value=v) for k, v in params])
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    try:
        empty = node._compensate_targets(CompensateTargets.Request(), CompensateTargets.Response())
        assert not empty.success and empty.message == "no evaluated calibration yet"
        for sample in replay.samples:
            node._on_sample(to_ros(sample_to_msg(sample), CalibrationSampleMsg))
        calibration = identify(model, replay.campaign)
        node._on_calibration(to_ros(calibration_to_msg(calibration, stamp_ns=1), CalibrationResultMsg))
        assert spin_until(executor, lambda: node._evaluated is not None, timeout_s=120.0)
        campaign, evaluated, options = node._evaluated
        data = calibration_to_dict(evaluated, robot=model.name)
        calibrated = apply_calibration(model, data)
        q = campaign.joint_positions[:3] + 0.01
        points = forward_points(calibrated, calibrated.parameter_vector(), q)
        request = CompensateTargets.Request(trials=200, seed=4)
        request.targets = PoseArray()
        request.targets.header.frame_id = calibrated.measurement_frame_id
        for x, y, z in points:
            pose = Pose()
            pose.position.x, pose.position.y, pose.position.z = float(x), float(y), float(z)
            request.targets.poses.append(pose)
        request.seed_joints = campaign.joint_positions[:3].reshape(-1).tolist()
        response = node._compensate_targets(request, CompensateTargets.Response())
        assert response.success, response.message
        assert list(response.status) == ["ok"] * 3 and response.trials == 200
        joints = np.reshape(response.joint_positions, (3, 6))
        assert np.abs(forward_points(calibrated, calibrated.parameter_vector(), joints) - points).max() < 1e-9
        from dataclasses import replace

        expected = compensate(
            model,
            data,
            Targets(points, None, "t", "m"),
            frame="measurement",
            seeds=campaign.joint_positions[:3],
            campaign=campaign,
            options=replace(options, trials=200, seed=4),
        )
        assert expected.uncertainty is not None
        u = [a.standard_uncertainty for p in expected.uncertainty.poses for a in p.axes]
        assert list(response.standard_uncertainty) == u
        request.targets.header.frame_id = "world"
        wrong = node._compensate_targets(request, CompensateTargets.Response())
        assert not wrong.success and "give them in the measurement frame" in wrong.message
    finally:
        executor.shutdown()
        node.destroy_node()
