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

    Parameters
    ----------
    params : (n_p, n_params), n_p 1 or n_trials
    qs : (n_q, n_poses, n_joints), n_q 1 or n_trials
    joints : (n_joints, 6) int64, see :class:`~robocal_uncertainty.kernels._layout.FlatLayout`
    blocks : (4,) int64
    q_ref : (n_poses, n_joints); theta_ref : (n_joints,)
    cos_ref, sin_ref : (n_poses, n_joints), of the reference angles
    poses : bool
        Also the rotation: out[..., 3:12] is ``world_R_tool`` row by row.
    out : (n_trials, n_poses, 3 or 12)
    """
    n_trials = out.shape[0]
    n_poses = out.shape[1]
    nj = joints.shape[0]
    t0, r0, m0, b0 = blocks[0], blocks[1], blocks[2], blocks[3]
    for t in numba.prange(n_trials):
        p = params[0] if params.shape[0] == 1 else params[t]
        q = qs[0] if qs.shape[0] == 1 else qs[t]
        # Per-trial constants: cos/sin of alpha and beta, a, d, the theta change.
        k = np.empty((nj, 7))
        for j in range(nj):
            alpha = p[joints[j, 0]]
            k[j, 0] = math.cos(alpha)
            k[j, 1] = math.sin(alpha)
            if joints[j, 4] >= 0:
                k[j, 2] = math.cos(p[joints[j, 4]])
                k[j, 3] = math.sin(p[joints[j, 4]])
            k[j, 4] = p[joints[j, 1]]
            k[j, 5] = p[joints[j, 3]]
            k[j, 6] = p[joints[j, 2]] - theta_ref[j]
        rot = np.empty(27)  # base, mount, tool rotations, row-major
        _rpy(p, b0 + 3, rot[0:9])
        if m0 >= 0:
            _rpy(p, m0 + 3, rot[9:18])
        if r0 >= 0:
            _rpy(p, r0, rot[18:27])
        for i in range(n_poses):
            vx, vy, vz = p[t0], p[t0 + 1], p[t0 + 2]
            # Tool x and z axes in the flange frame.
            xx, xy, xz = 1.0, 0.0, 0.0
            zx, zy, zz = 0.0, 0.0, 1.0
            if r0 >= 0:
                xx, xy, xz = rot[18], rot[21], rot[24]
                zx, zy, zz = rot[20], rot[23], rot[26]
            for j in range(nj - 1, -1, -1):
                theta = p[joints[j, 2]]
                if joints[j, 5]:
                    vz += k[j, 5] + q[i, j]
                    b = k[j, 6]
                    angle = theta
                else:
                    vz += k[j, 5]
                    b = (q[i, j] - q_ref[i, j]) + k[j, 6]
                    angle = q[i, j] + theta
                c, s = _cos_sin(b, cos_ref[i, j], sin_ref[i, j], angle)
                vx, vy = c * vx - s * vy, s * vx + c * vy
                if poses:
                    xx, xy = c * xx - s * xy, s * xx + c * xy
                    zx, zy = c * zx - s * zy, s * zx + c * zy
                if joints[j, 4] >= 0:
                    cb, sb = k[j, 2], k[j, 3]
                    vz, vx = cb * vz - sb * vx, sb * vz + cb * vx
                    if poses:
                        xz, xx = cb * xz - sb * xx, sb * xz + cb * xx
                        zz, zx = cb * zz - sb * zx, sb * zz + cb * zx
                ca, sa = k[j, 0], k[j, 1]
                vy, vz = ca * vy - sa * vz, sa * vy + ca * vz
                if poses:
                    xy, xz = ca * xy - sa * xz, sa * xy + ca * xz
                    zy, zz = ca * zy - sa * zz, sa * zy + ca * zz
                vx += k[j, 4]
            if m0 >= 0:
                m = rot[9:18]
                vx, vy, vz = (
                    m[0] * vx + m[1] * vy + m[2] * vz + p[m0],
                    m[3] * vx + m[4] * vy + m[5] * vz + p[m0 + 1],
                    m[6] * vx + m[7] * vy + m[8] * vz + p[m0 + 2],
                )
                if poses:
                    xx, xy, xz = (
                        m[0] * xx + m[1] * xy + m[2] * xz,
                        m[3] * xx + m[4] * xy + m[5] * xz,
                        m[6] * xx + m[7] * xy + m[8] * xz,
                    )
                    zx, zy, zz = (
                        m[0] * zx + m[1] * zy + m[2] * zz,
                        m[3] * zx + m[4] * zy + m[5] * zz,
                        m[6] * zx + m[7] * zy + m[8] * zz,
                    )
            o = out[t, i]
            for r in range(3):
                r0_, r1_, r2_ = rot[3 * r], rot[3 * r + 1], rot[3 * r + 2]
                o[r] = r0_ * vx + r1_ * vy + r2_ * vz + p[b0 + r]
                if poses:
                    # world_R_tool row r: columns x, y = z cross x, z.
                    o[3 + 3 * r] = r0_ * xx + r1_ * xy + r2_ * xz
                    o[4 + 3 * r] = r0_ * (zy * xz - zz * xy) + r1_ * (zz * xx - zx * xz) + r2_ * (zx * xy - zy * xx)
                    o[5 + 3 * r] = r0_ * zx + r1_ * zy + r2_ * zz
