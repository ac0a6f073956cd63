"""Robot models from a URDF joint chain, and the chain's joint origins from a calibrated model.

A URDF describes a serial arm as a tree of links joined by joints, each with a fixed
``<origin xyz rpy>`` (parent link <- joint frame at zero reading) and an ``<axis>`` in the joint
frame. :func:`robot_model_from_urdf` takes the chain from a base link to a tip link (by default
the root and the end of the first serial chain), folds the fixed joints into their neighbours
and converts the chain exactly to the package's modified-DH model:

- frame 0 of the modified-DH chain is placed on the first joint axis; the transform base link
  <- frame 0 is the model's ``mount`` (parameters ``mount.*``: with measurements in the base link
  they carry the first axis's place and direction, which the first row alone cannot; with a
  tracker frame the base transform duplicates them and the observability report drops them);
- each further axis is placed relative to the previous one by the common normal (``alpha, a``
  on the row, ``theta, d`` on the previous row); where the axes are parallel within
  :data:`HAYATI_ANGLE` the row uses Hayati's ``beta`` instead of the ill-defined common normal;
- the tip link's frame (and the measured point in it, ``tool_point``) is the tool.

The identification then estimates these parameters and the structural observability drops the
combinations the data cannot tell apart, as for a model given in DH form.

:func:`calibrated_joint_origins` goes the other way: given the nominal and the calibrated model
and a URDF chain whose joint axes coincide with the model's, it returns the joint origins that
make the URDF's forward kinematics equal the calibrated model's (fixed joints kept).

xacro is not read: expand it first (``xacro robot.urdf.xacro > robot.urdf``).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.robot_model import RobotModel, rpy_from_matrix, rpy_to_matrix
from robocal_uncertainty.errors import ConfigError

__all__ = [
    "HAYATI_ANGLE",
    "UrdfChain",
    "UrdfJoint",
    "UrdfRobot",
    "calibrated_joint_origins",
    "chain_frames",
    "load_urdf",
    "model_frames",
    "parse_urdf",
    "robot_model_from_urdf",
    "transform",
    "urdf_chain",
    "urdf_rpy",
]

Array = NDArray[np.float64]

HAYATI_ANGLE = 0.01
"""Consecutive axes closer to parallel than this [rad] get a Hayati ``beta`` row."""

_MOVABLE = ("revolute", "continuous", "prismatic")
_KNOWN_TYPES = (*_MOVABLE, "fixed", "floating", "planar")
_AXIS_TOL = 1e-9
"""Allowed misfit [m, rad] between a URDF joint axis and the model's axis when mapping them."""


def transform(xyz: Array | tuple[float, ...], rpy: Array | tuple[float, ...]) -> Array:
    """Homogeneous transform of a URDF ``<origin xyz rpy>``, shape (4, 4) [m]."""
    out = np.eye(4)
    out[:3, :3] = rpy_to_matrix(np.asarray(rpy, dtype=np.float64))
    out[:3, 3] = np.asarray(xyz, dtype=np.float64)
    return out


def urdf_rpy(rotation: Array) -> Array:
    """Roll, pitch, yaw [rad] of ``Rz(yaw) Ry(pitch) Rx(roll)``, exact also at pitch ±pi/2.

    At gimbal lock (``|r20| = 1``) roll is 0 and yaw carries the whole turn about the axis.
    """
    r = np.asarray(rotation, dtype=np.float64)
    if abs(r[2, 0]) < 1.0 - 1e-12:
        return rpy_from_matrix(r)
    pitch = math.copysign(math.pi / 2.0, -r[2, 0])
    return np.array([0.0, pitch, math.atan2(-r[0, 1], r[1, 1])])


def _inv(t: Array) -> Array:
    out = np.eye(4)
    out[:3, :3] = t[:3, :3].T
    out[:3, 3] = -t[:3, :3].T @ t[:3, 3]
    return out


def _rot(axis: int, angle: float) -> Array:
    c, s = math.cos(angle), math.sin(angle)
    out = np.eye(4)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    out[i, i], out[i, j], out[j, i], out[j, j] = c, -s, s, c
    return out


def _trans(axis: int, dist: float) -> Array:
    out = np.eye(4)
    out[axis, 3] = dist
    return out


@dataclass(frozen=True)
class UrdfJoint:
    """One ``<joint>`` of a URDF, SI units (lengths m, angles rad).

    Attributes
    ----------
    name, type, parent, child : str
    xyz, rpy : tuple of 3 float
        ``<origin>``: parent link <- joint frame at zero reading.
    axis : tuple of 3 float
        Unit axis in the joint frame (URDF default ``1 0 0``).
    lower, upper : float or None
        ``<limit>`` of a revolute or prismatic joint [rad or m].
    mimic : str or None
        The joint this one mimics.
    """

    name: str
    type: str
    parent: str
    child: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    axis: tuple[float, float, float]
    lower: float | None
    upper: float | None
    mimic: str | None

    @property
    def origin(self) -> Array:
        """``<origin>`` as a homogeneous transform, shape (4, 4)."""
        return transform(self.xyz, self.rpy)


@dataclass(frozen=True)
class UrdfRobot:
    """The links and joints of a URDF (a tree: every link has at most one parent joint)."""

    name: str
    links: tuple[str, ...]
    joints: tuple[UrdfJoint, ...]
    where: str

    def parent_joint(self, link: str) -> UrdfJoint | None:
        """The joint whose child is `link`, or None for the root."""
        return next((j for j in self.joints if j.child == link), None)

    def child_joints(self, link: str) -> list[UrdfJoint]:
        """Joints whose parent is `link`, in document order."""
        return [j for j in self.joints if j.parent == link]


@dataclass(frozen=True)
class UrdfChain:
    """The joints from `base_link` to `tip_link` (fixed ones included), in order.

    `base_link` may hang off the chain by fixed joints (UR's ``base``, a child of ``base_link``
    like the arm): `joints` then start at the link both descend from and `base_offset` is
    ``base_link <- that link`` (identity when `base_link` is upstream of the tip).
    """

    robot: UrdfRobot
    base_link: str
    tip_link: str
    joints: tuple[UrdfJoint, ...]
    base_offset: Array = field(default_factory=lambda: np.eye(4))

    @property
    def movable(self) -> tuple[UrdfJoint, ...]:
        """The revolute, continuous and prismatic joints of the chain, in order."""
        return tuple(j for j in self.joints if j.type in _MOVABLE)


def _floats(text: str | None, default: tuple[float, float, float], what: str) -> tuple[float, float, float]:
    if text is None:
        return default
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        values = []
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        msg = f"{what} must be 3 finite numbers, got {text!r}"
        raise ConfigError(msg)
    return (values[0], values[1], values[2])


def _limit(element: ET.Element | None, key: str, what: str) -> float | None:
    if element is None or element.get(key) is None:
        return None
    try:
        value = float(element.get(key, ""))
    except ValueError:
        value = float("nan")
    if not math.isfinite(value):
        msg = f"{what} limit {key}={element.get(key)!r} is not a finite number"
        raise ConfigError(msg)
    return value


def _parse_joint(element: ET.Element, where: str) -> UrdfJoint:
    name = element.get("name")
    if not name:
        msg = f"{where}: a <joint> has no name"
        raise ConfigError(msg)
    what = f"{where}: joint {name!r}"
    kind = element.get("type", "")
    if kind not in _KNOWN_TYPES:
        msg = f"{what} has type {kind!r}; known: {', '.join(_KNOWN_TYPES)}"
        raise ConfigError(msg)
    ends = {}
    for tag in ("parent", "child"):
        node = element.find(tag)
        link = node.get("link") if node is not None else None
        if not link:
            msg = f"{what} has no <{tag} link=...>"
            raise ConfigError(msg)
        ends[tag] = link
    origin = element.find("origin")
    xyz = _floats(origin.get("xyz") if origin is not None else None, (0.0, 0.0, 0.0), f"{what} origin xyz")
    rpy = _floats(origin.get("rpy") if origin is not None else None, (0.0, 0.0, 0.0), f"{what} origin rpy")
    axis_node = element.find("axis")
    axis = _floats(axis_node.get("xyz") if axis_node is not None else None, (1.0, 0.0, 0.0), f"{what} axis")
    norm = math.sqrt(sum(a * a for a in axis))
    if kind in _MOVABLE and norm < 1e-9:
        msg = f"{what} has a zero axis"
        raise ConfigError(msg)
    if norm > 0:
        axis = (axis[0] / norm, axis[1] / norm, axis[2] / norm)
    limit = element.find("limit")
    lower, upper = _limit(limit, "lower", what), _limit(limit, "upper", what)
    mimic = element.find("mimic")
    return UrdfJoint(
        name=name,
        type=kind,
        parent=ends["parent"],
        child=ends["child"],
        xyz=xyz,
        rpy=rpy,
        axis=axis,
        lower=lower,
        upper=upper,
        mimic=(mimic.get("joint") or "?") if mimic is not None else None,
    )


def _parse_links(root: ET.Element, where: str) -> list[str]:
    """The link names, each named once."""
    links: list[str] = []
    for element in root.findall("link"):
        name = element.get("name")
        if not name:
            msg = f"{where}: a <link> has no name"
            raise ConfigError(msg)
        if name in links:
            msg = f"{where}: link {name!r} is defined twice"
            raise ConfigError(msg)
        links.append(name)
    return links


def _parse_joints(root: ET.Element, links: list[str], where: str) -> list[UrdfJoint]:
    """The joints, each named once, between defined links, no link the child of two joints."""
    joints: list[UrdfJoint] = []
    for element in root.findall("joint"):
        joint = _parse_joint(element, where)
        if any(j.name == joint.name for j in joints):
            msg = f"{where}: joint {joint.name!r} is defined twice"
            raise ConfigError(msg)
        for end in (joint.parent, joint.child):
            if end not in links:
                msg = f"{where}: joint {joint.name!r} names link {end!r}, which the URDF does not define"
                raise ConfigError(msg)
        other = next((j for j in joints if j.child == joint.child), None)
        if other is not None:
            msg = (
                f"{where}: link {joint.child!r} is the child of joints {other.name!r} and {joint.name!r}: "
                "a kinematic loop (a URDF describes a tree)"
            )
            raise ConfigError(msg)
        joints.append(joint)
    return joints


def _check_tree(robot: UrdfRobot) -> None:
    """Refuse a kinematic loop or several root links."""
    where, links = robot.where, robot.links
    for link in links:
        seen = {link}
        up = robot.parent_joint(link)
        while up is not None:
            if up.parent in seen:
                msg = f"{where}: joint {up.name!r} closes a kinematic loop through link {up.parent!r}"
                raise ConfigError(msg)
            seen.add(up.parent)
            up = robot.parent_joint(up.parent)
    roots = [link for link in links if robot.parent_joint(link) is None]
    if len(roots) > 1:
        msg = f"{where}: links {', '.join(repr(r) for r in roots)} have no parent: the URDF is not one tree"
        raise ConfigError(msg)


def parse_urdf(text: str, *, where: str = "URDF") -> UrdfRobot:
    """Parse URDF text (plain XML; xacro must be expanded first) into links and joints.

    Raises
    ------
    ConfigError
        Not XML, not a ``<robot>``, xacro left in, duplicate names, a joint naming a link
        that is not defined, a link with two parent joints or a cycle (a kinematic loop),
        several root links.
    """
    try:
        root = ET.fromstring(text)
    except ET.ParseError as err:
        msg = f"{where} is not valid XML: {err}"
        raise ConfigError(msg) from err
    if root.tag != "robot":
        msg = f"{where}: top element is <{root.tag}>, expected <robot>"
        raise ConfigError(msg)
    if any("xacro" in (el.tag if isinstance(el.tag, str) else "") for el in root.iter()) or "${" in text:
        msg = f"{where} still holds xacro macros: expand it first (xacro robot.urdf.xacro > robot.urdf)"
        raise ConfigError(msg)
    links = _parse_links(root, where)
    joints = _parse_joints(root, links, where)
    if not links:
        msg = f"{where} defines no links"
        raise ConfigError(msg)
    robot = UrdfRobot(name=root.get("name") or "robot", links=tuple(links), joints=tuple(joints), where=where)
    _check_tree(robot)
    return robot


def load_urdf(path: str | Path) -> UrdfRobot:
    """Read and parse a URDF file (see :func:`parse_urdf`)."""
    file = Path(path)
    try:
        text = file.read_text(encoding="utf-8")
    except OSError as err:
        msg = f"cannot read URDF {file}: {err.strerror}"
        raise ConfigError(msg) from err
    except UnicodeDecodeError as err:
        msg = f"URDF {file} is not UTF-8 text (byte {err.start})"
        raise ConfigError(msg) from err
    return parse_urdf(text, where=str(file))


def _movable_below(robot: UrdfRobot, link: str) -> int:
    return sum((j.type in _MOVABLE) + _movable_below(robot, j.child) for j in robot.child_joints(link))


def _default_tip(robot: UrdfRobot, base: str) -> str:
    """End of the first serial chain: follow the branch with the most movable joints below it;
    stop where every branch is fixed-only (or at a leaf)."""
    link = base
    while True:
        children = robot.child_joints(link)
        if not children:
            return link
        counts = [(j.type in _MOVABLE) + _movable_below(robot, j.child) for j in children]
        if len(children) > 1 and max(counts) == 0:
            return link
        link = children[counts.index(max(counts))].child


def urdf_chain(robot: UrdfRobot, base_link: str | None = None, tip_link: str | None = None) -> UrdfChain:
    """The joint chain from `base_link` (default: the root link) to `tip_link` (default: the end
    of the first serial chain below the base).

    `base_link` may also be a link fixed to the chain off its path (UR's ``base``, the frame
    the controller and the DH parameters use, a fixed child of ``base_link``): the chain is
    then expressed in it (``UrdfChain.base_offset``).

    Raises
    ------
    ConfigError
        Unknown links, a tip not downstream of the base, a floating or planar joint or a mimic
        joint in the chain, a revolute or prismatic joint without limits, no movable joint.
    """
    where = robot.where
    for flag, link in (("--base-link", base_link), ("--tip-link", tip_link)):
        if link is not None and link not in robot.links:
            msg = f"{where}: {flag} {link!r} is not a link of robot {robot.name!r}"
            raise ConfigError(msg)
    base = base_link if base_link is not None else next(k for k in robot.links if robot.parent_joint(k) is None)
    if tip_link is None:
        # Below a base that hangs off the arm by fixed joints (UR's `base`), the arm starts higher up.
        top = base
        while _movable_below(robot, top) == 0 and (joint := robot.parent_joint(top)) is not None:
            if joint.type != "fixed":
                break
            top = joint.parent
        tip_link = _default_tip(robot, top)
    tip = tip_link
    upstream = [tip]  # the tip and its ancestors, up to the root
    while (joint := robot.parent_joint(upstream[-1])) is not None:
        upstream.append(joint.parent)
    # A base off that path must hang on it by fixed joints: its pose is then fixed in the chain.
    anchor, offset = base, np.eye(4)  # offset: anchor <- base
    while anchor not in upstream:
        joint = robot.parent_joint(anchor)
        if joint is None or joint.type != "fixed":
            msg = f"{where}: tip link {tip!r} is not downstream of base link {base!r}"
            raise ConfigError(msg)
        offset = joint.origin @ offset
        anchor = joint.parent
    joints: list[UrdfJoint] = []
    link = tip
    while link != anchor:
        joint = robot.parent_joint(link)
        assert joint is not None  # anchor is upstream of the tip
        joints.append(joint)
        link = joint.parent
    joints.reverse()
    for joint in joints:
        if joint.type in ("floating", "planar"):
            msg = (
                f"{where}: joint {joint.name!r} between {base!r} and {tip!r} is {joint.type}: a "
                f"{joint.type} base is not a serial arm; give --base-link {joint.child}"
            )
            raise ConfigError(msg)
        if joint.mimic is not None and joint.type in _MOVABLE:
            msg = (
                f"{where}: joint {joint.name!r} mimics joint {joint.mimic!r}: coupled joints are not "
                "supported in a calibrated chain"
            )
            raise ConfigError(msg)
        if joint.type in ("revolute", "prismatic") and (joint.lower is None or joint.upper is None):
            msg = f"{where}: {joint.type} joint {joint.name!r} has no <limit lower=... upper=...>"
            raise ConfigError(msg)
        if joint.type in ("revolute", "prismatic") and not joint.lower < joint.upper:  # type: ignore[operator]
            msg = f"{where}: joint {joint.name!r} has limits lower={joint.lower} >= upper={joint.upper}"
            raise ConfigError(msg)
    chain = UrdfChain(robot=robot, base_link=base, tip_link=tip, joints=tuple(joints), base_offset=_inv(offset))
    if not chain.movable:
        msg = f"{where}: no revolute, continuous or prismatic joint between {base!r} and {tip!r}"
        raise ConfigError(msg)
    return chain


def chain_frames(chain: UrdfChain, q: Array | None = None) -> tuple[list[Array], Array]:
    """Frames of the chain in the base link: each movable joint's frame, and the tip.

    Parameters
    ----------
    chain : UrdfChain
    q : ndarray, shape (n_movable,), optional [rad, m]
        Joint readings; zeros by default.

    Returns
    -------
    joint_frames : list of ndarray, shape (4, 4)
        Base link <- joint frame (after the joint's origin, before its motion).
    tip : ndarray, shape (4, 4)
        Base link <- tip link at `q`.
    """
    values = np.zeros(len(chain.movable)) if q is None else np.asarray(q, dtype=np.float64)
    current = chain.base_offset.copy()
    frames: list[Array] = []
    k = 0
    for joint in chain.joints:
        current = current @ joint.origin
        if joint.type in _MOVABLE:
            frames.append(current.copy())
            motion = np.eye(4)
            axis = np.asarray(joint.axis)
            if joint.type == "prismatic":
                motion[:3, 3] = axis * values[k]
            else:
                motion[:3, :3] = _axis_angle(axis, float(values[k]))
            current = current @ motion
            k += 1
    return frames, current


def _axis_angle(axis: Array, angle: float) -> Array:
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.asarray(np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k), dtype=np.float64)


def _frame_on_axis(point: Array, direction: Array) -> tuple[Array, Array]:
    """xyz, rpy of a frame at `point` whose z is `direction`, with pitch 0 (no gimbal lock)."""
    roll = math.acos(float(np.clip(direction[2], -1.0, 1.0)))
    yaw = math.atan2(float(direction[0]), float(-direction[1])) if math.sin(roll) > 1e-12 else 0.0
    return np.asarray(point, dtype=np.float64), np.array([roll, 0.0, yaw])


@dataclass(frozen=True)
class _Row:
    alpha: float
    a: float
    beta: float
    phi: float
    s: float
    has_beta: bool


def _line_step(frame: Array, point: Array, direction: Array) -> _Row:
    """Modified-DH step from `frame` (z on the current axis) to the line (point, direction)
    given in the base link: ``RotZ(phi) TransZ(s)`` on the current row, then ``RotX(alpha)
    TransX(a) [RotY(beta)]`` on the next; the result's origin lies on the line, its z along it."""
    inv = _inv(frame)
    p = inv[:3, :3] @ point + inv[:3, 3]
    u = inv[:3, :3] @ direction
    cross = math.hypot(u[0], u[1])  # |e_z x u|
    if cross > math.sin(HAYATI_ANGLE):
        # Common normal: x along e_z x u, feet of the perpendicular on both lines.
        x = np.array([-u[1], u[0], 0.0]) / cross
        cosang = float(u[2])
        s = (p[2] - cosang * float(p @ u)) / (1.0 - cosang**2)
        t = (cosang * p[2] - float(p @ u)) / (1.0 - cosang**2)
        foot = p + t * u
        a = float((foot - np.array([0.0, 0.0, s])) @ x)
        y = np.array([-x[1], x[0], 0.0])  # e_z x x
        alpha = math.atan2(-float(u @ y), float(u[2]))
        return _Row(alpha=alpha, a=a, beta=0.0, phi=math.atan2(x[1], x[0]), s=s, has_beta=False)
    # (Nearly) parallel: Hayati. Stay in the plane z = 0 of the current frame, go along x to
    # where the line pierces it, tilt about x (alpha) and about the new y (beta).
    t = -p[2] / u[2]
    pierce = p + t * u
    a = math.hypot(pierce[0], pierce[1])
    phi = math.atan2(pierce[1], pierce[0]) if a > 1e-15 else 0.0
    x = np.array([math.cos(phi), math.sin(phi), 0.0])
    y = np.array([-x[1], x[0], 0.0])
    beta = math.asin(float(np.clip(u @ x, -1.0, 1.0)))
    alpha = math.atan2(-float(u @ y), float(u[2]))
    return _Row(alpha=alpha, a=a, beta=beta, phi=phi, s=0.0, has_beta=True)


def model_frames(model: RobotModel, q: Array | None = None) -> tuple[list[Array], Array]:
    """Modified-DH frames of `model` in its base frame (the mount applied, ``world_T_base`` not).

    Returns
    -------
    frames : list of ndarray, shape (4, 4), length n_joints
        Base <- frame i at reading `q` (zeros by default): the frame whose z is joint i's axis.
    tool : ndarray, shape (4, 4)
        Base <- tool frame (``tool_rpy`` and ``tool_point`` after the last frame).
    """
    values = np.zeros(model.n_joints) if q is None else np.asarray(q, dtype=np.float64)
    current = transform(model.mount_xyz, model.mount_rpy)
    frames = []
    for j in range(model.n_joints):
        current = current @ _rot(0, float(model.alpha[j])) @ _trans(0, float(model.a[j]))
        if model.has_beta[j]:
            current = current @ _rot(1, float(model.beta[j]))
        if model.prismatic[j]:
            current = current @ _rot(2, float(model.theta[j])) @ _trans(2, float(model.d[j] + values[j]))
        else:
            current = current @ _rot(2, float(model.theta[j] + values[j])) @ _trans(2, float(model.d[j]))
        frames.append(current)
    return frames, current @ transform(model.tool_point, model.tool_rpy)


@dataclass(frozen=True)
class _DhRows:
    """The modified-DH rows of a chain and the mount that puts joint 1's frame on its axis."""

    mount_xyz: Array
    mount_rpy: Array
    alpha: Array
    a: Array
    theta: Array
    d: Array
    beta: Array
    has_beta: tuple[bool, ...]


def _dh_rows(joint_frames: list[Array], movable: tuple[UrdfJoint, ...]) -> _DhRows:
    """Walk the joint axes (in the base link) into modified-DH rows, one line step per joint."""
    axes = [frame[:3, :3] @ np.asarray(j.axis) for frame, j in zip(joint_frames, movable)]
    points = [frame[:3, 3] for frame in joint_frames]
    mount_xyz, mount_rpy = _frame_on_axis(points[0], axes[0])
    n = len(movable)
    alpha, a, beta, theta, d = (np.zeros(n) for _ in range(5))
    has_beta = [False] * n
    frame = transform(mount_xyz, mount_rpy)
    for i in range(1, n):
        row = _line_step(frame, points[i], axes[i])
        theta[i - 1] += row.phi
        d[i - 1] += row.s
        alpha[i], a[i], beta[i], has_beta[i] = row.alpha, row.a, row.beta, row.has_beta
        frame = frame @ _rot(2, row.phi) @ _trans(2, row.s) @ _rot(0, row.alpha) @ _trans(0, row.a)
        if row.has_beta:
            frame = frame @ _rot(1, row.beta)
    return _DhRows(mount_xyz, mount_rpy, alpha, a, theta, d, beta, tuple(has_beta))


def robot_model_from_urdf(
    robot: UrdfRobot,
    base_link: str | None = None,
    tip_link: str | None = None,
    *,
    tool_point: Array | tuple[float, float, float] | None = None,
    measurement_frame_id: str = "laser_tracker",
) -> RobotModel:
    """The modified-DH identification model of a URDF chain (see the module docstring).

    Parameters
    ----------
    robot : UrdfRobot
        From :func:`parse_urdf` or :func:`load_urdf`.
    base_link, tip_link : str, optional
        Chain ends (see :func:`urdf_chain`).
    tool_point : array_like, shape (3,) [m], optional
        The measured point (reflector, probe centre) in the tip link frame, when it is known
        (zeros: the tip link is the probe, e.g. a fixed link added at the probe centre). None
        (default): unknown; the model's tool point starts at the tip link's origin and
        ``tool_known`` is False, so the identification starts it from a least-squares fit to
        the campaign and does not regularise it towards the tip link.
    measurement_frame_id : str
        TF name of the measurement frame.

    Returns
    -------
    RobotModel
        Named ``robot[base->tip]``; joint limits from the URDF (``continuous``: ±2π);
        ``tool_rpy`` is the tip link's rotation in the last modified-DH frame. Its forward
        kinematics equal the URDF's (the tip link frame, moved to `tool_point`) to rounding.
    """
    chain = urdf_chain(robot, base_link, tip_link)
    joint_frames, _ = chain_frames(chain)
    movable = chain.movable
    dh = _dh_rows(joint_frames, movable)
    limits = np.array(
        [[j.lower, j.upper] if j.type != "continuous" else [-2.0 * math.pi, 2.0 * math.pi] for j in movable],
        dtype=np.float64,
    )
    model = RobotModel(
        name=f"{robot.name}[{chain.base_link}->{chain.tip_link}]",
        joint_names=tuple(j.name for j in movable),
        alpha=dh.alpha,
        a=dh.a,
        theta=dh.theta,
        d=dh.d,
        beta=dh.beta,
        has_beta=dh.has_beta,
        joint_limits=limits,
        tool_point=np.zeros(3),
        base_xyz=np.zeros(3),
        base_rpy=np.zeros(3),
        base_known=True,
        base_frame_id=chain.base_link,
        measurement_frame_id=measurement_frame_id,
        prismatic=tuple(j.type == "prismatic" for j in movable),
        mount_xyz=dh.mount_xyz,
        mount_rpy=dh.mount_rpy,
        mounted=True,
    )
    return _with_tool(model, chain, tool_point)


def _with_tool(
    model: RobotModel, chain: UrdfChain, tool_point: Array | tuple[float, float, float] | None
) -> RobotModel:
    """`model` with its tool: the tip link in the last modified-DH frame, then the measured point in it."""
    frames, _ = model_frames(model)
    _, tip = chain_frames(chain)
    last_t_tip = _inv(frames[-1]) @ tip
    given = np.zeros(3) if tool_point is None else np.asarray(tool_point, dtype=np.float64)
    if given.shape != (3,) or not np.isfinite(given).all():
        msg = f"tool point must be 3 finite numbers [m] in the tip link {chain.tip_link!r}, got {given.tolist()}"
        raise ConfigError(msg)
    point = last_t_tip[:3, :3] @ given + last_t_tip[:3, 3]
    return replace(model, tool_point=point, tool_rpy=urdf_rpy(last_t_tip[:3, :3]), tool_known=tool_point is not None)


def _axis_offsets(chain: UrdfChain, nominal: RobotModel, base: Array) -> list[Array]:
    """Per movable joint, its nominal frame in the nominal model frame on its axis.

    Raises ConfigError when a joint does not turn (or slide) about that frame's z axis.
    """
    joint_nominal, _ = chain_frames(chain)
    model_nominal, _ = model_frames(nominal)
    offsets = []
    for joint, j_frame, m_frame in zip(chain.movable, joint_nominal, model_nominal):
        k = _inv(base @ m_frame) @ j_frame  # model frame i <- joint frame i
        axis = k[:3, :3] @ np.asarray(joint.axis)
        misfit = float(np.linalg.norm(axis - np.array([0.0, 0.0, 1.0])))
        if joint.type != "prismatic":
            misfit = max(misfit, float(math.hypot(k[0, 3], k[1, 3])))
        if misfit > _AXIS_TOL:
            msg = (
                f"{chain.robot.where}: joint {joint.name!r} does not turn about the model's axis "
                f"(misfit {misfit:.3g}): the URDF and robot model {nominal.name!r} describe different robots"
            )
            raise ConfigError(msg)
        offsets.append(k)
    return offsets


def calibrated_joint_origins(
    chain: UrdfChain,
    nominal: RobotModel,
    calibrated: RobotModel,
    *,
    frame0: Array | None = None,
) -> tuple[dict[str, tuple[Array, Array]], Array]:
    """URDF joint origins under which the chain's kinematics equal the calibrated model's.

    Each movable joint's frame keeps its place relative to the model frame on its axis (the
    fixed transform from the nominal model frame to the nominal joint frame), so the origin
    of joint i becomes ``(parent link frame)^-1 @ calibrated frame i @ that transform``; fixed
    joints are kept. The tool (the measured point) is not a URDF joint: the calibrated measured
    point is returned in the tip link frame.

    Parameters
    ----------
    chain : UrdfChain
        Its movable joints must be the model's joints, in order.
    nominal, calibrated : RobotModel
        The nominal model (whose axes the chain's must match) and the calibrated one.
    frame0 : ndarray, shape (4, 4), optional
        Chain base link <- the model's base frame; identity by default (a model read from
        this URDF, whose base frame is the chain's base link).

    Returns
    -------
    origins : dict
        Joint name -> ``(xyz [m], rpy [rad])`` for every movable joint.
    point_in_tip : ndarray, shape (3,) [m]
        The calibrated measured point in the tip link frame.

    Raises
    ------
    ConfigError
        Joint names differ, or a URDF joint axis is not the model's axis at the nominal
        (the URDF and the model describe different robots).
    """
    movable = chain.movable
    names = tuple(j.name for j in movable)
    if names != nominal.joint_names:
        msg = (
            f"{chain.robot.where}: joints {list(names)} from {chain.base_link!r} to {chain.tip_link!r} "
            f"are not the model's {list(nominal.joint_names)}"
        )
        raise ConfigError(msg)
    base = np.eye(4) if frame0 is None else np.asarray(frame0, dtype=np.float64)
    offsets = _axis_offsets(chain, nominal, base)
    model_cal, tool_cal = model_frames(calibrated)
    origins: dict[str, tuple[Array, Array]] = {}
    current = chain.base_offset.copy()
    k_index = 0
    last = np.eye(4)
    for joint in chain.joints:
        if joint.type in _MOVABLE:
            new_frame = base @ model_cal[k_index] @ offsets[k_index]
            origin = _inv(current) @ new_frame
            origins[joint.name] = (origin[:3, 3].copy(), urdf_rpy(origin[:3, :3]))
            # Continue from the origin as written, so that the next one absorbs its rounding.
            current = current @ transform(*origins[joint.name])
            k_index += 1
        else:
            current = current @ joint.origin
        last = current
    point = base @ tool_cal @ np.array([0.0, 0.0, 0.0, 1.0])
    point_in_tip = (_inv(last) @ point)[:3]
    return origins, point_in_tip
