"""Export a calibration to where robots run: a corrected URDF, UR kinematics, or a robot YAML.

- ``urdf``: the input URDF (or, for a model given in DH form without one, a URDF generated
  from the model) with every movable joint's ``<origin>`` corrected so that its forward
  kinematics equal the calibrated model's; fixed joints, links and everything else unchanged;
  the calibration's identity in a comment at the top.
- ``ur-kinematics``: the ``kinematics:`` YAML that ``ur_description`` reads as
  ``kinematics_params_file`` (per joint ``x y z roll pitch yaw`` of the joint origin, and a
  ``hash``), for a Universal Robots chain (``shoulder_pan_joint`` ... ``wrist_3_joint``).
- ``yaml``: the package's own robot YAML (modified DH, SI units) of the calibrated model.

Beside every export, :attr:`Export.sidecar` states the uncertainty that travels with it: the
parameters with their standard uncertainties, which of them the data determined, their
covariance where the calibration file holds one, the tracker placement (not part of a URDF)
and the calibrated measured point in the tip link frame.
"""

from __future__ import annotations

import hashlib
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from robocal_uncertainty.core.calibration_file import apply_calibration
from robocal_uncertainty.core.inverse_kinematics import UR_JOINT_NAMES
from robocal_uncertainty.core.robot_config import load_robot_model, resolve_robot_config
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
    urdf_chain,
    urdf_rpy,
)
from robocal_uncertainty.errors import ConfigError

__all__ = [
    "EXPORT_FORMATS",
    "SIDECAR_FORMAT",
    "UR_KINEMATICS_KEYS",
    "Export",
    "RobotSource",
    "calibrated_robot_description",
    "export_calibration",
    "load_robot_source",
]

Array = NDArray[np.float64]

EXPORT_FORMATS = ("urdf", "ur-kinematics", "yaml")
SIDECAR_FORMAT = "robocal_uncertainty/export-uncertainty/1"
UR_KINEMATICS_KEYS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")


@dataclass(frozen=True)
class RobotSource:
    """A nominal robot model and, where there is one, the URDF chain it came from or maps to.

    Attributes
    ----------
    model : RobotModel
    urdf : UrdfRobot or None
        The URDF read with ``--robot X.urdf``, or the one shipped beside a shipped model
        (``ur10``), or None.
    base_link, tip_link : str or None
        The chain ends asked for.
    from_urdf : bool
        True when `model` was built from `urdf` (its base frame is the chain's base link).
    """

    model: RobotModel
    urdf: UrdfRobot | None
    base_link: str | None = None
    tip_link: str | None = None
    from_urdf: bool = False

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


def is_urdf_source(name: str) -> bool:
    """Whether a ``--robot`` value names a URDF (``.urdf`` file) rather than a robot YAML."""
    return Path(name).suffix.lower() == ".urdf"


def load_robot_source(
    name: str,
    *,
    base_link: str | None = None,
    tip_link: str | None = None,
    urdf: str | None = None,
) -> RobotSource:
    """Resolve ``--robot`` (a robot YAML, a shipped model name, or a ``.urdf`` file).

    Parameters
    ----------
    name : str
        ``--robot`` value.
    base_link, tip_link : str, optional
        Chain ends for a URDF (``--base-link``, ``--tip-link``).
    urdf : str, optional
        A URDF whose joint origins an export corrects, for a model given in DH form (e.g.
        ``xacro ur.urdf.xacro ur_type:=ur10 > ur10.urdf``); the shipped ``ur10`` has one.
    """
    if is_urdf_source(name):
        robot = load_urdf(name)
        model = robot_model_from_urdf(robot, base_link, tip_link)
        return RobotSource(model=model, urdf=robot, base_link=base_link, tip_link=tip_link, from_urdf=True)
    path = resolve_robot_config(name)
    model = load_robot_model(path)
    structure: UrdfRobot | None = None
    if urdf is not None:
        structure = load_urdf(urdf)
    elif path.with_suffix(".urdf").is_file():
        structure = load_urdf(path.with_suffix(".urdf"))
    return RobotSource(model=model, urdf=structure, base_link=base_link, tip_link=tip_link)


def robot_source_from_description(
    text: str,
    *,
    base_link: str | None = None,
    tip_link: str | None = None,
    where: str = "robot_description",
    tool_point: Sequence[float] | None = None,
) -> RobotSource:
    """A :class:`RobotSource` from URDF text (a ``robot_description`` parameter or topic);
    `tool_point` [m, in the tip link] when the measured point is known (None: fitted, not
    regularised; see :func:`~robocal_uncertainty.core.urdf_model.robot_model_from_urdf`)."""
    robot = parse_urdf(text, where=where)
    point = None if tool_point is None else np.asarray(tool_point, dtype=np.float64)
    model = robot_model_from_urdf(robot, base_link, tip_link, tool_point=point)
    return RobotSource(model=model, urdf=robot, base_link=base_link, tip_link=tip_link, from_urdf=True)


@dataclass(frozen=True)
class Export:
    """An exported calibration.

    Attributes
    ----------
    format : {"urdf", "ur-kinematics", "yaml"}
    text : str
        The file content.
    sidecar : dict
        The uncertainty that travels with it (JSON-ready; see the module docstring).
    point_in_tip : ndarray, shape (3,) [m]
        The calibrated measured point in the tip link frame (``urdf``, ``ur-kinematics``).
    tip_link : str
    """

    format: str
    text: str
    sidecar: dict[str, Any]
    point_in_tip: Array
    tip_link: str


def _identity(data: dict[str, Any]) -> dict[str, Any]:
    """What identifies a calibration: robot, date, campaign, residuals, sources."""
    keys = ("created", "date", "campaign", "sources", "session", "seed")
    out: dict[str, Any] = {
        "robot": data.get("robot"),
        "model_name": data.get("model_name"),
        "format": data.get("format"),
    }
    out.update({k: data[k] for k in keys if k in data})
    for k in ("n_poses", "residual_rms_before_m", "residual_rms_after_m", "residual_max_after_m", "lambda"):
        out[k] = data.get(k)
    return out


def _comment(data: dict[str, Any], where: str, what: str, uncertainty: str = "the sidecar JSON") -> str:
    ident = _identity(data)
    lines = [
        f"{what} written by robocal-uncertainty export from {where}.",
        f"robot {ident['robot']!r}, model {ident['model_name']!r}, {ident['n_poses']} poses",
    ]
    for key in ("created", "date", "campaign", "sources"):
        if key in ident:
            lines.append(f"{key}: {ident[key]}")
    session = ident.get("session")
    if isinstance(session, dict):  # format 2: the session record (its covariances are in the sidecar)
        lines.append(
            f"session: campaign {session.get('campaign')}, {session.get('n_poses')} poses in the "
            f"{session.get('frame')} frame {session.get('frame_id')}; scope: {data.get('scope', 'session')}"
        )
    rms_b, rms_a = ident.get("residual_rms_before_m"), ident.get("residual_rms_after_m")
    if isinstance(rms_b, (int, float)) and isinstance(rms_a, (int, float)):
        lines.append(f"residual RMS {1e3 * rms_b:.4g} mm before, {1e3 * rms_a:.4g} mm after calibration")
    lines.append(f"The parameters' uncertainty and which of them the data determine: see {uncertainty}.")
    return "\n".join(lines)


def _covariance_entry(data: dict[str, Any]) -> Any:
    return data.get("parameter_covariance") or data.get("covariance")


def _covariance(data: dict[str, Any], names: list[str]) -> tuple[list[list[float]] | None, str]:
    """The calibration's covariance over `names` if it holds one, else None and why.

    Format 2 calibration files hold it as ``parameter_covariance: {names, matrix}`` (the
    estimated parameters' linearised covariance); an older ``covariance`` key is read too."""
    cov = _covariance_entry(data)
    matrix, order = None, names
    if isinstance(cov, dict):
        matrix = cov.get("matrix")
        order = cov.get("parameters") or cov.get("names") or names
    elif isinstance(cov, list):
        matrix = cov
    if matrix is None:
        return None, (
            "the calibration file states standard uncertainties only (no covariance): correlations "
            "between parameters are not stated here; the Monte Carlo of `evaluate` gives the full statement"
        )
    try:
        arr = np.asarray(matrix, dtype=np.float64)
    except (TypeError, ValueError):
        arr = np.zeros((0, 0))
    if arr.shape != (len(order), len(order)):
        return None, f"the calibration's covariance has shape {arr.shape}, not ({len(order)}, {len(order)}): left out"
    return (
        arr.tolist(),
        f"from the calibration file, over {len(order)} parameters (order: sidecar 'covariance_parameters')",
    )


def _sidecar(
    data: dict[str, Any], calibrated: RobotModel, point_in_tip: Array | None, tip: str | None
) -> dict[str, Any]:
    params = [p for p in data.get("parameters", []) if isinstance(p, dict)]
    names = [str(p.get("name")) for p in params]
    covariance, note = _covariance(data, names)
    cov = _covariance_entry(data)
    order = (cov.get("parameters") or cov.get("names")) if isinstance(cov, dict) else names
    return {
        "format": SIDECAR_FORMAT,
        "units": {"length": "m", "angle": "rad"},
        "calibration": _identity(data),
        "parameters": [
            {
                "name": p.get("name"),
                "unit": p.get("unit"),
                "nominal": p.get("nominal"),
                "estimate": p.get("estimate"),
                "determined_by_data": bool(p.get("estimated")),
                "standard_uncertainty": p.get("linearized_std"),
            }
            for p in params
        ],
        "not_identifiable": list(data.get("not_identifiable", [])),
        "covariance": covariance,
        "covariance_parameters": list(order or names) if covariance is not None else None,
        "covariance_note": note,
        "measurement_frame": {
            "note": (
                "world_T_base: the measurement (tracker) frame <- robot base; not part of a URDF "
                "(identity when the measurements were in the base frame)"
            ),
            "frame_id": calibrated.measurement_frame_id,
            "xyz": calibrated.base_xyz.tolist(),
            "rpy": calibrated.base_rpy.tolist(),
        },
        "measured_point_in_tip": None
        if point_in_tip is None
        else {"tip_link": tip, "xyz": [float(v) for v in point_in_tip]},
    }


def _fmt(value: float) -> str:
    return repr(float(value)) if value != 0.0 else "0"


def _clean(value: float) -> float:
    """``value`` as a float, with -0.0 written as 0.0."""
    return float(value) + 0.0


def _corrected_urdf_text(text: str, origins: dict[str, tuple[Array, Array]], comment: str, where: str) -> str:
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


def _generated_urdf(model: RobotModel, comment: str) -> tuple[str, Array, str]:
    """A URDF of a modified-DH model: one link per frame, joints at the model frames."""
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


def _q(value: str) -> str:
    return '"' + value.replace("&", "&amp;").replace('"', "&quot;").replace("<", "&lt;") + '"'


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


def _robot_yaml(model: RobotModel, comment: str) -> str:
    if any(model.prismatic) or model.mounted:
        msg = (
            f"robot model {model.name!r} comes from a URDF (a mount, prismatic joints), which the robot "
            "YAML cannot hold: use --format urdf"
        )
        raise ConfigError(msg)
    beta_rows = [j + 1 for j in range(model.n_joints) if model.has_beta[j]]
    joints = [
        {
            "name": name,
            "alpha": float(model.alpha[j]),
            "a": float(model.a[j]),
            "d": float(model.d[j]),
            "theta": float(model.theta[j]),
            "limits": [float(v) for v in model.joint_limits[j]],
        }
        for j, name in enumerate(model.joint_names)
    ]
    if any(model.beta[j] != 0.0 for j in range(model.n_joints)):
        # The robot YAML has no beta field: refuse rather than drop an identified beta.
        msg = (
            f"robot model {model.name!r} has identified Hayati beta rotations, which the robot YAML cannot "
            "hold: use --format urdf"
        )
        raise ConfigError(msg)
    data = {
        "name": model.name,
        "convention": "modified_dh",
        "units": {"length": "m", "angle": "rad"},
        "hayati_beta_joints": beta_rows,
        "joints": joints,
        "tool_point": [float(v) for v in model.tool_point],
        "base": {
            "known": model.base_known,
            "frame_id": model.base_frame_id,
            "measurement_frame_id": model.measurement_frame_id,
            "xyz": [float(v) for v in model.base_xyz],
            "rpy": [float(v) for v in model.base_rpy],
        },
    }
    header = "".join(f"# {line}\n" for line in comment.splitlines())
    return header + yaml.safe_dump(data, sort_keys=False, default_flow_style=None)


def _ur_kinematics(chain: UrdfChain, origins: dict[str, tuple[Array, Array]], comment: str) -> str:
    movable = chain.movable
    if len(movable) != 6 or not all(j.name.endswith(ur) for j, ur in zip(movable, UR_JOINT_NAMES)):
        msg = (
            f"--format ur-kinematics needs a Universal Robots chain ({', '.join(UR_JOINT_NAMES)}), "
            f"got {[j.name for j in movable]}"
        )
        raise ConfigError(msg)
    kin: dict[str, Any] = {}
    for key, joint in zip(UR_KINEMATICS_KEYS, movable):
        xyz, rpy = origins[joint.name]
        kin[key] = {
            "x": _clean(xyz[0]),
            "y": _clean(xyz[1]),
            "z": _clean(xyz[2]),
            "roll": _clean(rpy[0]),
            "pitch": _clean(rpy[1]),
            "yaw": _clean(rpy[2]),
        }
    digest = hashlib.sha256(repr(sorted((k, sorted(v.items())) for k, v in kin.items())).encode()).hexdigest()
    kin["hash"] = "calib_robocal_" + digest[:16]
    header = "".join(f"# {line}\n" for line in comment.splitlines())
    return header + yaml.safe_dump({"kinematics": kin}, sort_keys=False)


def export_calibration(
    data: dict[str, Any],
    source: RobotSource,
    fmt: str,
    *,
    where: str = "calibration",
    urdf_text: str | None = None,
    uncertainty: str = "the sidecar JSON",
) -> Export:
    """Export a calibration (what :func:`read_calibration` returns) in format `fmt`.

    Parameters
    ----------
    data : dict
        The calibration file's content.
    source : RobotSource
        The nominal robot the calibration was identified on (and its URDF, where there is one).
    fmt : {"urdf", "ur-kinematics", "yaml"}
    where : str
        Names the calibration in messages and in the exported file's comment.
    urdf_text : str, optional
        The text of ``source.urdf`` when it is not a file (a ``robot_description`` parameter).
    uncertainty : str
        Where the comment says the uncertainty is stated.

    Raises
    ------
    ConfigError
        Unknown format, a calibration of another robot, a URDF that does not describe the
        model, a non-UR chain for ``ur-kinematics``.
    """
    if fmt not in EXPORT_FORMATS:
        msg = f"unknown export format {fmt!r}; known: {', '.join(EXPORT_FORMATS)}"
        raise ConfigError(msg)
    calibrated = apply_calibration(source.model, data, where=where)
    nominal = source.model.with_tool_rotation() if calibrated.tool_rotation else source.model
    if fmt == "yaml":
        text = _robot_yaml(calibrated, _comment(data, where, "Calibrated robot model"))
        return Export(fmt, text, _sidecar(data, calibrated, None, None), np.zeros(3), "")
    if fmt == "urdf" and source.urdf is None:
        text, point, tip = _generated_urdf(
            calibrated, _comment(data, where, "Calibrated URDF (generated)", uncertainty)
        )
        return Export(fmt, text, _sidecar(data, calibrated, point, tip), point, tip)
    if fmt == "ur-kinematics" and source.urdf is None:
        msg = (
            f"--format ur-kinematics needs the robot's ur_description URDF for model {source.model.name!r}: "
            "give --urdf (xacro ur.urdf.xacro ur_type:=... name:=ur > ur.urdf)"
        )
        raise ConfigError(msg)
    chain = source.chain()
    origins, point = calibrated_joint_origins(chain, nominal, calibrated, frame0=_frame0(source, chain))
    assert source.urdf is not None
    if fmt == "urdf":
        raw = urdf_text
        if raw is None and Path(source.urdf.where).is_file():
            raw = Path(source.urdf.where).read_text(encoding="utf-8")
        if raw is None:
            msg = f"cannot read the URDF text of {source.urdf.where}"
            raise ConfigError(msg)
        text = _corrected_urdf_text(
            raw, origins, _comment(data, where, "Calibrated URDF", uncertainty), source.urdf.where
        )
    else:
        text = _ur_kinematics(chain, origins, _comment(data, where, "UR kinematics_params_file"))
    return Export(fmt, text, _sidecar(data, calibrated, point, chain.tip_link), point, chain.tip_link)


def calibrated_robot_description(data: dict[str, Any], source: RobotSource, *, urdf_text: str | None = None) -> str:
    """The calibrated URDF as a string, for a ``robot_description`` topic.

    Parameters
    ----------
    data : dict
        A calibration (``calibration_to_dict``).
    source : RobotSource
        The nominal robot.
    urdf_text : str, optional
        The URDF text the model was read from (a ``robot_description`` parameter); without it
        the URDF file of `source`, or one generated from the model.
    """
    note = "the node's calibration_file"
    return export_calibration(
        data, source, "urdf", where="calibration_node", urdf_text=urdf_text, uncertainty=note
    ).text
