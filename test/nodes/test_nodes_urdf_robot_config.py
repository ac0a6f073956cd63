"""Calibration node with a URDF file in ``robot_config``: read by the one robot loader with the
same ``base_link``/``tip_link``/``tool_point_m`` parameters as a ``robot_description``, and the
same model as from that parameter; the nodes without those parameters refuse a URDF."""

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
from robocal_uncertainty.nodes.common import load_model, robot_config_path

UR10_URDF = Path(__file__).resolve().parents[2] / "robocal_uncertainty" / "data" / "ur10.urdf"


def _node(context, tmp_path: Path, **params) -> CalibrationNode:
    params = {"campaign_path": str(tmp_path / "none.mcap"), **params}
    return CalibrationNode(context=context, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])


def test_a_urdf_file_in_robot_config(ros_context, tmp_path) -> None:
    chain = {"base_link": "base", "tip_link": "tool0", "tool_point_m": [0.0, 0.0, 0.109]}
    from_file = _node(ros_context, tmp_path, robot_config=str(UR10_URDF), **chain)
    from_text = _node(ros_context, tmp_path, robot_description=UR10_URDF.read_text(), **chain)
    unknown = _node(ros_context, tmp_path, robot_config=str(UR10_URDF), base_link="base", tip_link="tool0")
    try:
        assert from_file.model.tool_known and not unknown.model.tool_known
        assert from_file.model.base_frame_id == "base"
        dh = load_robot_model(robot_config_path("ur10"))  # the probe at 109 mm, DH frame = UR's base
        q = np.random.default_rng(1).uniform(-np.pi, np.pi, size=(20, 6))
        points = forward_points(from_file.model, from_file.model.parameter_vector(), q)
        np.testing.assert_allclose(points, forward_points(dh, dh.parameter_vector(), q), rtol=0, atol=1e-12)
        np.testing.assert_array_equal(from_file.model.parameter_vector(), from_text.model.parameter_vector())
    finally:
        for node in (from_file, from_text, unknown):
            node.destroy_node()


def test_the_nodes_without_chain_parameters_refuse_a_urdf() -> None:
    """The collector and uncertainty nodes have no base_link/tip_link: a URDF read with default
    chain ends could be another chain than the calibration node's, so it is refused."""
    with pytest.raises(ConfigError, match="is a URDF, which this node does not read"):
        load_model(str(UR10_URDF))
    assert load_model("ur10", base_unknown=True).base_known is False
