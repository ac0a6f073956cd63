"""The trial kernels compiled by numba: the chain walk, and the whole chord re-identification.

Imported only when numba is installed (the ``fast`` extra). The walk's arithmetic is that of
:class:`~robocal_uncertainty.core.kinematics.NearbyPoints`: the point (and, for poses, the
tool's x and z axes) is walked from the tool back to the base, and the cosine and sine of a
joint angle near its reference come from ``cos(a0 + b) = cos a0 cos b - sin a0 sin b`` with
``cos b`` and ``sin b`` from their Taylor series. Here the choice is made per element: the
series (three terms each, truncation below 2e-21 for ``|b| <= 1e-3`` rad) or, for a larger
change, ``cos`` and ``sin`` of the angle itself; the link angles (alpha, beta, the base, mount
and tool rotations) likewise near the reference parameters. Either way the value is the
angle's cosine to an ulp or two, so the result agrees with
:func:`~robocal_uncertainty.core.kinematics.forward_points` to a few ulps, and a trial's values
never depend on the other trials of its batch. Unlike the numpy walk it covers every layout (a
URDF mount, prismatic joints).

:func:`chord_solve` runs :meth:`~robocal_uncertainty.uncertainty.reidentification.ChordSolver.solve`
for every trial start to end (trials spread over numba's threads), so a trial's cost is its
pose count times a constant, with no temporaries of a whole batch.

Every kernel lives in this one module: numba's disk cache is checked against the source file
of the function it compiled, so a kernel calling a function of another module could outlive a
change there. They are compiled on first use and cached on disk (``cache=True``): later
processes load them in about a second.
"""

from __future__ import annotations

import math

import numba
import numpy as np

SERIES_LIMIT = 1.0e-3
"""Largest angle change [rad] from the reference taken by the series."""


@numba.njit(cache=True, error_model="numpy", inline="always")
def _cos_sin(b: float, cos_ref: float, sin_ref: float, angle: float) -> tuple[float, float]:
    if abs(b) <= SERIES_LIMIT:
        b2 = b * b
        cb = 1.0 + b2 * (-0.5 + b2 * (1.0 / 24.0))
        sb = b * (1.0 + b2 * (-1.0 / 6.0 + b2 * (1.0 / 120.0)))
        return cos_ref * cb - sin_ref * sb, sin_ref * cb + cos_ref * sb
    return math.cos(angle), math.sin(angle)


@numba.njit(cache=True, error_model="numpy")
def _trig(p: np.ndarray, i: int, p_ref: np.ndarray, cos_p: np.ndarray, sin_p: np.ndarray) -> tuple[float, float]:
    """Cosine and sine of the angle p[i]: near the reference p_ref[i] (whose cosine and sine
    are given) by the series of the change, as the joint angles; else directly."""
    angle = p[i]
    return _cos_sin(angle - p_ref[i], cos_p[i], sin_p[i], angle)


@numba.njit(cache=True, error_model="numpy")
def _rpy(
    p: np.ndarray, k: int, p_ref: np.ndarray, cos_p: np.ndarray, sin_p: np.ndarray, out: np.ndarray, at: int
) -> None:
    """Row-major ``Rz(p[k+2]) Ry(p[k+1]) Rx(p[k])`` into out[at:at + 9] (indexed, not sliced:
    a view of an array costs two atomic reference counts, per trial)."""
    cr, sr = _trig(p, k, p_ref, cos_p, sin_p)
    cp, sp = _trig(p, k + 1, p_ref, cos_p, sin_p)
    cy, sy = _trig(p, k + 2, p_ref, cos_p, sin_p)
    out[at + 0] = cy * cp
    out[at + 1] = cy * sp * sr - sy * cr
    out[at + 2] = cy * sp * cr + sy * sr
    out[at + 3] = sy * cp
    out[at + 4] = sy * sp * sr + cy * cr
    out[at + 5] = sy * sp * cr - cy * sr
    out[at + 6] = -sp
    out[at + 7] = cp * sr
    out[at + 8] = cp * cr


@numba.njit(cache=True, error_model="numpy", inline="always")
def _turn(w: np.ndarray, iu: int, iv: int, c: np.ndarray, s: np.ndarray) -> None:
    """Rows u = w[iu], v = w[iv]: ``u, v = c u - s v, s u + c v`` elementwise, in place."""
    for i in range(w.shape[1]):
        a, b = w[iu, i], w[iv, i]
        w[iu, i] = c[i] * a - s[i] * b
        w[iv, i] = s[i] * a + c[i] * b


@numba.njit(cache=True, error_model="numpy", inline="always")
def _turn_fixed(w: np.ndarray, iu: int, iv: int, c: float, s: float) -> None:
    """Rows u = w[iu], v = w[iv]: ``u, v = c u - s v, s u + c v`` with constant c, s, in place."""
    for i in range(w.shape[1]):
        a, b = w[iu, i], w[iv, i]
        w[iu, i] = c * a - s * b
        w[iv, i] = s * a + c * b


@numba.njit(cache=True, error_model="numpy", inline="always")
def _series_turns(
    v: np.ndarray,
    m: int,
    cos: np.ndarray,
    sin: np.ndarray,
    has_beta: bool,
    link: tuple[float, float, float, float],
    a: float,
    translate: bool,
) -> None:
    """One joint's turns of vector m (components ``v[3 m: 3 m + 3]``, each (n_poses,)) at
    every pose, in place: about z by the joint angle (`cos`, `sin` per pose), about y by beta (when
    `has_beta`), about x by alpha (`link` = cos beta, sin beta, cos alpha, sin alpha), then
    (with `translate`, the point) along x by `a`. One loop per case without a branch inside,
    so that the compiler vectorises it; the operations per pose are those of the pass over
    larger changes in :func:`_walk_trial`."""
    cb_, sb_, ca, sa = link
    if has_beta:
        for i in range(v.shape[1]):
            c, s = cos[i], sin[i]
            xi, yi, zi = v[3 * m, i], v[3 * m + 1, i], v[3 * m + 2, i]
            xi, yi = c * xi - s * yi, s * xi + c * yi
            zi, xi = cb_ * zi - sb_ * xi, sb_ * zi + cb_ * xi
            yi, zi = ca * yi - sa * zi, sa * yi + ca * zi
            v[3 * m, i] = xi + a if translate else xi
            v[3 * m + 1, i] = yi
            v[3 * m + 2, i] = zi
    else:
        for i in range(v.shape[1]):
            c, s = cos[i], sin[i]
            xi, yi, zi = v[3 * m, i], v[3 * m + 1, i], v[3 * m + 2, i]
            xi, yi = c * xi - s * yi, s * xi + c * yi
            yi, zi = ca * yi - sa * zi, sa * yi + ca * zi
            v[3 * m, i] = xi + a if translate else xi
            v[3 * m + 1, i] = yi
            v[3 * m + 2, i] = zi


@numba.njit(cache=True, error_model="numpy")
def _walk_trial(
    p: np.ndarray,
    q: np.ndarray,
    joints: np.ndarray,
    blocks: np.ndarray,
    q_ref: np.ndarray,
    theta_ref: np.ndarray,
    cos_ref: np.ndarray,
    sin_ref: np.ndarray,
    p_ref: np.ndarray,
    cos_p: np.ndarray,
    sin_p: np.ndarray,
    poses: bool,
    rot: np.ndarray,
    v: np.ndarray,
    b: np.ndarray,
    cos: np.ndarray,
    sin: np.ndarray,
    o: np.ndarray,
) -> None:
    """One trial's tool points (and rotations) at every pose into `o` (n_poses, 3 or 12).

    Within the trial the loops run over the poses joint by joint (each a short loop over
    contiguous arrays that the compiler vectorises), the per-joint choices (prismatic, beta,
    series or direct) taken once per joint; every pose's value is computed by the same
    operations whatever the other poses and trials, so batching never changes a value.
    The cosine and sine of a link angle (alpha, beta, the base, mount and tool rotations)
    come from those of the reference parameters `p_ref` (`cos_p`, `sin_p`, each (n_params,)),
    as the joint angles' do. `rot` (27,), `v` (9, n_poses), `b`, `cos`, `sin` (n_poses,) are scratch.
    """
    n_poses = o.shape[0]
    n_vec = 3 if poses else 1
    _start_vectors(p, blocks, p_ref, cos_p, sin_p, poses, rot, v)
    for j in range(joints.shape[0] - 1, -1, -1):
        _joint_turns(p, q, j, joints, q_ref, theta_ref, cos_ref, sin_ref, p_ref, cos_p, sin_p, n_vec, v, b, cos, sin)
    m0, b0 = blocks[2], blocks[3]
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
        vx, vy, vz = v[0, i], v[1, i], v[2, i]
        for r in range(3):
            e0, e1, e2 = rot[3 * r], rot[3 * r + 1], rot[3 * r + 2]
            o[i, r] = e0 * vx + e1 * vy + e2 * vz + p[b0 + r]
        if poses:
            xx, xy, xz = v[3, i], v[4, i], v[5, i]
            zx, zy, zz = v[6, i], v[7, i], v[8, i]
            yx, yy, yz = zy * xz - zz * xy, zz * xx - zx * xz, zx * xy - zy * xx
            for r in range(3):
                e0, e1, e2 = rot[3 * r], rot[3 * r + 1], rot[3 * r + 2]
                # world_R_tool row r: columns x, y = z cross x, z.
                o[i, 3 + 3 * r] = e0 * xx + e1 * xy + e2 * xz
                o[i, 4 + 3 * r] = e0 * yx + e1 * yy + e2 * yz
                o[i, 5 + 3 * r] = e0 * zx + e1 * zy + e2 * zz


@numba.njit(cache=True, error_model="numpy")
def _start_vectors(
    p: np.ndarray,
    blocks: np.ndarray,
    p_ref: np.ndarray,
    cos_p: np.ndarray,
    sin_p: np.ndarray,
    poses: bool,
    rot: np.ndarray,
    v: np.ndarray,
) -> None:
    """The base, mount and tool rotations into `rot`, and the vectors at the tool into `v`
    (see :func:`_walk_trial`)."""
    t0, r0, m0, b0 = blocks[0], blocks[1], blocks[2], blocks[3]
    _rpy(p, b0 + 3, p_ref, cos_p, sin_p, rot, 0)  # base, mount, tool rotations, row-major
    if m0 >= 0:
        _rpy(p, m0 + 3, p_ref, cos_p, sin_p, rot, 9)
    if r0 >= 0:
        _rpy(p, r0, p_ref, cos_p, sin_p, rot, 18)
    # v[3 m + c]: component c of vector m (the point; the tool's x and z axes) per pose.
    n_poses = v.shape[1]
    for c in range(3):
        for i in range(n_poses):
            v[c, i] = p[t0 + c]
    if poses:
        for c in range(3):
            # tool x axis: column 0 of the tool rotation; tool z axis: column 2
            x_c = rot[18 + 3 * c] if r0 >= 0 else (1.0 if c == 0 else 0.0)
            z_c = rot[20 + 3 * c] if r0 >= 0 else (1.0 if c == 2 else 0.0)
            for i in range(n_poses):
                v[3 + c, i] = x_c
                v[6 + c, i] = z_c


@numba.njit(cache=True, error_model="numpy")
def _joint_turns(
    p: np.ndarray,
    q: np.ndarray,
    j: int,
    joints: np.ndarray,
    q_ref: np.ndarray,
    theta_ref: np.ndarray,
    cos_ref: np.ndarray,
    sin_ref: np.ndarray,
    p_ref: np.ndarray,
    cos_p: np.ndarray,
    sin_p: np.ndarray,
    n_vec: int,
    v: np.ndarray,
    b: np.ndarray,
    cos: np.ndarray,
    sin: np.ndarray,
) -> None:
    """Joint j's offset, turns and link length applied to the `n_vec` vectors of `v` at every
    pose (see :func:`_walk_trial`)."""
    n_poses = v.shape[1]
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
    if largest <= SERIES_LIMIT:
        # The usual case (every change within the series): the angles' cosines and sines
        # by the series, then the joint's turns of each vector in one pass over the poses,
        # the same operations in the same order as the passes below take them.
        has_beta = joints[j, 4] >= 0
        cb_, sb_ = _trig(p, joints[j, 4], p_ref, cos_p, sin_p) if has_beta else (1.0, 0.0)
        ca, sa = _trig(p, joints[j, 0], p_ref, cos_p, sin_p)
        a = p[joints[j, 1]]
        for i in range(n_poses):
            bi = b[i]
            b2 = bi * bi
            cb = 1.0 + b2 * (-0.5 + b2 * (1.0 / 24.0))
            sb = bi * (1.0 + b2 * (-1.0 / 6.0 + b2 * (1.0 / 120.0)))
            cos[i] = cos_ref[j, i] * cb - sin_ref[j, i] * sb
            sin[i] = sin_ref[j, i] * cb + cos_ref[j, i] * sb
        for m in range(n_vec):
            _series_turns(v, m, cos, sin, has_beta, (cb_, sb_, ca, sa), a, m == 0)
        return
    # A larger change somewhere: per pose the series or the angle's own cosine and sine.
    for i in range(n_poses):
        angle = theta if prismatic else q[i, j] + theta
        cos[i], sin[i] = _cos_sin(b[i], cos_ref[j, i], sin_ref[j, i], angle)
    for m in range(n_vec):
        _turn(v, 3 * m, 3 * m + 1, cos, sin)
    if joints[j, 4] >= 0:
        cb_, sb_ = _trig(p, joints[j, 4], p_ref, cos_p, sin_p)
        for m in range(n_vec):
            _turn_fixed(v, 3 * m + 2, 3 * m, cb_, sb_)
    ca, sa = _trig(p, joints[j, 0], p_ref, cos_p, sin_p)
    for m in range(n_vec):
        _turn_fixed(v, 3 * m + 1, 3 * m + 2, ca, sa)
    a = p[joints[j, 1]]
    for i in range(n_poses):
        v[0, i] += a


def chunk_count(n_trials: int) -> int:
    """Trial chunks for numba's threads: a few per thread, each chunk's scratch allocated once
    (a trial's values never depend on the chunks)."""
    return max(1, min(n_trials, 4 * numba.get_num_threads()))


@numba.njit(parallel=True, cache=True, error_model="numpy")
def walk(
    params: np.ndarray,
    qs: np.ndarray,
    joints: np.ndarray,
    blocks: np.ndarray,
    q_ref: np.ndarray,
    theta_ref: np.ndarray,
    cos_ref: np.ndarray,
    sin_ref: np.ndarray,
    p_ref: np.ndarray,
    cos_p: np.ndarray,
    sin_p: np.ndarray,
    poses: bool,
    out: np.ndarray,
    n_chunks: int,
) -> None:
    """Tool points (and rotations) of every trial at every pose, in the measurement frame.

    Parameters
    ----------
    params : (n_p, n_params), n_p 1 or n_trials
    qs : (n_q, n_poses, n_joints), n_q 1 or n_trials
    joints : (n_joints, 6) int64, see :class:`~robocal_uncertainty.kernels._layout.FlatLayout`
    blocks : (4,) int64
    q_ref : (n_joints, n_poses), reference readings, joint by joint; theta_ref : (n_joints,)
    cos_ref, sin_ref : (n_joints, n_poses), of the reference angles
    p_ref, cos_p, sin_p : (n_params,), the reference parameters and their cosines and sines
    poses : bool
        Also the rotation: out[..., 3:12] is ``world_R_tool`` row by row.
    out : (n_trials, n_poses, 3 or 12)
    n_chunks : int
        Chunks of trials spread over the threads (:func:`chunk_count`).
    """
    n_trials = out.shape[0]
    n_poses = out.shape[1]
    for c in numba.prange(n_chunks):
        rot = np.empty(27)
        v = np.empty((9, n_poses))
        b = np.empty(n_poses)
        cos = np.empty(n_poses)
        sin = np.empty(n_poses)
        for t in range(c * n_trials // n_chunks, (c + 1) * n_trials // n_chunks):
            p = params[0] if params.shape[0] == 1 else params[t]
            q = qs[0] if qs.shape[0] == 1 else qs[t]
            _walk_trial(
                p,
                q,
                joints,
                blocks,
                q_ref,
                theta_ref,
                cos_ref,
                sin_ref,
                p_ref,
                cos_p,
                sin_p,
                poses,
                rot,
                v,
                b,
                cos,
                sin,
                out[t],
            )


# --- The whole chord re-identification of a trial (see ChordSolver.solve) -------------------

POSE_SERIES_SINE = 2.0e-3
"""Largest ``sin(theta)`` of a residual rotation for which ``theta / sin(theta)`` is taken from
its series ``1 + s^2/6 + 3 s^4/40`` (the first term left out, ``5 s^6/112``, is below 3e-18);
larger rotations use ``atan2`` as :meth:`PoseMeasurement.residual` does."""


@numba.njit(cache=True, error_model="numpy")
def _residual(
    m: np.ndarray, pred: np.ndarray, poses: bool, wcomp: np.ndarray, pw: np.ndarray, has_pw: bool, r: np.ndarray
) -> bool:
    """Whitened, pose-weighted residual ``measured - predicted`` of one trial into r (n_eq,).

    Points: the difference. Poses: the difference of the positions and ``log(R_m R_p^T)``
    by :meth:`~robocal_uncertainty.core.pose_measurement.PoseMeasurement.residual`'s
    formulas; False (and nothing usable in r) when a residual rotation comes within ~0.14 rad
    of pi, where that method switches to another formula (the caller then takes the numpy path).
    """
    n_poses = pred.shape[0]
    dim = 6 if poses else 3
    for i in range(n_poses):
        mi = m[i]
        pi = pred[i]
        base = i * dim
        w_pose = pw[i] if has_pw else 1.0
        for c in range(3):
            value = (mi[c] - pi[c]) * wcomp[c]
            r[base + c] = value * w_pose if has_pw else value
        if poses:
            e00 = mi[3] * pi[3] + mi[4] * pi[4] + mi[5] * pi[5]
            e01 = mi[3] * pi[6] + mi[4] * pi[7] + mi[5] * pi[8]
            e02 = mi[3] * pi[9] + mi[4] * pi[10] + mi[5] * pi[11]
            e10 = mi[6] * pi[3] + mi[7] * pi[4] + mi[8] * pi[5]
            e11 = mi[6] * pi[6] + mi[7] * pi[7] + mi[8] * pi[8]
            e12 = mi[6] * pi[9] + mi[7] * pi[10] + mi[8] * pi[11]
            e20 = mi[9] * pi[3] + mi[10] * pi[4] + mi[11] * pi[5]
            e21 = mi[9] * pi[6] + mi[10] * pi[7] + mi[11] * pi[8]
            e22 = mi[9] * pi[9] + mi[10] * pi[10] + mi[11] * pi[11]
            w0, w1, w2 = e21 - e12, e02 - e20, e10 - e01
            cosine = 0.5 * (e00 + e11 + e22 - 1.0)
            if cosine < -0.99:
                return False
            s = 0.5 * math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
            if s <= POSE_SERIES_SINE and cosine > 0.0:
                s2 = s * s
                half = 0.5 * (1.0 + s2 * (1.0 / 6.0 + s2 * (3.0 / 40.0)))
            else:
                half = 0.5 * (math.atan2(s, cosine) / s)
            r[base + 3] = (half * w0) * wcomp[3]
            r[base + 4] = (half * w1) * wcomp[4]
            r[base + 5] = (half * w2) * wcomp[5]
            if has_pw:
                for c in range(3, 6):
                    r[base + c] *= w_pose
    return True


_SUMS = {"reassoc", "contract"}
"""The fast-math flags of the kernel's sums: reassociation (vectorised sums) and fused
multiply-adds, never the flags that assume no NaN or infinity. A sum's order then depends on
its length alone, never on the other trials."""


@numba.njit(cache=True, error_model="numpy", fastmath=_SUMS)
def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """``a @ b`` of two vectors of one length."""
    acc = 0.0
    for i in range(a.shape[0]):
        acc += a[i] * b[i]
    return acc


@numba.njit(cache=True, error_model="numpy", fastmath=_SUMS)
def _dot_row(a: np.ndarray, matrix: np.ndarray, row: int, n: int) -> float:
    """``a[:n] @ matrix[row, :n]``, indexed rather than sliced (a view of an array costs two
    atomic reference counts, and these products run a hundred times per trial)."""
    acc = 0.0
    for i in range(n):
        acc += a[i] * matrix[row, i]
    return acc


@numba.njit(cache=True, error_model="numpy")
def _times(vector: np.ndarray, matrix_t: np.ndarray, out: np.ndarray) -> None:
    """``out = vector @ matrix`` for vector (n,) and the matrix transposed, matrix_t (k, n)."""
    for c in range(out.shape[0]):
        out[c] = _dot_row(vector, matrix_t, c, vector.shape[0])


@numba.njit(cache=True, error_model="numpy")
def _eigen_step(
    rhs: np.ndarray,
    lam2: float,
    factors: tuple[np.ndarray, ...],
    rp: np.ndarray,
    rf: np.ndarray,
    y: np.ndarray,
    step: np.ndarray,
) -> None:
    """``(N + lam2 M) step = rhs`` by the Schur complement's eigen-decomposition, as
    :meth:`ChordSolver._step`; `factors` as :meth:`StepFactors.as_tuple` gives them."""
    pen_idx, free_idx, coupling, evecs, evecs_t, evals, normal_fp, free_inverse_t = factors
    n_pen = pen_idx.shape[0]
    n_free = free_idx.shape[0]
    # rp[:n_pen] the penalised right-hand side, rf[:n_free] the free one, y the rotated solution.
    for f in range(n_free):
        rf[f] = rhs[free_idx[f]]
    for a in range(n_pen):
        rp[a] = rhs[pen_idx[a]]
        if n_free:
            rp[a] -= _dot_row(rf, coupling, a, n_free)
    for e in range(n_pen):
        y[e] = _dot_row(rp, evecs_t, e, n_pen) / (evals[e] + lam2)
    for a in range(n_pen):
        rp[a] = _dot_row(y, evecs, a, n_pen)
        step[pen_idx[a]] = rp[a]
    if n_free:
        for f in range(n_free):
            y[f] = rhs[free_idx[f]] - _dot_row(rp, normal_fp, f, n_pen)
        for f in range(n_free):
            step[free_idx[f]] = _dot_row(y, free_inverse_t, f, n_free)


@numba.njit(cache=True, error_model="numpy")
def _cholesky(a: np.ndarray) -> bool:
    """Lower Cholesky factor of the symmetric `a` in place (its lower triangle); False when
    `a` is not numerically positive definite."""
    k = a.shape[0]
    for j in range(k):
        s = a[j, j]
        for m in range(j):
            s -= a[j, m] * a[j, m]
        if not s > 0.0:
            return False
        d = math.sqrt(s)
        a[j, j] = d
        for i in range(j + 1, k):
            s = a[i, j]
            for m in range(j):
                s -= a[i, m] * a[j, m]
            a[i, j] = s / d
    return True


@numba.njit(cache=True, error_model="numpy")
def _cholesky_solve(factor: np.ndarray, rhs: np.ndarray, step: np.ndarray) -> None:
    """``L L^T step = rhs`` for the factor of :func:`_cholesky`."""
    k = rhs.shape[0]
    for i in range(k):
        s = rhs[i]
        for m in range(i):
            s -= factor[i, m] * step[m]
        step[i] = s / factor[i, i]
    for i in range(k - 1, -1, -1):
        s = step[i]
        for m in range(i + 1, k):
            s -= factor[m, i] * step[m]
        step[i] = s / factor[i, i]


@numba.njit(cache=True, error_model="numpy")
def _norm(x: np.ndarray) -> float:
    return math.sqrt(_dot(x, x))


@numba.njit(parallel=True, cache=True, error_model="numpy")
def chord_solve(
    qs: np.ndarray,
    reading_errors: np.ndarray,
    measured: np.ndarray,
    deviations: np.ndarray,
    weights: np.ndarray,
    lambdas: np.ndarray,
    x_start: np.ndarray,
    problem: tuple[np.ndarray, ...],
    factors: tuple[np.ndarray, ...],
    walker: tuple[np.ndarray, ...],
    poses: bool,
    max_iterations: int,
    relative_tolerance: float,
    x_out: np.ndarray,
    steps: np.ndarray,
    failed: np.ndarray,
    n_chunks: int,
) -> None:
    """The chord re-identification of every trial, each trial start to end in one pass.

    The iteration of :meth:`~robocal_uncertainty.uncertainty.reidentification.ChordSolver.solve`
    with ``linear_start`` (first-order first step, then exact steps, the Jacobian frozen at
    the calibration): the numpy solver's operations in another order (equal to rounding).

    Parameters
    ----------
    qs : (n_q, n_poses, n_joints), n_q 1 or n_trials
    reading_errors : (n_e, n_poses, n_joints), n_e 0 or n_trials
        The trials' reading errors, added here to the shared `qs` (n_q 1); n_e 0: none.
    measured : (n_m, n_poses, value_size), n_m 1 or n_trials
    deviations : (n_d, n_poses, dimension), n_d 0 or n_trials
        The trials' measurement errors, applied here to the shared `measured` (n_m 1) by
        :func:`_perturb`; n_d 0: `measured` are the trials' values.
    weights : (n_w, n_poses), n_w 0 (every pose) or n_trials
    lambdas : (n_trials,); x_start : (k,)
    problem : tuple
        The problem's nominal parameters (n_params,), estimated indices (k,), column scaling
        (k,), penalty mask (k,); the whitened Jacobian transposed (k, n_poses dimension); the
        whitening (dimension,); the whitened ``J_q`` (n_poses, dimension, n_joints), so that
        the first step's right-hand side is ``(r - J_q dQ) J`` (the numpy iteration's
        ``r J - dQ @ joint_map``); the pose normals (n_poses, k k); the reference prediction
        (n_poses, value_size) and readings (n_poses, n_joints).
    factors
        :meth:`~robocal_uncertainty.uncertainty.reidentification.StepFactors.as_tuple`.
    walker : tuple
        The walk's layout and reference, ``joints .. sin_p`` of :func:`walk`.
    poses : bool
        6-DOF values (12 per pose, 6 equations) instead of points.
    x_out : (n_trials, k); steps : (n_trials,) int64; failed : (n_trials,) bool
        Results: the trial's parameters, steps taken, and whether the trial needs the numpy
        path (a residual rotation near pi, or a weighted normal matrix that is not positive definite).
    n_chunks : int, as for :func:`walk`
    """
    n_trials = x_out.shape[0]
    ref_joints = problem[9]
    n_poses, nj = ref_joints.shape
    # The first step corrects for readings that differ from the reference (numpy: np.any(dq)).
    correct = qs.shape[0] > 1 or reading_errors.shape[0] > 0 or _differs(qs[0], ref_joints)
    has_w = weights.shape[0] > 0
    for ch in numba.prange(n_chunks):
        scratch = _trial_scratch(n_poses, nj, x_start.shape[0], problem[0].shape[0], poses)
        pw = scratch[-1]
        pw[:] = 1.0
        perturbed = np.empty((n_poses, measured.shape[2]))
        read = np.empty((n_poses, nj))
        for t in range(ch * n_trials // n_chunks, (ch + 1) * n_trials // n_chunks):
            if has_w:
                pw[:] = weights[t]
            q = qs[0] if qs.shape[0] == 1 else qs[t]
            if reading_errors.shape[0] > 0:
                _add(q, reading_errors[t], read)
                q = read
            m = measured[0] if measured.shape[0] == 1 else measured[t]
            if deviations.shape[0] > 0:
                _perturb(m, deviations[t], poses, perturbed)
                m = perturbed
            settings = (poses, has_w, correct, max_iterations, relative_tolerance)
            steps[t], failed[t] = _solve_trial(q, m, lambdas[t], x_start, problem, factors, walker, settings, scratch)
            x_out[t] = scratch[9]


@numba.njit(cache=True, error_model="numpy")
def _trial_scratch(n_poses: int, nj: int, k: int, n_params: int, poses: bool) -> tuple[np.ndarray, ...]:
    """Working arrays of :func:`_solve_trial` (allocated once per chunk of trials): the walk's
    rot, v, b, cos, sin; pred, r, rhs, step, x, rp, rf, y, dqs, params, normal, pw."""
    width = 12 if poses else 3
    dim = 6 if poses else 3
    return (
        np.empty(27),
        np.empty((9, n_poses)),
        np.empty(n_poses),
        np.empty(n_poses),
        np.empty(n_poses),
        np.empty((n_poses, width)),
        np.empty(n_poses * dim),
        np.empty(k),
        np.empty(k),
        np.empty(k),
        np.empty(k),
        np.empty(k),
        np.empty(k),
        np.empty(nj),
        np.empty(n_params),
        np.empty((k, k)),
        np.ones(n_poses),
    )


@numba.njit(cache=True, error_model="numpy")
def _solve_trial(
    q: np.ndarray,
    m: np.ndarray,
    lam: float,
    x_start: np.ndarray,
    problem: tuple[np.ndarray, ...],
    factors: tuple[np.ndarray, ...],
    walker: tuple[np.ndarray, ...],
    settings: tuple[bool, bool, bool, int, float],
    scratch: tuple[np.ndarray, ...],
) -> tuple[int, bool]:
    """One trial of :func:`chord_solve` (readings q, measured values m, lambda `lam`): its
    parameters into ``scratch[9]``; returns the steps taken and whether it failed.
    `settings`: poses, pose weights given (in ``scratch[-1]``), readings to correct for in
    the first step, the most steps, the relative tolerance."""
    start, estimated, scale, mask, jacobian_t, wcomp, joint_jacobian, pose_normal, reference, ref_joints = problem
    rot, v, b, cos, sin, pred, r, rhs, step, x, rp, rf, y, dqs, params, normal, pw = scratch
    poses, has_w, correct, max_iterations, relative_tolerance = settings
    k = x.shape[0]
    lam2 = lam * lam
    x[:] = x_start
    # Step 1: the first-order prediction at the start.
    if not _residual(m, reference, poses, wcomp, pw, has_w, r):
        return 1, True
    if correct:
        _reading_correction(q, ref_joints, joint_jacobian, pw, has_w, dqs, r)
    _times(r, jacobian_t, rhs)
    for c in range(k):
        rhs[c] -= lam2 * (x[c] * mask[c])
    if has_w:
        # Every trial its own normal matrix (its poses), factorised once for its steps.
        if not _weighted_normal(pose_normal, pw, lam2, mask, normal):
            return 1, True
        _cholesky_solve(normal, rhs, step)
    else:
        _eigen_step(rhs, lam2, factors, rp, rf, y, step)
    for c in range(k):
        x[c] += step[c]
    first = max(_norm(step), 2.2250738585072014e-308)
    # Exact steps until one is small enough.
    for it in range(2, max_iterations + 1):
        params[:] = start
        for c in range(k):
            params[estimated[c]] += x[c] / scale[c]
        joints, blocks, q_ref, theta_ref, cos_ref, sin_ref, p_ref, cos_p, sin_p = walker
        _walk_trial(
            params,
            q,
            joints,
            blocks,
            q_ref,
            theta_ref,
            cos_ref,
            sin_ref,
            p_ref,
            cos_p,
            sin_p,
            poses,
            rot,
            v,
            b,
            cos,
            sin,
            pred,
        )
        if not _residual(m, pred, poses, wcomp, pw, has_w, r):
            return it - 1, True
        _times(r, jacobian_t, rhs)
        for c in range(k):
            rhs[c] -= lam2 * (x[c] * mask[c])
        if has_w:
            _cholesky_solve(normal, rhs, step)
        else:
            _eigen_step(rhs, lam2, factors, rp, rf, y, step)
        for c in range(k):
            x[c] += step[c]
        if not _norm(step) > relative_tolerance * first:
            return it, False
    return max(1, max_iterations), False


@numba.njit(cache=True, error_model="numpy")
def _reading_correction(
    q: np.ndarray,
    ref_joints: np.ndarray,
    joint_jacobian: np.ndarray,
    pw: np.ndarray,
    has_w: bool,
    dqs: np.ndarray,
    r: np.ndarray,
) -> None:
    """``r -= J_q dQ`` pose by pose (pose-weighted): the reading errors' first-order move of
    the residual at the reference."""
    n_poses, nj = ref_joints.shape
    dim = joint_jacobian.shape[1]
    for i in range(n_poses):
        for j in range(nj):
            dqs[j] = q[i, j] - ref_joints[i, j]
        w_pose = pw[i] if has_w else 1.0
        jq = joint_jacobian[i]
        for c in range(dim):
            row = jq[c]
            moved = 0.0
            for j in range(nj):
                moved += row[j] * dqs[j]
            r[i * dim + c] -= moved * w_pose if has_w else moved


@numba.njit(cache=True, error_model="numpy")
def _weighted_normal(
    pose_normal: np.ndarray, pw: np.ndarray, lam2: float, mask: np.ndarray, normal: np.ndarray
) -> bool:
    """``sum_i w_i J_i^T J_i + lam2 M`` into `normal` (k, k), factorised by :func:`_cholesky`
    in place; False when it is not positive definite."""
    k = normal.shape[0]
    flat_normal = normal.reshape(k * k)
    flat_normal[:] = 0.0
    for i in range(pw.shape[0]):
        wi = pw[i]
        if wi != 0.0:
            contribution = pose_normal[i]
            for e in range(k * k):
                flat_normal[e] += wi * contribution[e]
    for c in range(k):
        normal[c, c] += lam2 * mask[c]
    return _cholesky(normal)


POSE_SERIES_THETA2 = 1.0e-6
"""Squared angle [rad^2] of a trial's orientation errors below which :func:`_perturb` takes
``sin(t) / t`` and ``(1 - cos t) / t^2`` from their series, as
:meth:`~robocal_uncertainty.core.pose_measurement.PoseMeasurement.perturb` does."""


@numba.njit(cache=True, error_model="numpy")
def _perturb(values: np.ndarray, errors: np.ndarray, poses: bool, out: np.ndarray) -> None:
    """One trial's measured values moved by its errors into `out` (n_poses, value_size).

    Points: ``values + errors``. Poses: the position plus its error and ``exp([e]x) R`` by
    :meth:`~robocal_uncertainty.core.pose_measurement.PoseMeasurement.perturb`'s formulas,
    operation by operation. That method takes the series for a whole batch when every angle
    of the batch is small; here the choice is the trial's own (its every angle below 1e-3
    rad: the series; else per pose as there), so where a batch holds a larger angle the two
    differ by rounding alone, and a trial's values never depend on the other trials.
    """
    n_poses = values.shape[0]
    if not poses:
        for i in range(n_poses):
            for c in range(values.shape[1]):
                out[i, c] = values[i, c] + errors[i, c]
        return
    largest = 0.0
    for i in range(n_poses):
        e = errors[i]
        largest = max(largest, e[3] * e[3] + e[4] * e[4] + e[5] * e[5])
    for i in range(n_poses):
        _perturb_pose(values[i], errors[i], largest < POSE_SERIES_THETA2, out[i])


@numba.njit(cache=True, error_model="numpy")
def _perturb_pose(v: np.ndarray, e: np.ndarray, series: bool, out: np.ndarray) -> None:
    """One pose's 12 values moved by its 6 errors (see :func:`_perturb`)."""
    for c in range(3):
        out[c] = v[c] + e[c]
    e0, e1, e2 = e[3], e[4], e[5]
    theta2 = e0 * e0 + e1 * e1 + e2 * e2
    if series or theta2 < 1e-8:
        a = 1.0 - theta2 / 6.0 + (theta2 * theta2) / 120.0
        b = 0.5 - theta2 / 24.0 + (theta2 * theta2) / 720.0
    else:
        t = math.sqrt(theta2)
        a = math.sin(t) / t
        b = (1.0 - math.cos(t)) / (t * t)
    diagonal = 1.0 - b * theta2
    be0, be1, be2 = b * e0, b * e1, b * e2
    ae0, ae1, ae2 = a * e0, a * e1, a * e2
    for i in range(3):
        if i == 0:
            x, y, z = diagonal + be0 * e0, be0 * e1 - ae2, be0 * e2 + ae1
        elif i == 1:
            x, y, z = be1 * e0 + ae2, diagonal + be1 * e1, be1 * e2 - ae0
        else:
            x, y, z = be2 * e0 - ae1, be2 * e1 + ae0, diagonal + be2 * e2
        for j in range(3):
            out[3 + 3 * i + j] = x * v[3 + j] + y * v[6 + j] + z * v[9 + j]


@numba.njit(cache=True, error_model="numpy")
def _add(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """``out = a + b`` for 2-D arrays of one shape."""
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            out[i, j] = a[i, j] + b[i, j]


@numba.njit(cache=True, error_model="numpy")
def _differs(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two 2-D arrays of one shape differ anywhere."""
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            if a[i, j] != b[i, j]:
                return True
    return False
