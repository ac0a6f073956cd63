"""The uncertainty node's model-error parameters: the field by default, ``independent_model_error``
for the per-pose model, and the former ``model_error_field`` of an old parameter file accepted with
a warning that it is no longer read (the statement is the default field, not silently another)."""

from __future__ import annotations

import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("robocal_uncertainty.msg", reason="robocal_uncertainty is not built with colcon")

from rclpy.parameter import Parameter
from robocal_uncertainty.msg import CalibrationResult as CalibrationResultMsg

from robocal_uncertainty.nodes.uncertainty_node import UncertaintyNode


class _Log:
    def __init__(self) -> None:
        self.warnings: list[str] = []

    def warning(self, text: str) -> None:
        self.warnings.append(text)

    def info(self, text: str) -> None:
        pass

    def error(self, text: str) -> None:
        pass


@pytest.mark.parametrize(
    ("overrides", "expected", "warned"),
    [
        ({}, "field", False),
        ({"independent_model_error": True}, "independent", False),
        ({"model_error_field": False}, "field", True),
        ({"model_error_field": True}, "field", True),
    ],
)
def test_model_error_parameters(ros_context, tmp_path, monkeypatch, overrides, expected, warned) -> None:
    log = _Log()
    monkeypatch.setattr(UncertaintyNode, "get_logger", lambda self: log)
    node = UncertaintyNode(
        context=ros_context,
        node_name="uncertainty_model_error",
        parameter_overrides=[
            Parameter("campaign_path", value=str(tmp_path / "none.mcap")),
            *(Parameter(name, value=value) for name, value in overrides.items()),
        ],
    )
    try:
        options = node._options(CalibrationResultMsg())
        assert options.uncertainty.model_error == expected
        notes = [w for w in log.warnings if "model_error_field" in w]
        assert len(notes) == (1 if warned else 0), log.warnings
        if warned:
            assert "no longer read" in notes[0] and "independent_model_error: true" in notes[0]
    finally:
        node.destroy_node()
