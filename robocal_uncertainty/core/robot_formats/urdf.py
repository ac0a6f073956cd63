"""URDF as a robot format: read a nominal robot from a URDF chain, and write a calibration as
a URDF (the input URDF with corrected joint origins, or one generated for a DH model).

The chain model itself (parsing, chain extraction, the exact conversion to modified DH and back
to joint origins) is :mod:`robocal_uncertainty.core.urdf_model`; this module is the file format
around it.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.robot_formats.source import ExportRequest, ReadRequest, RobotSource, Written
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.urdf_model import (
    UrdfChain,
    UrdfRobot,
    calibrated_joint_origins,
    load_urdf,
    model_frames,
    parse_urdf,
    robot_model_from_urdf,
    transform,
    urdf_rpy,
)
from robocal_uncertainty.errors import ConfigError

__all__ = [
    "corrected_joint_origins",
    "corrected_urdf_text",
    "generated_urdf",
    "read_robot",
    "read_robot_text",
    "write_calibrated",
]

Array = NDArray[np.float64]


def read_robot(name: str, request: ReadRequest) -> RobotSource:
    """A URDF file as a :class:`RobotSource` (the reader of this format): the chain from
    ``request.base_link`` to ``request.tip_link`` converted to modified DH."""
    robot = load_urdf(name)
    model = robot_model_from_urdf(robot, request.base_link, request.tip_link, tool_point=request.tool_point)
    return RobotSource(model=model, urdf=robot, base_link=request.base_link, tip_link=request.tip_link, from_urdf=True)


def read_robot_text(text: str, request: ReadRequest, *, where: str = "robot_description") -> RobotSource:
    """URDF text (a ``robot_description`` parameter or topic) as a :class:`RobotSource`;
    `where` names it in messages."""
    robot = parse_urdf(text, where=where)
    model = robot_model_from_urdf(robot, request.base_link, request.tip_link, tool_point=request.tool_point)
    return RobotSource(model=model, urdf=robot, base_link=request.base_link, tip_link=request.tip_link, from_urdf=True)


def _fmt(value: float) -> str:
    return repr(float(value)) if value != 0.0 else "0"


def _q(value: str) -> str:
    return '"' + value.replace("&", "&amp;").replace('"', "&quot;").replace("<", "&lt;") + '"'


def corrected_urdf_text(text: str, origins: dict[str, tuple[Array, Array]], comment: str, where: str) -> str:
    """`text` (a URDF) with the ``<origin>`` of each joint named in `origins` set to its
    ``(xyz [m], rpy [rad])``, everything else kept, `comment` at the top."""
    try:
        root = ET.fromstring(text, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))
    except ET.ParseError as err:
        msg = f"{where} is not valid XML: {err}"
        raise ConfigError(msg) from err
    for joint in root.findall("joint"):
        name = joint.get("name")
        if name not in origins:
            continue
        xyz, rpy = origins[name]
        origin = joint.find("origin")
        if origin is None:
            origin = ET.SubElement(joint, "origin")
        origin.set("xyz", " ".join(_fmt(v) for v in xyz))
        origin.set("rpy", " ".join(_fmt(v) for v in rpy))
    note = ET.Comment(" " + comment.replace("--", "- -").replace("\n", "\n     ") + " ")
    note.tail = "\n  "
    root.insert(0, note)
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def generated_urdf(model: RobotModel, comment: str) -> tuple[str, Array, str]:
    """A URDF of a modified-DH model: one link per frame, joints at the model frames.

    Returns
    -------
    text : str
    point_in_tip : ndarray, shape (3,) [m]
        Zeros: the measured point is a link of its own.
    tip_link : str
        ``measured_point``.
    """
    frames, _ = model_frames(model)
    base = model.base_frame_id
    links = [base] + [f"{name}_link" for name in model.joint_names] + ["flange", "measured_point"]
    body = [f"  <link name={_q(link)}/>" for link in links]
    previous = np.eye(4)
    for j, name in enumerate(model.joint_names):
        origin = np.linalg.inv(previous) @ frames[j]
        kind = "prismatic" if model.prismatic[j] else "revolute"
        lo, hi = model.joint_limits[j]
        body.append(
            f"  <joint name={_q(name)} type={_q(kind)}>\n"
            f"    <parent link={_q(links[j])}/><child link={_q(links[j + 1])}/>\n"
            f"    <origin xyz={_q(' '.join(_fmt(v) for v in origin[:3, 3]))} "
            f"rpy={_q(' '.join(_fmt(v) for v in urdf_rpy(origin[:3, :3])))}/>\n"
            f'    <axis xyz="0 0 1"/>\n    <limit lower={_q(_fmt(lo))} upper={_q(_fmt(hi))} effort="0" velocity="0"/>\n'
            "  </joint>"
        )
        previous = previous @ transform(origin[:3, 3], urdf_rpy(origin[:3, :3]))
    flange = np.linalg.inv(previous) @ frames[-1]
    body.append(
        f'  <joint name="flange_joint" type="fixed">\n    <parent link={_q(links[-3])}/><child link="flange"/>\n'
        f"    <origin xyz={_q(' '.join(_fmt(v) for v in flange[:3, 3]))} "
        f"rpy={_q(' '.join(_fmt(v) for v in urdf_rpy(flange[:3, :3])))}/>\n  </joint>"
    )
    body.append(
        '  <joint name="measured_point_joint" type="fixed">\n'
        '    <parent link="flange"/><child link="measured_point"/>\n'
        f"    <origin xyz={_q(' '.join(_fmt(v) for v in model.tool_point))} "
        f"rpy={_q(' '.join(_fmt(v) for v in model.tool_rpy))}/>\n  </joint>"
    )
    text = (
        '<?xml version="1.0"?>\n<robot name=' + _q(model.name) + ">\n  <!-- " + comment.replace("--", "- -") + " -->\n"
    )
    return text + "\n".join(body) + "\n</robot>\n", np.zeros(3), "measured_point"


def _link_pose(robot: UrdfRobot, link: str) -> Array:
    """Root link <- `link` at zero joint readings."""
    out = np.eye(4)
    joint = robot.parent_joint(link)
    while joint is not None:
        out = joint.origin @ out
        joint = robot.parent_joint(joint.parent)
    return out


def _frame0(source: RobotSource, chain: UrdfChain) -> Array | None:
    """Chain base link <- the model's base frame (None: they are the same frame)."""
    if source.from_urdf:
        return None
    base_id = source.model.base_frame_id
    if base_id == chain.base_link:
        return None
    robot = chain.robot
    if base_id not in robot.links:
        # A DH model on a URDF whose links do not name its base: the chain's base it is.
        return None
    return np.asarray(np.linalg.inv(_link_pose(robot, chain.base_link)) @ _link_pose(robot, base_id))


def corrected_joint_origins(request: ExportRequest) -> tuple[UrdfChain, dict[str, tuple[Array, Array]], Array]:
    """The source's URDF chain, its movable joints' calibrated origins ``(xyz [m], rpy [rad])``
    and the calibrated measured point in the tip link [m]."""
    chain = request.source.chain()
    origins, point = calibrated_joint_origins(
        chain, request.nominal, request.calibrated, frame0=_frame0(request.source, chain)
    )
    return chain, origins, point


def write_calibrated(request: ExportRequest) -> Written:
    """The calibration as a URDF (the writer of this format): the source's URDF with corrected
    joint origins, or a URDF generated from the calibrated model when the source has none."""
    source = request.source
    if source.urdf is None:
        text, point, tip = generated_urdf(request.calibrated, request.comment("Calibrated URDF (generated)"))
        return Written(text, point, tip)
    chain, origins, point = corrected_joint_origins(request)
    raw = request.urdf_text
    if raw is None and Path(source.urdf.where).is_file():
        raw = Path(source.urdf.where).read_text(encoding="utf-8")
    if raw is None:
        msg = f"cannot read the URDF text of {source.urdf.where}"
        raise ConfigError(msg)
    text = corrected_urdf_text(raw, origins, request.comment("Calibrated URDF"), source.urdf.where)
    return Written(text, point, chain.tip_link)
