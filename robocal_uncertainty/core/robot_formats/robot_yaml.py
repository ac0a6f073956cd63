"""The package's robot YAML: read a :class:`RobotModel` from it (units stated in the file), and
write a calibrated model back to it (modified DH, SI units).

Example (``config/paper_arm.yaml``)::

    name: paper_arm
    convention: modified_dh        # or standard_dh (converted exactly)
    units: {length: mm, angle: deg}
    hayati_beta_joints: [3, 4]     # rows whose axis is parallel to the previous one
    joints:
      - {name: joint1, alpha: 0, a: 0, d: 99.927, theta: 0, limits: [-180, 180]}
      ...
    tool_point: [0, 0, 0]          # in the flange frame
    base:                          # measurement frame <- robot base
      known: true
      xyz: [0, 0, 0]
      rpy: [0, 0, 0]

For ``standard_dh`` each joint gives its own ``alpha_i, a_i, d_i, theta_i``; the model is
converted exactly: modified row ``i`` takes ``alpha_{i-1}, a_{i-1}`` of standard row ``i-1``
and the last row's ``alpha_n, a_n`` move into the tool point (they commute, both about x).
"""

from __future__ import annotations

from difflib import get_close_matches
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from robocal_uncertainty.core.robot_formats.registry import robot_format_named
from robocal_uncertainty.core.robot_formats.source import ExportRequest, ReadRequest, RobotSource, Written
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.errors import ConfigError

__all__ = [
    "ANGLE_UNITS",
    "LENGTH_UNITS",
    "TOP_LEVEL_KEYS",
    "load_robot_model",
    "read_robot",
    "resolve_robot_config",
    "robot_model_from_dict",
    "robot_yaml_text",
    "write_calibrated",
]

LENGTH_UNITS: dict[str, float] = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6}
ANGLE_UNITS: dict[str, float] = {"rad": 1.0, "deg": float(np.pi / 180.0)}
_JOINT_KEYS = {"name", "alpha", "a", "d", "theta", "limits"}
TOP_LEVEL_KEYS: tuple[str, ...] = ("name", "convention", "units", "joints", "hayati_beta_joints", "tool_point", "base")
"""Every top-level field a robot YAML may have; any other (a typo) is refused."""
_BASE_KEYS: tuple[str, ...] = ("known", "xyz", "rpy", "frame_id", "measurement_frame_id")


def _unknown_fields(given: dict[Any, Any], known: tuple[str, ...] | set[str], what: str) -> str | None:
    """One line naming the unknown fields of `given` and the known field each resembles."""
    unknown = sorted(str(k) for k in given if k not in known)
    if not unknown:
        return None
    parts = []
    for key in unknown:
        close = get_close_matches(key, sorted(known), n=1, cutoff=0.6)
        parts.append(f"{key!r} (did you mean {close[0]!r}?)" if close else repr(key))
    return f"{what} {'field' if len(unknown) == 1 else 'fields'} {', '.join(parts)} (known: {', '.join(sorted(known))})"


def _unit(units: dict[str, Any], key: str, table: dict[str, float], where: str) -> float:
    if key not in units:
        msg = f"{where}: 'units' must state '{key}' (one of {', '.join(table)})"
        raise ConfigError(msg)
    name = str(units[key])
    if name not in table:
        msg = f"{where}: unknown {key} unit {name!r} (known: {', '.join(table)})"
        raise ConfigError(msg)
    return table[name]


def _number(value: object, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        msg = f"{what} must be a number, got {value!r}"
        raise ConfigError(msg)
    if not np.isfinite(value):
        msg = f"{what} must be finite, got {value!r}"
        raise ConfigError(msg)
    return float(value)


def _vector3(value: object, what: str) -> list[float]:
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        msg = f"{what} must be a list of 3 numbers, got {value!r}"
        raise ConfigError(msg)
    return [_number(v, f"{what}[{i}]") for i, v in enumerate(value)]


def _rot_x(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _joint_rows(
    joints: list[Any], to_m: float, to_rad: float, where: str
) -> tuple[list[str], dict[str, list[float]], list[list[float]]]:
    """Names, DH rows (SI) and limits [rad] of the ``joints`` list, each joint checked."""
    names: list[str] = []
    rows: dict[str, list[float]] = {"alpha": [], "a": [], "d": [], "theta": []}
    limits: list[list[float]] = []
    for i, joint in enumerate(joints, start=1):
        if not isinstance(joint, dict):
            msg = f"{where}: joint {i} must be a mapping"
            raise ConfigError(msg)
        unknown = _unknown_fields(joint, _JOINT_KEYS, f"joint {i} has unknown")
        if unknown is not None:
            raise ConfigError(f"{where}: {unknown}")
        for key in ("name", "alpha", "a", "d"):
            if key not in joint:
                msg = f"{where}: joint {i} is missing '{key}'"
                raise ConfigError(msg)
        names.append(str(joint["name"]))
        rows["alpha"].append(_number(joint["alpha"], f"joint {i} alpha") * to_rad)
        rows["a"].append(_number(joint["a"], f"joint {i} a") * to_m)
        rows["d"].append(_number(joint["d"], f"joint {i} d") * to_m)
        rows["theta"].append(_number(joint.get("theta", 0.0), f"joint {i} theta") * to_rad)
        lim = joint.get("limits", [-360.0 * ANGLE_UNITS["deg"] / to_rad, 360.0 * ANGLE_UNITS["deg"] / to_rad])
        if not isinstance(lim, (list, tuple)) or len(lim) != 2:
            msg = f"{where}: joint {i} limits must be [lower, upper]"
            raise ConfigError(msg)
        limits.append([_number(lim[0], f"joint {i} limits") * to_rad, _number(lim[1], f"joint {i} limits") * to_rad])
    if len(set(names)) != len(names):
        msg = f"{where}: joint names must be unique, got {names}"
        raise ConfigError(msg)
    return names, rows, limits


def _base_mapping(data: dict[str, Any], where: str) -> dict[str, Any]:
    """The ``base`` mapping (empty when absent), its fields checked."""
    base = data.get("base", {})
    if not isinstance(base, dict):
        msg = f"{where}: 'base' must be a mapping with known, xyz, rpy"
        raise ConfigError(msg)
    unknown_base = _unknown_fields(base, _BASE_KEYS, "base has unknown")
    if unknown_base is not None:
        raise ConfigError(f"{where}: {unknown_base}")
    return base


def robot_model_from_dict(data: object, *, where: str = "robot config") -> RobotModel:
    """Build a :class:`RobotModel` from the parsed YAML mapping (see module docstring).

    Raises
    ------
    ConfigError
        Missing fields, unknown units or conventions, malformed numbers.
    """
    if not isinstance(data, dict):
        msg = f"{where}: expected a mapping at top level, got {type(data).__name__}"
        raise ConfigError(msg)
    unknown_top = _unknown_fields(data, TOP_LEVEL_KEYS, "unknown top-level")
    if unknown_top is not None:
        # A misspelt optional field (tool_piont, hayati_beta_joint) would otherwise give
        # another model without a word.
        raise ConfigError(f"{where}: {unknown_top}")
    for key in ("name", "convention", "units", "joints"):
        if key not in data:
            msg = f"{where}: missing required field '{key}'"
            raise ConfigError(msg)
    units = data["units"]
    if not isinstance(units, dict):
        msg = f"{where}: 'units' must be a mapping like {{length: mm, angle: deg}}"
        raise ConfigError(msg)
    to_m = _unit(units, "length", LENGTH_UNITS, where)
    to_rad = _unit(units, "angle", ANGLE_UNITS, where)
    convention = data["convention"]
    if convention not in ("modified_dh", "standard_dh"):
        msg = f"{where}: convention must be 'modified_dh' or 'standard_dh', got {convention!r}"
        raise ConfigError(msg)
    joints = data["joints"]
    if not isinstance(joints, list) or not joints:
        msg = f"{where}: 'joints' must be a non-empty list"
        raise ConfigError(msg)
    names, rows, limits = _joint_rows(joints, to_m, to_rad, where)
    n = len(names)
    tool = np.array(_vector3(data.get("tool_point", [0.0, 0.0, 0.0]), f"{where}: tool_point")) * to_m
    alpha = np.array(rows["alpha"])
    a = np.array(rows["a"])
    if convention == "standard_dh":
        # Row i of modified DH carries alpha_{i-1}, a_{i-1} of standard DH; the last
        # standard row's twist and length become a fixed flange offset folded into the tool.
        tool = _rot_x(alpha[-1]) @ tool + np.array([a[-1], 0.0, 0.0])
        alpha = np.concatenate(([0.0], alpha[:-1]))
        a = np.concatenate(([0.0], a[:-1]))
    beta_joints = data.get("hayati_beta_joints", [])
    if not isinstance(beta_joints, list) or any(
        isinstance(j, bool) or not isinstance(j, int) or not 1 <= j <= n for j in beta_joints
    ):
        msg = f"{where}: hayati_beta_joints must list joint numbers 1..{n}, got {beta_joints!r}"
        raise ConfigError(msg)
    base = _base_mapping(data, where)
    return RobotModel(
        name=str(data["name"]),
        joint_names=tuple(names),
        alpha=alpha,
        a=a,
        theta=np.array(rows["theta"]),
        d=np.array(rows["d"]),
        beta=np.zeros(n),
        has_beta=tuple((j + 1) in beta_joints for j in range(n)),
        joint_limits=np.array(limits),
        tool_point=tool,
        base_xyz=np.array(_vector3(base.get("xyz", [0.0, 0.0, 0.0]), f"{where}: base.xyz")) * to_m,
        base_rpy=np.array(_vector3(base.get("rpy", [0.0, 0.0, 0.0]), f"{where}: base.rpy")) * to_rad,
        base_known=bool(base.get("known", True)),
        base_frame_id=str(base.get("frame_id", "base_link")),
        measurement_frame_id=str(base.get("measurement_frame_id", "laser_tracker")),
    )


def load_robot_model(path: str | Path) -> RobotModel:
    """Read a robot model YAML file (``yaml.safe_load``) and build the model.

    Parameters
    ----------
    path : str or Path
        YAML file with explicit units.

    Raises
    ------
    ConfigError
        File missing or unreadable, invalid YAML, or invalid content (names the problem).
    """
    file = Path(path)
    try:
        text = file.read_text(encoding="utf-8")
    except OSError as err:
        msg = f"cannot read robot config {file}: {err.strerror}"
        raise ConfigError(msg) from err
    except UnicodeDecodeError as err:
        msg = f"robot config {file} is not UTF-8 text (byte {err.start})"
        raise ConfigError(msg) from err
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(err, "problem", None) or str(err).splitlines()[0]
        msg = f"robot config {file} is not valid YAML{where}: {problem}"
        raise ConfigError(msg) from err
    return robot_model_from_dict(data, where=str(file))


def resolve_robot_config(name: str) -> Path:
    """A robot YAML path, or the name of a shipped model (``paper_arm``, ``ur10``).

    Raises
    ------
    ConfigError
        Neither an existing file nor a shipped model.
    """
    path = Path(name).expanduser()
    if path.exists() or path.suffix in (".yaml", ".yml"):
        return path
    shipped = resources.files("robocal_uncertainty") / "data" / f"{name}.yaml"
    if shipped.is_file():
        return Path(str(shipped))
    msg = f"robot config {name!r} is neither a file nor a shipped model (paper_arm, ur10)"
    raise ConfigError(msg)


def read_robot(name: str, request: ReadRequest) -> RobotSource:
    """A robot YAML or a shipped model name as a :class:`RobotSource` (the reader of this format).

    The chain ends of `request` name links of its URDF (``request.urdf``, else the URDF beside
    the YAML), which is read only when an export needs it. Every error message names the file.
    """
    if request.tool_point is not None:
        msg = f"a tool point given apart describes a URDF chain; robot config {name} gives its own tool_point"
        raise ConfigError(msg)
    path = resolve_robot_config(name)
    try:
        model = load_robot_model(path)
    except ConfigError as err:
        if str(path) in str(err) or Path(path).name in str(err):
            raise
        msg = f"robot config {path}: {err}"  # every message names the file it is about
        raise ConfigError(msg) from err
    # A URDF beside the YAML (same name) is the structure an export corrects.
    companion = path.with_suffix(robot_format_named("urdf").suffixes[0])
    structure = Path(request.urdf) if request.urdf is not None else companion if companion.is_file() else None
    return RobotSource(
        model=model, urdf=None, base_link=request.base_link, tip_link=request.tip_link, structure_file=structure
    )


def robot_yaml_text(model: RobotModel, comment: str) -> str:
    """`model` as a robot YAML (modified DH, m and rad), `comment` as ``#`` lines at the top.

    Raises
    ------
    ConfigError
        A model the YAML cannot hold: one read from a URDF (a mount, prismatic joints), or with
        identified Hayati beta rotations (the YAML has no beta field).
    """
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
    body: str = yaml.safe_dump(data, sort_keys=False, default_flow_style=None)
    return header + body


def write_calibrated(request: ExportRequest) -> Written:
    """The calibrated model as a robot YAML (the writer of this format)."""
    return Written(robot_yaml_text(request.calibrated, request.comment("Calibrated robot model")))
