"""Calibration node with a URDF in ``robot_description``: the probe is unknown (fitted, not
regularised) unless ``tool_point_m`` gives it; ``tool_point_m`` with a robot YAML is refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("robocal_uncertainty.msg", reason="robocal_uncertainty is not built with colcon")

from rclpy.parameter import Parameter

from robocal_uncertainty.core import load_robot_model
from robocal_uncertainty.core.kinematics import forward_points
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.nodes.calibration_node import CalibrationNode
from robocal_uncertainty.nodes.common import robot_config_path

UR10_URDF = Path(__file__).resolve().parents[2] / "robocal_uncertainty" / "data" / "ur10.urdf"


def _node(context, tmp_path: Path, **params) -> CalibrationNode:
    params = {"campaign_path": str(tmp_path / "none.mcap"), **params}
    return CalibrationNode(context=context, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])


def test_tool_point_of_a_robot_description(ros_context, tmp_path) -> None:
    urdf = {"robot_description": UR10_URDF.read_text(), "base_link": "base", "tip_link": "tool0"}
    unknown = _node(ros_context, tmp_path, **urdf)
    known = _node(ros_context, tmp_path, **urdf, tool_point_m=[0.0, 0.0, 0.109])
    try:
        assert not unknown.model.tool_known and known.model.tool_known
        dh = load_robot_model(robot_config_path("ur10"))  # the probe at 109 mm, DH frame = UR's base
        q = np.random.default_rng(0).uniform(-np.pi, np.pi, size=(20, 6))
        np.testing.assert_allclose(
            forward_points(known.model, known.model.parameter_vector(), q),
            forward_points(dh, dh.parameter_vector(), q),
            rtol=0,
            atol=1e-12,
        )
    finally:
        unknown.destroy_node()
        known.destroy_node()
    with pytest.raises(ConfigError, match="tool_point_m describes the probe of a robot_description"):
        _node(ros_context, tmp_path, robot_config="ur10", tool_point_m=[0.0, 0.0, 0.1])
    with pytest.raises(ConfigError, match="tool_point_m: must be 3 finite numbers"):
        _node(ros_context, tmp_path, **urdf, tool_point_m=[0.0, 0.1])
