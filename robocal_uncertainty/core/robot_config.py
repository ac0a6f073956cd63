"""The robot YAML reader's names where they were first imported from; the reader and its writer
live in :mod:`robocal_uncertainty.core.robot_formats.robot_yaml`."""

from __future__ import annotations

from robocal_uncertainty.core.robot_formats.robot_yaml import (
    ANGLE_UNITS,
    LENGTH_UNITS,
    TOP_LEVEL_KEYS,
    load_robot_model,
    resolve_robot_config,
    robot_model_from_dict,
)

__all__ = [
    "ANGLE_UNITS",
    "LENGTH_UNITS",
    "TOP_LEVEL_KEYS",
    "load_robot_model",
    "resolve_robot_config",
    "robot_model_from_dict",
]
