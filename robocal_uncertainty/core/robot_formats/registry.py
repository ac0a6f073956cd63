"""The robot model formats, by name and by file suffix: the one place that says which module
reads or writes a format.

A format module (one per format, beside this one) defines ``read_robot(path, request)`` when the
format can be read as a nominal robot, and ``write_calibrated(request)`` when a calibration can be
exported to it. The table names modules rather than importing them, so the command line can list
the export formats without importing numpy; a module is imported when it is first used.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import import_module
from pathlib import Path
from types import ModuleType

__all__ = ["DEFAULT_FORMAT", "EXPORT_FORMATS", "ROBOT_FORMATS", "RobotFormat", "robot_format_named", "robot_format_of"]


@dataclass(frozen=True)
class RobotFormat:
    """A robot model format.

    Attributes
    ----------
    name : str
        The format's name (``--format`` of ``export`` for a writable one).
    suffixes : tuple of str
        File suffixes (lower case, with the dot) that name the format when read.
    module : str
        The module holding its ``read_robot`` and/or ``write_calibrated``.
    readable, writable : bool
        Whether the module reads a nominal robot / writes a calibrated one.
    chain_ends : bool
        Whether reading it takes chain ends and a tool point (``--base-link``, ``--tip-link``,
        ``--tool-point``; the nodes' ``base_link``, ``tip_link``, ``tool_point_m``).
    """

    name: str
    suffixes: tuple[str, ...]
    module: str
    readable: bool
    writable: bool
    chain_ends: bool = False

    def load(self) -> ModuleType:
        """The format's module (imported on first use)."""
        return import_module(self.module)


_PACKAGE = "robocal_uncertainty.core.robot_formats"

ROBOT_FORMATS: tuple[RobotFormat, ...] = (
    RobotFormat("urdf", (".urdf",), f"{_PACKAGE}.urdf", readable=True, writable=True, chain_ends=True),
    RobotFormat("ur-kinematics", (), f"{_PACKAGE}.ur_kinematics", readable=False, writable=True),
    RobotFormat("yaml", (".yaml", ".yml"), f"{_PACKAGE}.robot_yaml", readable=True, writable=True),
)
"""Every format; the order is the order the export formats are listed in."""

DEFAULT_FORMAT = "yaml"
"""What a robot name without a known suffix is read as: a robot YAML or a shipped model name."""

EXPORT_FORMATS: tuple[str, ...] = tuple(f.name for f in ROBOT_FORMATS if f.writable)


def robot_format_of(name: str | Path) -> RobotFormat:
    """The readable format a robot file name (or a shipped model name) is in, by its suffix."""
    suffix = Path(name).suffix.lower()
    for fmt in ROBOT_FORMATS:
        if fmt.readable and suffix in fmt.suffixes:
            return fmt
    return next(f for f in ROBOT_FORMATS if f.name == DEFAULT_FORMAT)


def robot_format_named(name: str) -> RobotFormat:
    """The format called `name` (``KeyError`` if none)."""
    for fmt in ROBOT_FORMATS:
        if fmt.name == name:
            return fmt
    raise KeyError(name)
