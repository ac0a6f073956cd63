"""Kinematic model of a serial arm: Craig modified DH with optional Hayati beta, tool, base.

The model is a value object. Its identifiable quantities are flattened into one parameter
vector whose layout (names, kinds, units) is fixed by :class:`ParameterLayout`, so that the
kinematics, the identification and the Monte Carlo all speak about the same numbers.

Per joint ``i`` (Craig's row ``i``), the link transform is::

    {i-1}_T_{i} = RotX(alpha_{i-1}) TransX(a_{i-1}) RotY(beta_{i-1}) RotZ(q_i + theta_i) TransZ(d_i)

``beta`` is Hayati's extra rotation about y, used where consecutive axes are (nearly) parallel
and the common normal, hence ``d``, is ill-defined. It is present only for joints that enable it.
The measured point is ``world_T_base @ base_T_n @ tool_point``. A prismatic joint (models read
from a URDF) adds its reading to ``d_i`` instead of ``theta_i``. A model read from a URDF may
also carry a ``mount`` (the URDF base link <- modified-DH frame 0, parameters ``mount.*``), so
that ``base_T_n`` starts from the mount. When the model has a tool
rotation (``tool_rotation``; needed only by measurements of orientation), the measured frame is
``base_T_n`` rotated by ``Rz(rz) Ry(ry) Rx(rx)`` (fixed axes of the flange frame, the URDF rpy
form) and moved to the tool point; the point itself does not depend on that rotation.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.errors import ConfigError

__all__ = [
    "KINEMATIC_FIELDS",
    "ParameterKind",
    "ParameterLayout",
    "RobotModel",
    "rpy_from_matrix",
    "rpy_to_matrix",
]

ParameterKind = Literal["length", "angle"]
KINEMATIC_FIELDS: tuple[str, ...] = ("alpha", "a", "theta", "d", "beta")
_FIELD_KIND: dict[str, ParameterKind] = {
    "alpha": "angle",
    "a": "length",
    "theta": "angle",
    "d": "length",
    "beta": "angle",
}


def rpy_to_matrix(rpy: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation matrix ``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (fixed-axis XYZ, as in ROS URDF).

    Parameters
    ----------
    rpy : ndarray, shape (..., 3) [rad]
        Roll, pitch, yaw.

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    rpy = np.asarray(rpy, dtype=np.float64)
    cr, cp, cy = np.cos(rpy[..., 0]), np.cos(rpy[..., 1]), np.cos(rpy[..., 2])
    sr, sp, sy = np.sin(rpy[..., 0]), np.sin(rpy[..., 1]), np.sin(rpy[..., 2])
    out = np.empty((*rpy.shape[:-1], 3, 3))
    out[..., 0, 0] = cy * cp
    out[..., 0, 1] = cy * sp * sr - sy * cr
    out[..., 0, 2] = cy * sp * cr + sy * sr
    out[..., 1, 0] = sy * cp
    out[..., 1, 1] = sy * sp * sr + cy * cr
    out[..., 1, 2] = sy * sp * cr - cy * sr
    out[..., 2, 0] = -sp
    out[..., 2, 1] = cp * sr
    out[..., 2, 2] = cp * cr
    return out


@dataclass(frozen=True)
class ParameterLayout:
    """Names and positions of every model parameter in the flat parameter vector.

    The vector holds, in this order: for each joint its ``alpha, a, theta, d`` and, where
    enabled, ``beta``; then ``tool.x, tool.y, tool.z``; when `tool_rotation` is true,
    ``tool.rx, tool.ry, tool.rz`` (the tool frame's rotation in the flange frame,
    ``Rz(rz) Ry(ry) Rx(rx)`` [rad]); when `has_mount` is true (models read from a URDF),
    ``mount.x, mount.y, mount.z, mount.roll, mount.pitch, mount.yaw`` (robot base <- frame 0);
    then ``base.x, base.y, base.z, base.roll, base.pitch, base.yaw``.

    Without `tool_rotation` (the default) the layout is exactly the point-only layout: the
    tool rotation does not move a measured point, so it exists only for orientation data.
    """

    n_joints: int
    has_beta: tuple[bool, ...]
    tool_rotation: bool = False
    prismatic: tuple[bool, ...] = ()
    has_mount: bool = False

    def is_prismatic(self, joint: int) -> bool:
        """Whether joint `joint` (0-based) is prismatic (its reading adds to ``d``, not ``theta``)."""
        return bool(self.prismatic) and self.prismatic[joint]

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names, e.g. ``joint2.alpha`` or ``base.yaw``."""
        out: list[str] = []
        for j in range(self.n_joints):
            fields = KINEMATIC_FIELDS if self.has_beta[j] else KINEMATIC_FIELDS[:4]
            out.extend(f"joint{j + 1}.{f}" for f in fields)
        out.extend(("tool.x", "tool.y", "tool.z"))
        if self.tool_rotation:
            out.extend(("tool.rx", "tool.ry", "tool.rz"))
        if self.has_mount:
            out.extend(("mount.x", "mount.y", "mount.z", "mount.roll", "mount.pitch", "mount.yaw"))
        out.extend(("base.x", "base.y", "base.z", "base.roll", "base.pitch", "base.yaw"))
        return tuple(out)

    @property
    def kinds(self) -> tuple[ParameterKind, ...]:
        """``"length"`` (m) or ``"angle"`` (rad) for each parameter."""
        kinds: list[ParameterKind] = []
        for name in self.names:
            group, field = name.split(".")
            if group.startswith("joint"):
                kinds.append(_FIELD_KIND[field])
            elif field in ("x", "y", "z"):
                kinds.append("length")
            else:
                kinds.append("angle")
        return tuple(kinds)

    @property
    def size(self) -> int:
        """Length of the parameter vector."""
        return 4 * self.n_joints + sum(self.has_beta) + 9 + (3 if self.tool_rotation else 0) + 6 * self.has_mount

    def joint_slices(self) -> tuple[dict[str, int], ...]:
        """Per joint, the index of each of its fields in the vector."""
        out = []
        k = 0
        for j in range(self.n_joints):
            fields = KINEMATIC_FIELDS if self.has_beta[j] else KINEMATIC_FIELDS[:4]
            out.append({f: k + i for i, f in enumerate(fields)})
            k += len(fields)
        return tuple(out)

    @property
    def tool_index(self) -> int:
        """Index of ``tool.x``; ``tool.y`` and ``tool.z`` follow."""
        return 4 * self.n_joints + sum(self.has_beta)

    @property
    def tool_rotation_index(self) -> int | None:
        """Index of ``tool.rx`` (``tool.ry``, ``tool.rz`` follow), or None without tool rotation."""
        return self.tool_index + 3 if self.tool_rotation else None

    @property
    def mount_index(self) -> int | None:
        """Index of ``mount.x`` (then y, z, roll, pitch, yaw), or None without a mount."""
        return self.tool_index + (6 if self.tool_rotation else 3) if self.has_mount else None

    @property
    def base_index(self) -> int:
        """Index of ``base.x``; then y, z, roll, pitch, yaw."""
        return self.tool_index + (6 if self.tool_rotation else 3) + 6 * self.has_mount

    def index(self, name: str) -> int:
        """Index of the parameter called `name`."""
        try:
            return self.names.index(name)
        except ValueError as err:
            msg = f"unknown parameter {name!r}; known: {', '.join(self.names)}"
            raise ConfigError(msg) from err


@dataclass(frozen=True)
class RobotModel:
    """Nominal geometry of a serial arm in modified DH form, SI units.

    Parameters
    ----------
    name : str
        Model name, e.g. ``"ur10"``.
    joint_names : tuple of str, length n_joints
        Joint names as they appear in ``sensor_msgs/JointState``.
    alpha : ndarray, shape (n_joints,) [rad]
        Link twist alpha_{i-1} of row i.
    a : ndarray, shape (n_joints,) [m]
        Link length a_{i-1} of row i.
    theta : ndarray, shape (n_joints,) [rad]
        Joint offset added to the joint reading.
    d : ndarray, shape (n_joints,) [m]
        Link offset d_i.
    beta : ndarray, shape (n_joints,) [rad]
        Hayati rotation about y; only used where `has_beta` is true.
    has_beta : tuple of bool, length n_joints
        Which rows carry a beta parameter.
    joint_limits : ndarray, shape (n_joints, 2) [rad]
        Lower and upper joint reading limits.
    tool_point : ndarray, shape (3,) [m]
        Measured point (reflector, probe centre) in the last modified-DH frame.
    base_xyz : ndarray, shape (3,) [m]
        Translation of ``world_T_base`` (measurement frame <- robot base).
    base_rpy : ndarray, shape (3,) [rad]
        Roll, pitch, yaw of ``world_T_base``.
    base_known : bool
        True when ``world_T_base`` is known (e.g. identity: points in the base frame).
    base_frame_id, measurement_frame_id : str
        TF names of the robot base and the measurement frame.
    tool_rpy : ndarray, shape (3,) [rad]
        Rotation ``Rz(rz) Ry(ry) Rx(rx)`` of the measured (tool) frame in the flange frame, as
        ``(rx, ry, rz)``; zeros by default. Part of the parameter vector only when
        `tool_rotation` is true.
    tool_rotation : bool
        Whether the parameter vector carries ``tool.rx, tool.ry, tool.rz`` (orientation
        measurements); False keeps the point-only layout.
    prismatic : tuple of bool, length n_joints (or empty: all revolute)
        Joints whose reading [m] adds to ``d`` instead of ``theta``; their ``joint_limits`` are in m.
    mount_xyz, mount_rpy : ndarray, shape (3,) [m, rad]
        Transform robot base (URDF base link) <- modified-DH frame 0 (URDF origin convention);
        zeros (identity) for models given in DH form.
    mounted : bool
        Whether the mount is part of the parameter vector (``mount.*``); set for models read
        from a URDF and whenever the mount is not the identity. With measurements in the base
        frame it carries the first axis's place, which the first row alone cannot.
    tool_known : bool
        Whether `tool_point` is a known nominal value (a robot YAML's ``tool_point``, a URDF
        read with a given tool point). False (a URDF whose tip link is not said to be the
        measured point): the identification starts the tool point from a least-squares fit
        to the campaign and does not regularise it, as it does the base.
    """

    name: str
    joint_names: tuple[str, ...]
    alpha: NDArray[np.float64]
    a: NDArray[np.float64]
    theta: NDArray[np.float64]
    d: NDArray[np.float64]
    beta: NDArray[np.float64]
    has_beta: tuple[bool, ...]
    joint_limits: NDArray[np.float64]
    tool_point: NDArray[np.float64]
    base_xyz: NDArray[np.float64]
    base_rpy: NDArray[np.float64]
    base_known: bool = True
    base_frame_id: str = "base_link"
    measurement_frame_id: str = "laser_tracker"
    tool_rpy: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    tool_rotation: bool = False
    prismatic: tuple[bool, ...] = ()
    mount_xyz: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    mount_rpy: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    mounted: bool = False
    tool_known: bool = True

    def __post_init__(self) -> None:
        n = len(self.joint_names)
        if n == 0:
            raise ConfigError("robot model has no joints")
        for field_name in ("alpha", "a", "theta", "d", "beta"):
            value = np.asarray(getattr(self, field_name), dtype=np.float64)
            if value.shape != (n,) or not np.isfinite(value).all():
                msg = f"{field_name} must be {n} finite numbers, got {value.tolist()}"
                raise ConfigError(msg)
            object.__setattr__(self, field_name, value)
        if len(self.has_beta) != n:
            msg = f"has_beta must have {n} entries, got {len(self.has_beta)}"
            raise ConfigError(msg)
        limits = np.asarray(self.joint_limits, dtype=np.float64)
        if limits.shape != (n, 2) or not (limits[:, 0] < limits[:, 1]).all():
            msg = f"joint_limits must be {n} pairs [lower, upper] with lower < upper"
            raise ConfigError(msg)
        object.__setattr__(self, "joint_limits", limits)
        prismatic = tuple(bool(b) for b in self.prismatic) or (False,) * n
        if len(prismatic) != n:
            msg = f"prismatic must have {n} entries, got {len(prismatic)}"
            raise ConfigError(msg)
        object.__setattr__(self, "prismatic", prismatic)
        for field_name in ("tool_point", "base_xyz", "base_rpy", "tool_rpy", "mount_xyz", "mount_rpy"):
            value = np.asarray(getattr(self, field_name), dtype=np.float64)
            if value.shape != (3,) or not np.isfinite(value).all():
                msg = f"{field_name} must be 3 finite numbers, got {value.tolist()}"
                raise ConfigError(msg)
            object.__setattr__(self, field_name, value)
        if np.any(self.mount_xyz != 0) or np.any(self.mount_rpy != 0):
            object.__setattr__(self, "mounted", True)
        object.__setattr__(self, "has_beta", tuple(bool(b) for b in self.has_beta))
        object.__setattr__(self, "joint_names", tuple(self.joint_names))

    @property
    def n_joints(self) -> int:
        """Number of joints."""
        return len(self.joint_names)

    @property
    def layout(self) -> ParameterLayout:
        """Layout of the flat parameter vector."""
        prismatic = self.prismatic if any(self.prismatic) else ()
        return ParameterLayout(self.n_joints, self.has_beta, self.tool_rotation, prismatic, self.mounted)

    def parameter_vector(self) -> NDArray[np.float64]:
        """Flatten the model into its parameter vector, shape (n_params,) [m, rad]."""
        layout = self.layout
        p = np.empty(layout.size)
        for j, idx in enumerate(layout.joint_slices()):
            for field_name, k in idx.items():
                p[k] = getattr(self, field_name)[j]
        p[layout.tool_index : layout.tool_index + 3] = self.tool_point
        r0 = layout.tool_rotation_index
        if r0 is not None:
            p[r0 : r0 + 3] = self.tool_rpy
        m0 = layout.mount_index
        if m0 is not None:
            p[m0 : m0 + 3] = self.mount_xyz
            p[m0 + 3 : m0 + 6] = self.mount_rpy
        p[layout.base_index : layout.base_index + 3] = self.base_xyz
        p[layout.base_index + 3 : layout.base_index + 6] = self.base_rpy
        return p

    def with_parameters(self, params: NDArray[np.float64]) -> RobotModel:
        """Return a copy whose geometry is taken from the parameter vector `params`."""
        layout = self.layout
        p = np.asarray(params, dtype=np.float64)
        if p.shape != (layout.size,):
            msg = f"params must have shape ({layout.size},), got {p.shape}"
            raise ConfigError(msg)
        fields = {f: getattr(self, f).copy() for f in ("alpha", "a", "theta", "d", "beta")}
        for j, idx in enumerate(layout.joint_slices()):
            for field_name, k in idx.items():
                fields[field_name][j] = p[k]
        r0 = layout.tool_rotation_index
        tool_rpy = self.tool_rpy.copy() if r0 is None else p[r0 : r0 + 3].copy()
        m0 = layout.mount_index
        if m0 is not None:
            fields["mount_xyz"] = p[m0 : m0 + 3].copy()
            fields["mount_rpy"] = p[m0 + 3 : m0 + 6].copy()
        return replace(
            self,
            tool_point=p[layout.tool_index : layout.tool_index + 3].copy(),
            tool_rpy=tool_rpy,
            base_xyz=p[layout.base_index : layout.base_index + 3].copy(),
            base_rpy=p[layout.base_index + 3 : layout.base_index + 6].copy(),
            **fields,
        )

    def with_tool_rotation(self) -> RobotModel:
        """This model with ``tool.rx, tool.ry, tool.rz`` in its parameter vector (itself if so)."""
        return self if self.tool_rotation else replace(self, tool_rotation=True)

    def world_T_base(self) -> NDArray[np.float64]:
        """Homogeneous transform measurement frame <- robot base, shape (4, 4) [m]."""
        out = np.eye(4)
        out[:3, :3] = rpy_to_matrix(self.base_rpy)
        out[:3, 3] = self.base_xyz
        return out


def rpy_from_matrix(rotation: NDArray[np.float64]) -> NDArray[np.float64]:
    """Roll, pitch, yaw [rad] of a rotation matrix ``Rz(yaw) Ry(pitch) Rx(roll)``, shape (3,)."""
    r = np.asarray(rotation, dtype=np.float64)
    pitch = float(np.arcsin(np.clip(-r[2, 0], -1.0, 1.0)))
    roll = float(np.arctan2(r[2, 1], r[2, 2]))
    yaw = float(np.arctan2(r[1, 0], r[0, 0]))
    return np.array([roll, pitch, yaw])
