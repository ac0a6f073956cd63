"""6-DOF measurements: the tool position and orientation in the measurement frame.

A laser tracker with a 6-DOF probe (a T-Mac, three reflector nests) reports the probe's
position and orientation. :class:`PoseMeasurement` stores one such value as **12 numbers**: the
position ``(x, y, z)`` [m] followed by the rotation matrix ``world_R_tool`` row by row (a
matrix, not a quaternion, so that the chordal mean, the residual and ``perturb`` are plain
matrix algebra and no sign ambiguity exists).

One pose gives **6 equations**:

- rows 0-2, position residual ``p_measured - p_predicted`` [m];
- rows 3-5, rotation residual ``log(R_measured R_predicted^T)`` [rad], a rotation vector about
  the fixed x, y, z axes of the measurement frame (the convention of
  :mod:`robocal_uncertainty.core.rotation` and of ROS pose covariances).

Weighting: every row is whitened by a standard deviation per component, ``1 / s_x, 1 / s_y,
1 / s_z`` [1/m] for the position and ``1 / s_rx, 1 / s_ry, 1 / s_rz`` [1/rad] for the rotation,
so the least squares minimises ``sum (r_i / s_i)^2``: a rotation residual of one standard
deviation weighs as much as a position residual of one. ``s`` is the stated instrument
uncertainty (``position_std``, ``rotation_std``) unless ``weight_std`` is set: the
identification sets it from the residual scatter (variance components, see
:func:`~robocal_uncertainty.core.identification.identify`), because on a real arm the
unmodelled errors, not the tracker, dominate the residuals and the stated uncertainties alone
would let one kind of equation drown the other. The instrument noise of the Monte Carlo always
comes from the stated values; the report states both.

The Jacobian comes from :func:`~robocal_uncertainty.core.kinematics.forward_poses_and_jacobian`:
the angular rows are the world-frame angular velocity per unit parameter, which is the
first-order change of the rotation residual (with the minus sign of the measurement contract).
The tool rotation in the flange frame (``tool.rx, tool.ry, tool.rz``, present when the layout
has ``tool_rotation``; the identification adds it for pose campaigns) moves only these rows:
with points alone it is structurally unidentifiable, with poses it is estimated. Without it the
measured frame is the flange frame.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.kinematics import NearbyPoints, forward_poses, forward_poses_and_jacobian
from robocal_uncertainty.core.measurement import POSITION_AXES, MeasurementType, positive_triple
from robocal_uncertainty.core.robot_model import ParameterLayout
from robocal_uncertainty.core.rotation import rotation_log
from robocal_uncertainty.errors import ConfigError, InputError

__all__ = ["ROTATION_AXES", "PoseMeasurement", "pose_values", "split_pose_values"]

Array = NDArray[np.float64]
ROTATION_AXES: tuple[str, str, str] = ("rx", "ry", "rz")
"""Components of a rotation residual: rotation vector about the measurement frame's x, y, z."""
_ORTHONORMAL_TOL = 1e-6


def pose_values(positions: Array, rotations: Array) -> Array:
    """Stored pose values, shape (..., 12): position [m] then the rotation matrix row by row.

    Parameters
    ----------
    positions : ndarray, shape (..., 3) [m]
    rotations : ndarray, shape (..., 3, 3)
    """
    pos = np.asarray(positions, dtype=np.float64)
    rot = np.asarray(rotations, dtype=np.float64)
    flat = rot.reshape(*rot.shape[:-2], 9)
    shape = np.broadcast_shapes(pos.shape[:-1], flat.shape[:-1])
    return np.concatenate((np.broadcast_to(pos, (*shape, 3)), np.broadcast_to(flat, (*shape, 9))), axis=-1)


_SERIES_THETA2 = 1e-6
"""Squared angle [rad^2] below which :meth:`PoseMeasurement.perturb` uses the series of
``sin(t) / t`` and ``(1 - cos t) / t^2`` to the t^4 term (the t^6 term is below 2e-22)."""


def _components(values: Array) -> Array:
    """The last axis first, contiguous: shape (m, ...) from (..., m)."""
    out: Array = np.ascontiguousarray(np.moveaxis(values, -1, 0), dtype=np.float64)
    return out


def split_pose_values(values: Array) -> tuple[Array, Array]:
    """Positions (..., 3) [m] and rotation matrices (..., 3, 3) of stored pose values (..., 12)."""
    v = np.asarray(values, dtype=np.float64)
    return v[..., :3], v[..., 3:].reshape(*v.shape[:-1], 3, 3)


@dataclass(frozen=True)
class PoseMeasurement(MeasurementType):
    """Tool position and orientation in the measurement frame: 6 equations per pose.

    Parameters
    ----------
    position_std : tuple of 3 float [m]
        Standard uncertainty of each measured coordinate (x, y, z).
    rotation_std : tuple of 3 float [rad]
        Standard uncertainty of the measured orientation about the measurement frame's x, y, z
        axes (components of the rotation residual).
    weight_std : tuple of 6 float [m, m, m, rad, rad, rad] or None
        Standard deviations that whiten the residual components in the least squares, when
        they differ from the stated uncertainties (estimated variance components); None: the
        stated ``position_std + rotation_std``.
    """

    position_std: tuple[float, float, float]
    rotation_std: tuple[float, float, float]
    weight_std: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "position_std", positive_triple("position_std", self.position_std, "m"))
        object.__setattr__(self, "rotation_std", positive_triple("rotation_std", self.rotation_std, "rad"))
        if self.weight_std is not None:
            if len(self.weight_std) != 6:
                msg = f"weight_std must hold six values [m, m, m, rad, rad, rad], got {self.weight_std!r}"
                raise ConfigError(msg)
            position = positive_triple("weight_std[:3]", self.weight_std[:3], "m")
            rotation = positive_triple("weight_std[3:]", self.weight_std[3:], "rad")
            object.__setattr__(self, "weight_std", position + rotation)

    @property
    def name(self) -> str:
        """``"pose"``."""
        return "pose"

    @property
    def quantity(self) -> str:
        """``"measured pose"``."""
        return "measured pose"

    @property
    def dimension(self) -> int:
        """6: x, y, z [m], rx, ry, rz [rad]."""
        return 6

    @property
    def value_size(self) -> int:
        """12: position [m] and the rotation matrix row by row."""
        return 12

    @property
    def component_names(self) -> tuple[str, ...]:
        """``("x", "y", "z", "rx", "ry", "rz")``."""
        return POSITION_AXES + ROTATION_AXES

    @property
    def component_units(self) -> tuple[str, ...]:
        """``("m", "m", "m", "rad", "rad", "rad")``."""
        return ("m",) * 3 + ("rad",) * 3

    @property
    def std(self) -> Array:
        """Standard uncertainty per residual component, shape (6,) [m, m, m, rad, rad, rad]."""
        return np.asarray(self.position_std + self.rotation_std, dtype=np.float64)

    @property
    def weights(self) -> Array:
        """``1 / weight_std`` per component [1/m, 1/rad] (``1 / std`` when it is None)."""
        return 1.0 / (self.std if self.weight_std is None else np.asarray(self.weight_std, dtype=np.float64))

    @property
    def measures_orientation(self) -> bool:
        """True: the tool rotation in the flange frame becomes identifiable."""
        return True

    def predict(self, layout: ParameterLayout, params: Array, joint_positions: Array) -> Array:
        """Tool poses as stored values, shape (..., n_poses, 12)."""
        points, rotations = forward_poses(layout, params, joint_positions)
        return pose_values(points, rotations)

    def predict_and_jacobian(
        self, layout: ParameterLayout, params: Array, joint_positions: Array
    ) -> tuple[Array, Array]:
        """Tool poses (..., n_poses, 12) and the (..., n_poses, 6, n_params) Jacobian."""
        points, rotations, jac = forward_poses_and_jacobian(layout, params, joint_positions)
        return pose_values(points, rotations), jac

    def nearby_predictor(
        self, layout: ParameterLayout, params: Array, joint_positions: Array
    ) -> Callable[[Array, Array], Array] | None:
        """Tool poses near the reference by :meth:`~robocal_uncertainty.core.kinematics.NearbyPoints.poses`
        (None for a layout it does not cover: prismatic joints or a mount)."""
        if not NearbyPoints.supports(layout):
            return None
        return NearbyPoints.at(layout, params, joint_positions).poses

    def residual(self, measured: Array, predicted: Array) -> Array:
        """``(p_m - p_p, log(R_m R_p^T))``, shape (..., n_poses, 6) [m, rad].

        Entry by entry on the stored values (no stacked 3x3 products, the Monte Carlo's hot
        path); :func:`~robocal_uncertainty.core.rotation.rotation_log`'s formulas, and that
        function itself when a residual rotation is within ~0.14 rad of pi.
        """
        m = np.asarray(measured, dtype=np.float64)
        p = np.asarray(predicted, dtype=np.float64)
        out = np.empty((*np.broadcast_shapes(m.shape, p.shape)[:-1], 6))
        out[..., :3] = m[..., :3] - p[..., :3]
        # Each rotation entry as one contiguous array: numpy runs the products below several
        # times faster than on the strided views of the stored values.
        rm = _components(m[..., 3:])
        rp = _components(p[..., 3:])

        def entry(i: int, j: int) -> Array:  # (R_m R_p^T)_ij
            value: Array = rm[3 * i] * rp[3 * j] + rm[3 * i + 1] * rp[3 * j + 1] + rm[3 * i + 2] * rp[3 * j + 2]
            return value

        w = (entry(2, 1) - entry(1, 2), entry(0, 2) - entry(2, 0), entry(1, 0) - entry(0, 1))
        c = 0.5 * (entry(0, 0) + entry(1, 1) + entry(2, 2) - 1.0)  # cos(theta)
        if np.any(c < -0.99):
            _, r_m = split_pose_values(m)
            _, r_p = split_pose_values(p)
            out[..., 3:] = rotation_log(r_m @ np.swapaxes(r_p, -1, -2))
            return out
        s = 0.5 * np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])  # sin(theta)
        theta = np.arctan2(s, c)
        small = s < 1e-8
        half = 0.5 * np.where(small, 1.0 + theta**2 / 6.0, theta / np.where(small, 1.0, 2.0 * s) * 2.0)
        for i in range(3):
            out[..., 3 + i] = half * w[i]
        return out

    def perturb(self, values: Array, errors: Array) -> Array:
        """``(p + e_p, exp([e_r]x) R)``: the inverse of :meth:`residual`.

        Rodrigues' formula entry by entry, ``exp([e]x) = I + a [e]x + b (e e^T - |e|^2 I)``
        with :func:`~robocal_uncertainty.core.rotation.rotation_exp`'s ``a`` and ``b``.
        """
        v = np.asarray(values, dtype=np.float64)
        e = np.asarray(errors, dtype=np.float64)
        out = np.empty((*np.broadcast_shapes(v.shape[:-1], e.shape[:-1]), 12))
        out[..., :3] = v[..., :3] + e[..., :3]
        e0, e1, e2 = _components(e[..., 3:])
        theta2 = e0 * e0 + e1 * e1 + e2 * e2
        if theta2.size and float(np.max(theta2)) < _SERIES_THETA2:
            # Every angle below 1e-3 rad (a Monte Carlo's noise): the series alone, whose first
            # term left out is below 2e-22 relative, and no sine or cosine.
            a = 1.0 - theta2 / 6.0 + theta2**2 / 120.0
            b = 0.5 - theta2 / 24.0 + theta2**2 / 720.0
        else:
            small = theta2 < 1e-8
            safe = np.where(small, 1.0, np.sqrt(theta2))
            a = np.where(small, 1.0 - theta2 / 6.0 + theta2**2 / 120.0, np.sin(safe) / safe)
            b = np.where(small, 0.5 - theta2 / 24.0 + theta2**2 / 720.0, (1.0 - np.cos(safe)) / safe**2)
        diagonal = 1.0 - b * theta2
        be0, be1, be2 = b * e0, b * e1, b * e2
        ae0, ae1, ae2 = a * e0, a * e1, a * e2
        rows = (
            (diagonal + be0 * e0, be0 * e1 - ae2, be0 * e2 + ae1),
            (be1 * e0 + ae2, diagonal + be1 * e1, be1 * e2 - ae0),
            (be2 * e0 - ae1, be2 * e1 + ae0, diagonal + be2 * e2),
        )
        r = _components(v[..., 3:])
        for i, (x, y, z) in enumerate(rows):
            for j in range(3):
                out[..., 3 + 3 * i + j] = x * r[j] + y * r[3 + j] + z * r[6 + j]
        return out

    def instrument_covariance(self, position_std: Array) -> Array:
        """Covariance from the instrument's **position** noise only, shape (n_poses, 6, 6).

        The rotation block is zero: the orientation noise is its own Monte Carlo source
        (``tracker_orientation``), drawn from `rotation_std`.
        """
        std = np.asarray(position_std, dtype=np.float64)
        out = np.zeros((std.shape[0], 6, 6))
        out[:, 0, 0] = out[:, 1, 1] = out[:, 2, 2] = std**2
        return out

    def rotation_covariance(self, n_poses: int) -> Array:
        """Covariance of the orientation noise per pose, shape (n_poses, 6, 6) [rad^2], position block zero."""
        out = np.zeros((n_poses, 6, 6))
        for i, s in enumerate(self.rotation_std):
            out[:, 3 + i, 3 + i] = s * s
        return out

    def check_values(self, values: Array) -> None:
        """Each stored rotation must be a proper rotation matrix (orthonormal within 1e-6, det +1).

        A scaled, reflected or transposed-and-mangled matrix would otherwise enter the residual
        ``log(R_m R_p^T)`` as some unrelated rotation and surface only as a failed iteration.
        """
        _, rot = split_pose_values(values)
        gram = rot @ np.swapaxes(rot, -1, -2)
        error = np.max(np.abs(gram - np.eye(3)), axis=(-2, -1))
        bad = (error > _ORTHONORMAL_TOL) | (np.linalg.det(rot) <= 0.0)
        if np.any(bad):
            first = int(np.flatnonzero(bad.ravel())[0])
            msg = (
                f"measured orientation of pose {first} is not a rotation matrix "
                f"(max |R R^T - I| = {error.ravel()[first]:.3g}, det = {np.linalg.det(rot).ravel()[first]:.6g})"
            )
            raise InputError(msg)

    def positions(self, values: Array) -> Array:
        """The position part of the values [m]."""
        return np.asarray(values, dtype=np.float64)[..., :3]
