"""The uncertainty node's ``field_correction`` parameter: declared off, described, and passed to the
app's :func:`~robocal_uncertainty.app.evaluate` (the node is a thin shell over it; the correction
itself is tested offline in ``test/test_field_correction_statements.py``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("robocal_uncertainty.msg", reason="robocal_uncertainty is not built with colcon")

from nodes_support import BASE_BAG, spin_until
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from robocal_uncertainty.msg import CalibrationResult as CalibrationResultMsg
from robocal_uncertainty.msg import CalibrationSample as CalibrationSampleMsg
from std_msgs.msg import String

from robocal_uncertainty.bagio.messages import calibration_to_msg, sample_to_msg
from robocal_uncertainty.core import identify, load_robot_model
from robocal_uncertainty.nodes.common import robot_config_path, to_ros
from robocal_uncertainty.nodes.uncertainty_node import UncertaintyNode
from robocal_uncertainty.pipeline import CollectorSettings, replay_bag

TEST_JOINTS_DEG = [-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451]


def test_the_field_correction_parameter_reaches_the_app_evaluate(ros_context, tmp_path, monkeypatch) -> None:
    from robocal_uncertainty.nodes import uncertainty_node

    model = load_robot_model(robot_config_path("paper_arm"))
    replay = replay_bag(BASE_BAG, model, collector=CollectorSettings(window_s=0.1, guard_s=0.025), calibrate=False)
    real = uncertainty_node.evaluate
    asked: list[bool] = []

    def recording(*args, **kwargs):
        asked.append(kwargs.get("field_correction"))
        # The simulated bag's model error is none: evaluate uncorrected, only the path is tested.
        return real(*args, **{**kwargs, "field_correction": False})

    monkeypatch.setattr(uncertainty_node, "evaluate", recording)
    node = UncertaintyNode(
        context=ros_context,
        node_name="uncertainty_field_correction",
        parameter_overrides=[
            Parameter("campaign_path", value=str(tmp_path / "none.mcap")),
            Parameter("test_joints_deg", value=TEST_JOINTS_DEG),
            Parameter("trials", value=200),
        ],
    )
    peer = rclpy.create_node("listener_field_correction", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(peer)
    status: list[dict] = []
    peer.create_subscription(String, "robocal/uncertainty_status", lambda m: status.append(json.loads(m.data)), 10)
    try:
        assert node.get_parameter("field_correction").value is False
        assert "kriging" in node.describe_parameter("field_correction").description
        assert node.set_parameters([Parameter("field_correction", value=True)])[0].successful
        for sample in replay.samples:
            node._on_sample(to_ros(sample_to_msg(sample), CalibrationSampleMsg))
        calibration = identify(model, replay.campaign)
        node._on_calibration(to_ros(calibration_to_msg(calibration, stamp_ns=1), CalibrationResultMsg))
        assert spin_until(executor, lambda: bool(status) and status[-1]["state"] in ("failed", "done"), timeout_s=120.0)
        assert asked and all(asked)
        assert status[-1]["state"] == "done" and np.isfinite(status[-1]["elapsed_s"])
    finally:
        executor.shutdown()
        peer.destroy_node()
        node.destroy_node()
