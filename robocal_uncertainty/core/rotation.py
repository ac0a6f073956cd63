"""Rotations: exp/log maps, the chordal L2 mean, quaternions and Euler angles, batched.

Conventions used throughout the package:

- A rotation deviation ``delta`` [rad] of ``R`` from a reference ``R_ref`` is the rotation
  vector of ``R R_ref^T``, i.e. ``R = exp([delta]x) R_ref``: a small rotation about the
  **fixed** x, y, z axes of the frame ``R`` and ``R_ref`` are expressed in (the parent frame).
  This is the convention of the orientation block of ROS ``geometry_msgs/PoseWithCovariance``
  (rotation about the fixed X, Y, Z axes of the header frame) and of the residual of a
  measured orientation (``log(R_measured R_predicted^T)``).
- Quaternions are stored ``(x, y, z, w)`` as in ROS, with ``w >= 0``.
- Every function is vectorised over leading dimensions and free of Python loops over them.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.errors import InputError

__all__ = [
    "EULER_CONVENTIONS",
    "chordal_mean",
    "euler_to_matrix",
    "project_to_rotation",
    "quaternion_from_matrix",
    "quaternion_to_matrix",
    "rotation_exp",
    "rotation_log",
    "skew",
]

Array = NDArray[np.float64]

EulerConvention = Literal["intrinsic_xyz", "extrinsic_xyz", "intrinsic_zyx", "intrinsic_zyz"]
EULER_CONVENTIONS: tuple[str, ...] = ("intrinsic_xyz", "extrinsic_xyz", "intrinsic_zyx", "intrinsic_zyz")
"""Supported Euler conventions of :func:`euler_to_matrix`.

``intrinsic_xyz``: ``Rx(a) Ry(b) Rz(c)`` (rotate about x, then the new y, then the new z);
``extrinsic_xyz``: ``Rz(c) Ry(b) Rx(a)`` (about the fixed x, y, z: ROS roll, pitch, yaw);
``intrinsic_zyx``: ``Rz(a) Ry(b) Rx(c)``; ``intrinsic_zyz``: ``Rz(a) Ry(b) Rz(c)``.
"""


def _vectors(value: Array, name: str) -> Array:
    """`value` as float64 with a last axis of 3, or a one-line InputError."""
    v = np.asarray(value, dtype=np.float64)
    if v.shape[-1:] != (3,):
        msg = f"{name} must have shape (..., 3), got {v.shape}"
        raise InputError(msg)
    return v


def _matrices(value: Array, name: str) -> Array:
    """`value` as float64 with two last axes of 3, or a one-line InputError."""
    r = np.asarray(value, dtype=np.float64)
    if r.shape[-2:] != (3, 3):
        msg = f"{name} must have shape (..., 3, 3), got {r.shape}"
        raise InputError(msg)
    return r


def skew(v: Array) -> Array:
    """Cross-product matrices, shape (..., 3, 3), of vectors (..., 3)."""
    v = _vectors(v, "vector")
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def rotation_exp(rotvec: Array) -> Array:
    """Rotation matrices ``exp([v]x)`` (Rodrigues), shape (..., 3, 3), of rotation vectors (..., 3) [rad]."""
    v = _vectors(rotvec, "rotation vector")
    theta2 = np.sum(v * v, axis=-1)
    theta = np.sqrt(theta2)
    small = theta2 < 1e-8
    safe = np.where(small, 1.0, theta)
    # Taylor series below 1e-4 rad: relative error of the truncation < 1e-17.
    a = np.where(small, 1.0 - theta2 / 6.0 + theta2**2 / 120.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta2 / 24.0 + theta2**2 / 720.0, (1.0 - np.cos(safe)) / safe**2)
    k = skew(v)
    return np.asarray(np.eye(3) + a[..., None, None] * k + b[..., None, None] * (k @ k), dtype=np.float64)


def rotation_log(rotation: Array) -> Array:
    """Rotation vectors [rad], shape (..., 3), of rotation matrices (..., 3, 3), angle in [0, pi].

    Accurate for small angles (the antisymmetric part carries the information, no arccos of
    a number near 1) and near pi (the axis is taken from the symmetric part).
    """
    r = _matrices(rotation, "rotation")
    w = np.stack((r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1]), axis=-1)
    s = 0.5 * np.linalg.norm(w, axis=-1)  # sin(theta)
    c = 0.5 * (np.trace(r, axis1=-2, axis2=-1) - 1.0)  # cos(theta)
    theta = np.arctan2(s, c)
    small = s < 1e-8
    # theta / sin(theta) = 1 + theta^2/6 for small angles; the same expression otherwise.
    factor = np.where(small, 1.0 + theta**2 / 6.0, theta / np.where(small, 1.0, 2.0 * s) * 2.0)
    out = 0.5 * factor[..., None] * w
    # Within ~0.14 rad of pi the antisymmetric part loses digits: take the axis from the
    # symmetric part, (R + R^T)/2 - cos(theta) I = (1 - cos(theta)) n n^T, signed by w.
    near_pi = c < -0.99
    if np.any(near_pi):
        rp = r[near_pi]
        cp = c[near_pi]
        sym = 0.5 * (rp + np.swapaxes(rp, -1, -2)) - cp[:, None, None] * np.eye(3)
        col = np.argmax(np.diagonal(sym, axis1=-2, axis2=-1), axis=-1)
        axis = sym[np.arange(rp.shape[0]), :, col]
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        sign = np.where(np.sum(axis * w[near_pi], axis=-1) < 0.0, -1.0, 1.0)
        out[near_pi] = axis * (sign * theta[near_pi])[:, None]
    return np.asarray(out, dtype=np.float64)


def project_to_rotation(matrix: Array) -> Array:
    """Nearest rotation (Frobenius norm) to each 3x3 matrix, shape (..., 3, 3), via the SVD."""
    u, _, vt = np.linalg.svd(_matrices(matrix, "matrix"))
    d = np.sign(np.linalg.det(u @ vt))
    d = np.where(d == 0, 1.0, d)
    u = u.copy()
    u[..., :, 2] *= d[..., None]
    return np.asarray(u @ vt, dtype=np.float64)


def chordal_mean(rotations: Array, axis: int = 0) -> Array:
    """Chordal L2 mean of rotations: the rotation nearest to their arithmetic mean matrix.

    Parameters
    ----------
    rotations : ndarray, shape (..., 3, 3)
    axis : int
        Axis of the samples (not one of the last two).

    Returns
    -------
    ndarray
        ``argmin_R sum_i ||R - R_i||_F^2``, the SVD projection of the mean matrix (Hartley et
        al., "Rotation averaging", IJCV 2013, §5.1); `axis` removed.
    """
    return project_to_rotation(np.mean(np.asarray(rotations, dtype=np.float64), axis=axis))


def quaternion_to_matrix(quaternion: Array, *, name: str = "quaternion", atol: float = 1e-6) -> Array:
    """Rotation matrices of unit quaternions ``(x, y, z, w)``, shape (..., 3, 3).

    Raises
    ------
    InputError
        NaN/inf components or a norm farther than `atol` from 1 (one line naming `name`).
    """
    q = np.asarray(quaternion, dtype=np.float64)
    if q.shape[-1:] != (4,):
        msg = f"{name} must have 4 components (x, y, z, w), got shape {q.shape}"
        raise InputError(msg)
    if not np.isfinite(q).all():
        msg = f"{name} contains NaN or inf"
        raise InputError(msg)
    norm = np.linalg.norm(q, axis=-1)
    bad = np.abs(norm - 1.0) > atol
    if np.any(bad):
        first = int(np.flatnonzero(bad.ravel())[0])
        msg = f"{name} is not a unit quaternion: norm {norm.ravel()[first]:.6g} at entry {first} (tolerance {atol:g})"
        raise InputError(msg)
    x, y, z, w = np.moveaxis(q / norm[..., None], -1, 0)
    out = np.empty((*q.shape[:-1], 3, 3))
    out[..., 0, 0] = 1 - 2 * (y * y + z * z)
    out[..., 0, 1] = 2 * (x * y - z * w)
    out[..., 0, 2] = 2 * (x * z + y * w)
    out[..., 1, 0] = 2 * (x * y + z * w)
    out[..., 1, 1] = 1 - 2 * (x * x + z * z)
    out[..., 1, 2] = 2 * (y * z - x * w)
    out[..., 2, 0] = 2 * (x * z - y * w)
    out[..., 2, 1] = 2 * (y * z + x * w)
    out[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return out


def quaternion_from_matrix(rotation: Array) -> Array:
    """Unit quaternions ``(x, y, z, w)`` with ``w >= 0``, shape (..., 4), of rotation matrices."""
    v = rotation_log(rotation)
    theta = np.linalg.norm(v, axis=-1)
    half = 0.5 * theta
    small = theta < 1e-8
    scale = np.where(small, 0.5 - theta**2 / 48.0, np.sin(half) / np.where(small, 1.0, theta))
    q = np.concatenate((v * scale[..., None], np.cos(half)[..., None]), axis=-1)
    return np.asarray(q, dtype=np.float64)


def _axis_rotation(axis: str, angle: Array) -> Array:
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros((*angle.shape, 3, 3))
    i = "xyz".index(axis)
    j, k = (i + 1) % 3, (i + 2) % 3
    out[..., i, i] = 1.0
    out[..., j, j], out[..., k, k] = c, c
    out[..., j, k], out[..., k, j] = -s, s
    return out


def euler_to_matrix(angles: Array, convention: str) -> Array:
    """Rotation matrices of Euler angles [rad], shape (..., 3, 3); see :data:`EULER_CONVENTIONS`.

    Raises
    ------
    InputError
        Unknown convention, or angles not of shape (..., 3).
    """
    a = _vectors(angles, "Euler angles")
    if convention not in EULER_CONVENTIONS:
        msg = f"Euler convention must be one of {', '.join(EULER_CONVENTIONS)}, got {convention!r}"
        raise InputError(msg)
    if convention == "extrinsic_xyz":
        return _axis_rotation("z", a[..., 2]) @ _axis_rotation("y", a[..., 1]) @ _axis_rotation("x", a[..., 0])
    kind, order = convention.split("_")
    _ = kind  # every other convention is intrinsic: R = R_1(a) R_2(b) R_3(c)
    return (
        _axis_rotation(order[0], a[..., 0]) @ _axis_rotation(order[1], a[..., 1]) @ _axis_rotation(order[2], a[..., 2])
    )
