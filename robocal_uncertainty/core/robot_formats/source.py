"""The one robot loader: a robot name (a robot YAML, a shipped model, a URDF file) or a URDF
text becomes a :class:`RobotSource`, the nominal model with the URDF chain it came from or maps
to. The command line, the nodes and ``export`` all load their robot through
:func:`load_robot_source`, so a format read by one is read by all.

Which module reads a name is decided by :func:`~robocal_uncertainty.core.robot_formats.registry.robot_format_of`
(by suffix); the module's ``read_robot`` does the reading.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.robot_formats.registry import robot_format_named, robot_format_of
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.urdf_model import UrdfChain, UrdfRobot, load_urdf, urdf_chain
from robocal_uncertainty.errors import ConfigError

__all__ = [
    "ExportRequest",
    "ReadRequest",
    "RobotSource",
    "Written",
    "load_robot_source",
    "robot_source_from_description",
]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class RobotSource:
    """A nominal robot model and, where there is one, the URDF chain it came from or maps to.

    Attributes
    ----------
    model : RobotModel
    urdf : UrdfRobot or None
        The URDF the model was read from, or the one given for a DH model (``--urdf``) once
        :meth:`with_structure` has read it, or None.
    base_link, tip_link : str or None
        The chain ends asked for.
    from_urdf : bool
        True when `model` was built from `urdf` (its base frame is the chain's base link).
    structure_file : Path or None
        A URDF for a DH model that is read only when it is needed (an export): ``--urdf``, or
        the file shipped beside a shipped model (``ur10``).
    """

    model: RobotModel
    urdf: UrdfRobot | None
    base_link: str | None = None
    tip_link: str | None = None
    from_urdf: bool = False
    structure_file: Path | None = None

    def with_structure(self) -> RobotSource:
        """This source with its URDF read (itself when it has one or none is named)."""
        if self.urdf is not None or self.structure_file is None:
            return self
        return replace(self, urdf=load_urdf(self.structure_file), structure_file=None)

    def chain(self) -> UrdfChain:
        """The URDF chain (``ConfigError`` without a URDF)."""
        if self.urdf is None:
            msg = f"robot {self.model.name!r} has no URDF: give one (--urdf robot.urdf)"
            raise ConfigError(msg)
        if self.from_urdf:
            return urdf_chain(self.urdf, self.base_link, self.tip_link)
        # A DH model mapped onto a URDF: by default the URDF joints of the model's names.
        base, tip = self.base_link, self.tip_link
        if base is None or tip is None:
            first = next((j for j in self.urdf.joints if j.name == self.model.joint_names[0]), None)
            last = next((j for j in self.urdf.joints if j.name == self.model.joint_names[-1]), None)
            if first is None or last is None:
                msg = (
                    f"{self.urdf.where} has no joints {self.model.joint_names[0]!r} ... "
                    f"{self.model.joint_names[-1]!r} of robot model {self.model.name!r}"
                )
                raise ConfigError(msg)
            base = base if base is not None else first.parent
            tip = tip if tip is not None else last.child
        return urdf_chain(self.urdf, base, tip)


@dataclass(frozen=True)
class ReadRequest:
    """What a reader is asked for besides the file.

    Attributes
    ----------
    base_link, tip_link : str or None
        Chain ends in a URDF (None: the root and the end of the first serial chain).
    tool_point : ndarray, shape (3,) [m], or None
        The measured point in the tip link when known (None: fitted, not regularised).
    urdf : str or None
        For a DH model: the URDF whose joint origins an export corrects.
    """

    base_link: str | None = None
    tip_link: str | None = None
    tool_point: Array | None = None
    urdf: str | None = None


@dataclass(frozen=True)
class ExportRequest:
    """What a writer gets: the calibrated and nominal models and where they came from.

    Attributes
    ----------
    calibrated : RobotModel
        The nominal model with the calibration applied.
    nominal : RobotModel
        The nominal model in the calibrated model's parameter layout.
    source : RobotSource
        The nominal robot, its URDF read (:meth:`RobotSource.with_structure`).
    comment : callable
        ``comment(what)``: the calibration's identity as comment lines, `what` their title.
    urdf_text : str or None
        The text of ``source.urdf`` when it is not a file (a ``robot_description`` parameter).
    """

    calibrated: RobotModel
    nominal: RobotModel
    source: RobotSource
    comment: Callable[[str], str]
    urdf_text: str | None = None


@dataclass(frozen=True)
class Written:
    """A writer's output: the file text and, for a chain format, the measured point it leaves out.

    Attributes
    ----------
    text : str
    point_in_tip : ndarray, shape (3,) [m], or None
        The calibrated measured point in the tip link frame (None: in the file itself).
    tip_link : str or None
    """

    text: str
    point_in_tip: Array | None = None
    tip_link: str | None = None


def load_robot_source(
    name: str,
    *,
    base_link: str | None = None,
    tip_link: str | None = None,
    tool_point: Sequence[float] | None = None,
    urdf: str | None = None,
    base_known: bool | None = None,
) -> RobotSource:
    """Load a robot: a robot YAML, a shipped model name (``paper_arm``, ``ur10``) or a URDF file.

    Parameters
    ----------
    name : str
        The file or shipped model name (``--robot``, the ``robot_config`` parameter).
    base_link, tip_link : str, optional
        Chain ends for a URDF (``--base-link``, ``--tip-link``).
    tool_point : sequence of 3 float [m], optional
        For a URDF: the measured point in the tip link when known (``--tool-point``).
    urdf : str, optional
        For a model given in DH form: a URDF whose joint origins an export corrects (e.g.
        ``xacro ur.urdf.xacro ur_type:=ur10 > ur10.urdf``); the shipped ``ur10`` has one.
    base_known : bool, optional
        Overrides the model's ``base_known`` (False: the base transform is identified).

    Raises
    ------
    ConfigError
        An unreadable or invalid file (the message names it), an unknown shipped name.
    """
    point = None if tool_point is None else np.asarray(tool_point, dtype=np.float64)
    request = ReadRequest(base_link=base_link, tip_link=tip_link, tool_point=point, urdf=urdf)
    read: Callable[[str, ReadRequest], RobotSource] = robot_format_of(name).load().read_robot
    source = read(name, request)
    if base_known is not None:
        source = replace(source, model=replace(source.model, base_known=base_known))
    return source


def robot_source_from_description(
    text: str,
    *,
    base_link: str | None = None,
    tip_link: str | None = None,
    where: str = "robot_description",
    tool_point: Sequence[float] | None = None,
    base_known: bool | None = None,
) -> RobotSource:
    """A :class:`RobotSource` from URDF text (a ``robot_description`` parameter or topic, which
    ROS defines as URDF); `tool_point` [m, in the tip link] when the measured point is known
    (None: fitted, not regularised; see :func:`~robocal_uncertainty.core.urdf_model.robot_model_from_urdf`)."""
    point = None if tool_point is None else np.asarray(tool_point, dtype=np.float64)
    request = ReadRequest(base_link=base_link, tip_link=tip_link, tool_point=point)
    read: Callable[..., RobotSource] = robot_format_named("urdf").load().read_robot_text
    source = read(text, request, where=where)
    if base_known is not None:
        source = replace(source, model=replace(source.model, base_known=base_known))
    return source
