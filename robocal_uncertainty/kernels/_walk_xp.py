"""The chain walk written against an array module (``numpy`` or ``cupy``), for the GPU backend.

Every operation is elementwise on arrays of shape (n_trials, n_poses), so the same code runs
on the CPU with numpy standing in for CuPy (how the tests run it) and on a GPU with CuPy. The
arithmetic is the compiled kernel's (:mod:`~robocal_uncertainty.kernels._numba_walk`): the
chain walked from the tool back, the cosine and sine of a joint angle near its reference from
the reference's and the series of the change where the change is at most ``SERIES_LIMIT``,
directly elsewhere; so the three backends round alike and agree to a few ulps.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from robocal_uncertainty.kernels._layout import FlatLayout

__all__ = ["SERIES_LIMIT", "as_numpy", "walk_xp"]

SERIES_LIMIT = 1.0e-3
"""Largest angle change [rad] from the reference taken by the series (as in the compiled walk)."""


def _cos_sin(xp: Any, b: Any, cos_ref: Any, sin_ref: Any, angle: Any) -> tuple[Any, Any]:
    """Cosine and sine of `angle` = reference + `b`: by the series where ``|b|`` is small."""
    b2 = b * b
    cb = 1.0 + b2 * (-0.5 + b2 * (1.0 / 24.0))
    sb = b * (1.0 + b2 * (-1.0 / 6.0 + b2 * (1.0 / 120.0)))
    near = xp.abs(b) <= SERIES_LIMIT
    c = xp.where(near, cos_ref * cb - sin_ref * sb, xp.cos(angle))
    s = xp.where(near, sin_ref * cb + cos_ref * sb, xp.sin(angle))
    return c, s


def _rpy(xp: Any, p: Any, k: int) -> list[list[Any]]:
    """Rows of ``Rz Ry Rx`` of the angles at p[..., k:k+3], each entry (n, 1)."""
    cr, sr = xp.cos(p[..., k]), xp.sin(p[..., k])
    cp, sp = xp.cos(p[..., k + 1]), xp.sin(p[..., k + 1])
    cy, sy = xp.cos(p[..., k + 2]), xp.sin(p[..., k + 2])
    return [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]


def walk_xp(xp: Any, flat: FlatLayout, params: Any, qs: Any, reference: tuple[Any, ...], *, poses: bool) -> Any:
    """Tool points (..., 3) or poses (..., 12) of every trial at every pose, as arrays of `xp`.

    Parameters
    ----------
    xp : module
        ``numpy`` or ``cupy``.
    flat : FlatLayout
    params : array, shape (n_p, n_params), n_p 1 or n_trials [m, rad]
    qs : array, shape (n_q, n_poses, n_joints), n_q 1 or n_trials [rad or m]
    reference : tuple of arrays
        Reference readings, joint offsets (n_joints,), and the cosine and sine of the reference
        angles, each (n_joints, n_poses) but the offsets.
    poses : bool
        Also ``world_R_tool`` (row by row after the point, 12 values per pose).

    Returns
    -------
    array of `xp`, shape (n_trials, n_poses, 3 or 12)
    """
    n_trials = max(params.shape[0], qs.shape[0])
    n_poses = qs.shape[1]
    p = params[:, None, :]  # (n_p, 1, n_params)
    t0, r0, m0, b0 = (int(v) for v in flat.blocks)
    q_ref, theta_ref, cos_ref, sin_ref = reference
    full = (n_trials, n_poses)
    v = [xp.broadcast_to(p[..., t0 + c], full) for c in range(3)]
    axes = _tool_axes(xp, p, r0, full) if poses else []
    vectors = [v, *axes]
    for j in range(flat.joints.shape[0] - 1, -1, -1):
        i_alpha, i_a, i_theta, i_d, i_beta, prismatic = (int(x) for x in flat.joints[j])
        q = qs[..., j]
        theta = p[..., i_theta]
        if prismatic:
            v[2] = v[2] + (p[..., i_d] + q)
            change = theta - theta_ref[j]
            angle = theta
        else:
            v[2] = v[2] + p[..., i_d]
            change = (q - q_ref[j]) + (theta - theta_ref[j])
            angle = q + theta
        c, s = _cos_sin(xp, change, cos_ref[j], sin_ref[j], angle)
        for u in vectors:
            u[0], u[1] = c * u[0] - s * u[1], s * u[0] + c * u[1]
        if i_beta >= 0:
            cb, sb = xp.cos(p[..., i_beta]), xp.sin(p[..., i_beta])
            for u in vectors:
                u[2], u[0] = cb * u[2] - sb * u[0], sb * u[2] + cb * u[0]
        ca, sa = xp.cos(p[..., i_alpha]), xp.sin(p[..., i_alpha])
        for u in vectors:
            u[1], u[2] = ca * u[1] - sa * u[2], sa * u[1] + ca * u[2]
        v[0] = v[0] + p[..., i_a]
    if m0 >= 0:
        m = _rpy(xp, p, m0 + 3)
        for n_u, u in enumerate(vectors):
            moved = [m[r][0] * u[0] + m[r][1] * u[1] + m[r][2] * u[2] for r in range(3)]
            if n_u == 0:
                moved = [moved[r] + p[..., m0 + r] for r in range(3)]
            u[:] = moved
    base = _rpy(xp, p, b0 + 3)
    width = 12 if poses else 3
    out = xp.empty((*full, width))
    for r in range(3):
        row = base[r]
        out[..., r] = row[0] * v[0] + row[1] * v[1] + row[2] * v[2] + p[..., b0 + r]
    if poses:
        _write_rotation(out, base, vectors[1], vectors[2])
    return out


def _tool_axes(xp: Any, p: Any, r0: int, full: tuple[int, int]) -> list[list[Any]]:
    """The tool's x and z axes before the joints turn them: the tool rotation's first and third
    columns (identity without a tool rotation, ``r0`` < 0), each a list of 3 arrays of shape `full`."""
    if r0 >= 0:
        tool = _rpy(xp, p, r0)
        return [[xp.broadcast_to(tool[r][c], full) for r in range(3)] for c in (0, 2)]
    one, zero = xp.ones(full), xp.zeros(full)
    return [[one, zero, zero], [zero, zero, one]]


def _write_rotation(out: Any, base: list[list[Any]], x_axis: list[Any], z_axis: list[Any]) -> None:
    """``world_R_tool`` row by row into ``out[..., 3:12]``: the base rotation times the walked tool
    x, y = z cross x and z axes."""
    (xx, xy, xz), (zx, zy, zz) = x_axis, z_axis
    cols = ((xx, xy, xz), (zy * xz - zz * xy, zz * xx - zx * xz, zx * xy - zy * xx), (zx, zy, zz))
    for r in range(3):
        row = base[r]
        for c, col in enumerate(cols):
            out[..., 3 + 3 * r + c] = row[0] * col[0] + row[1] * col[1] + row[2] * col[2]


def as_numpy(values: Any) -> np.ndarray:
    """A host numpy array of `values` (a CuPy array is copied from the device)."""
    get = getattr(values, "get", None)
    return np.asarray(get() if callable(get) else values, dtype=np.float64)
