"""The chain walk compiled by numba: one fused loop per (trial, pose), trials in parallel.

Imported only when numba is installed (the ``fast`` extra). The arithmetic is that of
:class:`~robocal_uncertainty.core.kinematics.NearbyPoints`: the point (and, for poses, the
tool's x and z axes) is walked from the tool back to the base, and the cosine and sine of a
joint angle near its reference come from ``cos(a0 + b) = cos a0 cos b - sin a0 sin b`` with
``cos b`` and ``sin b`` from their Taylor series. Here the choice is made per element: the
series (three terms each, truncation below 2e-21 for ``|b| <= 1e-3`` rad) or, for a larger
change, ``cos`` and ``sin`` of the angle itself. Either way the value is the angle's cosine to
an ulp or two, so the result agrees with :func:`~robocal_uncertainty.core.kinematics.forward_points`
to a few ulps, and a trial's values never depend on the other trials of its batch. Unlike the
numpy walk it covers every layout (a URDF mount, prismatic joints).

The kernel is compiled on first use and cached on disk (``cache=True``): later processes
load it in a fraction of a second.
"""

from __future__ import annotations

import math

import numba
import numpy as np

SERIES_LIMIT = 1.0e-3
"""Largest angle change [rad] from the reference taken by the series."""


@numba.njit(cache=True, inline="always")
def _cos_sin(b: float, cos_ref: float, sin_ref: float, angle: float) -> tuple[float, float]:
    if abs(b) <= SERIES_LIMIT:
        b2 = b * b
        cb = 1.0 + b2 * (-0.5 + b2 * (1.0 / 24.0))
        sb = b * (1.0 + b2 * (-1.0 / 6.0 + b2 * (1.0 / 120.0)))
        return cos_ref * cb - sin_ref * sb, sin_ref * cb + cos_ref * sb
    return math.cos(angle), math.sin(angle)


@numba.njit(cache=True, inline="always")
def _rpy(p: np.ndarray, k: int, out: np.ndarray) -> None:
    """Row-major ``Rz(p[k+2]) Ry(p[k+1]) Rx(p[k])`` into out[0:9]."""
    cr, sr = math.cos(p[k]), math.sin(p[k])
    cp, sp = math.cos(p[k + 1]), math.sin(p[k + 1])
    cy, sy = math.cos(p[k + 2]), math.sin(p[k + 2])
    out[0] = cy * cp
    out[1] = cy * sp * sr - sy * cr
    out[2] = cy * sp * cr + sy * sr
    out[3] = sy * cp
    out[4] = sy * sp * sr + cy * cr
    out[5] = sy * sp * cr - cy * sr
    out[6] = -sp
    out[7] = cp * sr
    out[8] = cp * cr


@numba.njit(cache=True, inline="always")
def _turn(u: np.ndarray, v: np.ndarray, c: np.ndarray, s: np.ndarray) -> None:
    """``u, v = c u - s v, s u + c v`` elementwise, in place."""
    for i in range(u.shape[0]):
        a, b = u[i], v[i]
        u[i] = c[i] * a - s[i] * b
        v[i] = s[i] * a + c[i] * b


@numba.njit(cache=True, inline="always")
def _turn_fixed(u: np.ndarray, v: np.ndarray, c: float, s: float) -> None:
    """``u, v = c u - s v, s u + c v`` with constant c, s, in place."""
    for i in range(u.shape[0]):
        a, b = u[i], v[i]
        u[i] = c * a - s * b
        v[i] = s * a + c * b


@numba.njit(parallel=True, cache=True)
def walk(
    params: np.ndarray,
    qs: np.ndarray,
    joints: np.ndarray,
    blocks: np.ndarray,
    q_ref: np.ndarray,
    theta_ref: np.ndarray,
    cos_ref: np.ndarray,
    sin_ref: np.ndarray,
    poses: bool,
    out: np.ndarray,
) -> None:
    """Tool points (and rotations) of every trial at every pose, in the measurement frame.

    Within a trial the loops run over the poses joint by joint (each a short loop over
    contiguous arrays that the compiler vectorises), the per-joint choices (prismatic, beta,
    series or direct) taken once per joint; every pose's value is computed by the same
    operations whatever the other poses and trials, so batching never changes a value.

    Parameters
    ----------
    params : (n_p, n_params), n_p 1 or n_trials
    qs : (n_q, n_poses, n_joints), n_q 1 or n_trials
    joints : (n_joints, 6) int64, see :class:`~robocal_uncertainty.kernels._layout.FlatLayout`
    blocks : (4,) int64
    q_ref : (n_joints, n_poses), reference readings, joint by joint; theta_ref : (n_joints,)
    cos_ref, sin_ref : (n_joints, n_poses), of the reference angles
    poses : bool
        Also the rotation: out[..., 3:12] is ``world_R_tool`` row by row.
    out : (n_trials, n_poses, 3 or 12)
    """
    n_trials = out.shape[0]
    n_poses = out.shape[1]
    nj = joints.shape[0]
    t0, r0, m0, b0 = blocks[0], blocks[1], blocks[2], blocks[3]
    n_vec = 3 if poses else 1
    for t in numba.prange(n_trials):
        p = params[0] if params.shape[0] == 1 else params[t]
        q = qs[0] if qs.shape[0] == 1 else qs[t]
        rot = np.empty(27)  # base, mount, tool rotations, row-major
        _rpy(p, b0 + 3, rot[0:9])
        if m0 >= 0:
            _rpy(p, m0 + 3, rot[9:18])
        if r0 >= 0:
            _rpy(p, r0, rot[18:27])
        # v[3 m + c]: component c of vector m (the point; the tool's x and z axes) per pose.
        v = np.empty((3 * n_vec, n_poses))
        v[0, :] = p[t0]
        v[1, :] = p[t0 + 1]
        v[2, :] = p[t0 + 2]
        if poses:
            if r0 >= 0:
                for c in range(3):
                    v[3 + c, :] = rot[18 + 3 * c]  # tool x axis: column 0
                    v[6 + c, :] = rot[20 + 3 * c]  # tool z axis: column 2
            else:
                v[3:9, :] = 0.0
                v[3, :] = 1.0
                v[8, :] = 1.0
        b = np.empty(n_poses)
        cos = np.empty(n_poses)
        sin = np.empty(n_poses)
        for j in range(nj - 1, -1, -1):
            theta = p[joints[j, 2]]
            dtheta = theta - theta_ref[j]
            prismatic = joints[j, 5] != 0
            d = p[joints[j, 3]]
            largest = 0.0
            if prismatic:
                for i in range(n_poses):
                    v[2, i] += d + q[i, j]
                    b[i] = dtheta
                largest = abs(dtheta)
            else:
                for i in range(n_poses):
                    v[2, i] += d
                    b[i] = (q[i, j] - q_ref[j, i]) + dtheta
                for i in range(n_poses):
                    largest = max(largest, abs(b[i]))
            cr = cos_ref[j]
            sr = sin_ref[j]
            if largest <= SERIES_LIMIT:
                for i in range(n_poses):
                    bi = b[i]
                    b2 = bi * bi
                    cb = 1.0 + b2 * (-0.5 + b2 * (1.0 / 24.0))
                    sb = bi * (1.0 + b2 * (-1.0 / 6.0 + b2 * (1.0 / 120.0)))
                    cos[i] = cr[i] * cb - sr[i] * sb
                    sin[i] = sr[i] * cb + cr[i] * sb
            else:
                for i in range(n_poses):
                    angle = theta if prismatic else q[i, j] + theta
                    cos[i], sin[i] = _cos_sin(b[i], cr[i], sr[i], angle)
            for m in range(n_vec):
                _turn(v[3 * m], v[3 * m + 1], cos, sin)
            if joints[j, 4] >= 0:
                beta = p[joints[j, 4]]
                cb_, sb_ = math.cos(beta), math.sin(beta)
                for m in range(n_vec):
                    _turn_fixed(v[3 * m + 2], v[3 * m], cb_, sb_)
            alpha = p[joints[j, 0]]
            ca, sa = math.cos(alpha), math.sin(alpha)
            for m in range(n_vec):
                _turn_fixed(v[3 * m + 1], v[3 * m + 2], ca, sa)
            a = p[joints[j, 1]]
            for i in range(n_poses):
                v[0, i] += a
        for i in range(n_poses):
            for m in range(n_vec):
                x, y, z = v[3 * m, i], v[3 * m + 1, i], v[3 * m + 2, i]
                if m0 >= 0:
                    x, y, z = (
                        rot[9] * x + rot[10] * y + rot[11] * z,
                        rot[12] * x + rot[13] * y + rot[14] * z,
                        rot[15] * x + rot[16] * y + rot[17] * z,
                    )
                    if m == 0:
                        x, y, z = x + p[m0], y + p[m0 + 1], z + p[m0 + 2]
                v[3 * m, i], v[3 * m + 1, i], v[3 * m + 2, i] = x, y, z
            o = out[t, i]
            vx, vy, vz = v[0, i], v[1, i], v[2, i]
            for r in range(3):
                e0, e1, e2 = rot[3 * r], rot[3 * r + 1], rot[3 * r + 2]
                o[r] = e0 * vx + e1 * vy + e2 * vz + p[b0 + r]
            if poses:
                xx, xy, xz = v[3, i], v[4, i], v[5, i]
                zx, zy, zz = v[6, i], v[7, i], v[8, i]
                yx, yy, yz = zy * xz - zz * xy, zz * xx - zx * xz, zx * xy - zy * xx
                for r in range(3):
                    e0, e1, e2 = rot[3 * r], rot[3 * r + 1], rot[3 * r + 2]
                    # world_R_tool row r: columns x, y = z cross x, z.
                    o[3 + 3 * r] = e0 * xx + e1 * xy + e2 * xz
                    o[4 + 3 * r] = e0 * yx + e1 * yy + e2 * yz
                    o[5 + 3 * r] = e0 * zx + e1 * zy + e2 * zz
