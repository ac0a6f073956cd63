"""Robot model formats: one module per format, a registry naming them, one loader.

- :mod:`.registry`: every format by name and file suffix (the one place a suffix is tested);
- :mod:`.source`: :func:`load_robot_source`, the loader the command line, the nodes and
  ``export`` share, and the types readers and writers exchange;
- :mod:`.protocol`: what identification, Monte Carlo and export need from a chain;
- :mod:`.robot_yaml` (read, write), :mod:`.urdf` (read, write), :mod:`.ur_kinematics`
  (write): the formats.

How to add a format: ``docs/extending.md``.
"""

from __future__ import annotations

from robocal_uncertainty.core.robot_formats.registry import (
    EXPORT_FORMATS,
    ROBOT_FORMATS,
    RobotFormat,
    robot_format_named,
    robot_format_of,
)
from robocal_uncertainty.core.robot_formats.source import (
    ExportRequest,
    ReadRequest,
    RobotSource,
    Written,
    load_robot_source,
    robot_source_from_description,
)

__all__ = [
    "EXPORT_FORMATS",
    "ROBOT_FORMATS",
    "ExportRequest",
    "ReadRequest",
    "RobotFormat",
    "RobotSource",
    "Written",
    "load_robot_source",
    "robot_format_named",
    "robot_format_of",
    "robot_source_from_description",
]
