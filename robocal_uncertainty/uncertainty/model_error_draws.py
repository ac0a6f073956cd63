"""The model error every statement draws: one Gaussian field over configurations.

What the kinematic model cannot represent (gear errors, compliance, thermal gradients) is a
smooth function of the joint configuration. ``verify`` already states it as the Gaussian field
of :mod:`~robocal_uncertainty.core.model_error_field`; drawing it independently from pose to
pose instead (the residual bootstrap) states the same calibration another way: an error that
is smooth over the workspace is treated as one that averages out, and what the fit absorbed of
it at its poses is counted again at every test configuration.

With ``model_error="field"`` (``--model-error-field``; not the default, see the README's
held-out study) the ``residual`` source draws the field **jointly** over the calibration poses
and the test configurations: ``e_t`` is added to the measured values (the re-fit absorbs part of it, as
the calibration did) and ``-e_c`` to the predictions, so a trial's deviation is
``J G e_t - e_c``, whose covariance is that of the real prediction error ``e_c - J G e_t``
(``G`` the fit's gain): the cross term ``J G K_tc`` that ``verify`` subtracts analytically, by
construction. The GUM statement propagates the covariance of the same vector.

The field's covariance is a scalar correlation over configurations times one per-pose
covariance ``Sigma_m`` (``d x d``, the measurement's residual coordinates), so every draw is a
product of a scalar factor and ``Sigma_m^(1/2)``. Calibration poses are drawn through the
Cholesky factor ``L`` of their correlation ``C_tt = c R_tt + (1 - c) I``; the test
configurations conditionally on them, ``e_c = B z_t + D^(1/2) z_c`` with ``B = c R_ct L^-T``
and ``D = C_cc - B B^T``: jointly (a Cholesky factor of ``D``) up to :data:`JOINT_TEST_MAX`
configurations, beyond (a workspace map's thousands) with the diagonal of ``D`` only, so each
configuration's marginal (and its correlation with the calibration poses) is exact and memory
grows as ``n_c n_t``, never ``n_c^2``.

The correlation (``c``, ``l``) comes from restricted maximum likelihood on the calibration's own
residuals, whitened by the measurement type's weights (points and 6-DOF poses alike); the
per-pose covariance ``Sigma_m = diag(f) S diag(f)`` (``S`` the shape of the residuals'
covariance) from their leave-one-out prediction errors, component by component: the spread a
prediction at a configuration the fit did not see has, which a misstated kernel cannot make too
small. The draws resample the standardised residuals (the field's covariance, the residuals'
distribution). A field whose scale the poses do not determine (fewer than 32 effective degrees
of freedom) is not drawn: the residual source then draws the independent model error. No
constant is tuned to a data set.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.measurement import row_weights
from robocal_uncertainty.core.model_error_field import FIELD_KERNEL, FIELD_METRIC, chordal_distance, kernel_correlation
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty.model_adequacy import MIN_RESIDUAL_DOF_PER_COMPONENT

__all__ = [
    "FIELD_LENGTH_BOUNDS",
    "FIELD_MAX_EQUATIONS",
    "JOINT_TEST_MAX",
    "FieldEstimate",
    "FieldNormal",
    "central_hessian",
    "estimate_field",
    "standardised_innovations",
]

Array = NDArray[np.float64]
FIELD_MAX_EQUATIONS = 600
"""Most residual equations the hyperparameters are estimated from (a seeded subset of the poses
of larger campaigns: 200 point poses, 100 6-DOF poses); the likelihood costs a Cholesky
factorisation of this size per evaluation."""
JOINT_TEST_MAX = 1024
"""Test configurations up to which their model errors are drawn jointly (their correlation kept);
beyond, each conditionally on the calibration poses alone (exact per-configuration marginals)."""
FIELD_LENGTH_BOUNDS = (0.02, 20.0)
"""Range [rad] of the field's correlation length searched by the likelihood (shared with the
session field of :mod:`.sessions`)."""
_JITTER = 1e-10


@dataclass(frozen=True, eq=False)
class FieldEstimate:
    """The model-error field of a calibration, in its measurement's residual coordinates.

    Attributes
    ----------
    correlated_fraction : float
        ``c`` in [0, 1] (0: independent from pose to pose).
    length_scale : float [rad]
        ``l`` of the exponential kernel over the chordal joint distance.
    per_pose_covariance : ndarray, shape (d, d) [m^2; rad^2 for rotation components]
        ``Sigma_m``: the model error's covariance at one configuration, measurement frame (its
        scale from the leave-one-out prediction errors, see :func:`estimate_field`).
    likelihood_per_pose_covariance : ndarray, shape (d, d), or None
        The same with the restricted-likelihood scale (recorded for comparison).
    log_likelihood, independent_log_likelihood : float
        Restricted log-likelihood at the estimate and of the best ``c = 0`` model.
    dof : float
        Effective degrees of freedom of the scale (``2 / var(log s)`` from the curvature).
    poses_used : int
        Poses the hyperparameters were estimated from.
    """

    correlated_fraction: float
    length_scale: float
    per_pose_covariance: Array
    likelihood_per_pose_covariance: Array | None = None
    log_likelihood: float = float("nan")
    independent_log_likelihood: float = float("nan")
    dof: float = float("inf")
    poses_used: int = 0
    kernel: str = FIELD_KERNEL
    metric: str = FIELD_METRIC

    @property
    def identified(self) -> bool:
        """Whether the data determine the field well enough to state it (``dof >= 32``).

        The rule of :data:`~robocal_uncertainty.uncertainty.model_adequacy.MIN_RESIDUAL_DOF_PER_COMPONENT`
        for one variance: with fewer effective degrees of freedom the scale is uncertain by more
        than 25 % and a 95 % interval's coverage by more than 4 %. A correlated field's scale has
        far fewer than ``d n`` (a 53-pose UR10 campaign: 1-30), and then the correlation length
        and the scale trade off against each other; the residual source then draws the
        independent model error (the field's ``c = 0`` case), whose covariance has ``d n - p``.
        """
        return bool(self.dof >= MIN_RESIDUAL_DOF_PER_COMPONENT)

    @property
    def standard_uncertainty(self) -> Array:
        """Per-component standard uncertainty of the model error at one configuration, shape (d,)."""
        return np.sqrt(np.clip(np.diag(self.per_pose_covariance), 0.0, None))

    def to_dict(self) -> dict[str, object]:
        """JSON-ready record (reports, ``calibrate --json``)."""
        return {
            "kernel": self.kernel,
            "metric": self.metric,
            "correlated_fraction": float(self.correlated_fraction),
            "length_scale_rad": float(self.length_scale),
            "per_pose_covariance": self.per_pose_covariance.tolist(),
            "standard_uncertainty": self.standard_uncertainty.tolist(),
            "likelihood_standard_uncertainty": None
            if self.likelihood_per_pose_covariance is None
            else np.sqrt(np.clip(np.diag(self.likelihood_per_pose_covariance), 0.0, None)).tolist(),
            "log_likelihood": float(self.log_likelihood),
            "independent_log_likelihood": float(self.independent_log_likelihood),
            "dof": float(self.dof),
            "identified": self.identified,
            "poses_used": int(self.poses_used),
        }


def central_hessian(fun: Callable[[Array], float], x0: Array, free: list[int], step: float = 1e-3) -> Array:
    """Central-difference Hessian of `fun` at `x0` over the coordinates `free`."""
    hess = np.empty((len(free), len(free)))
    for a, i in enumerate(free):
        for b, j in enumerate(free):
            values = []
            for si, sj in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
                x = x0.copy()
                x[i] += si * step
                x[j] += sj * step
                values.append(fun(x))
            hess[a, b] = (values[0] - values[1] - values[2] + values[3]) / (4 * step * step)
    return hess


def estimate_field(
    calibration: IdentificationResult,
    joint_positions: Array,
    noise: Array,
    shape: Array,
    *,
    max_equations: int = FIELD_MAX_EQUATIONS,
    seed: int = 0,
) -> FieldEstimate:
    """The model-error field of a calibration by restricted maximum likelihood.

    The residuals' projection on the directions orthogonal to the (whitened) Jacobian depends
    neither on the parameters nor on their estimate and is normal with covariance
    ``Q^T W (N + V(s, c, l)) W Q`` (``N`` the stated noise, ``V = [c rho(d / l) + (1 - c) I]
    (x) s S``, ``W`` the measurement type's whitening weights); ``s``, ``c``, ``l`` maximise its
    likelihood (Harville's identity, ``Q`` never formed). ``c = 0`` is the independent model
    error; for points it is the estimator of
    :func:`~robocal_uncertainty.uncertainty.sessions.estimate_model_error_field`. The returned
    per-pose covariance keeps ``c`` and ``l`` and takes its scale, per component, from the
    leave-one-out prediction errors (:func:`_leave_one_out_scale`,
    :func:`_leave_one_out_components`); the likelihood's is recorded beside it.

    Parameters
    ----------
    calibration : IdentificationResult
    joint_positions : ndarray, shape (n, n_joints) [rad]
    noise : ndarray, shape (n, d, d)
        Stated noise covariance per pose, residual coordinates (unweighted).
    shape : ndarray, shape (d, d)
        Shape ``S`` of the per-pose model-error covariance (its scale is estimated).
    max_equations : int
        Campaigns with more residual equations use a seeded subset of their poses.
    seed : int
        Seed of that subset.
    """
    from scipy import linalg, optimize

    measurement = calibration.measurement
    residuals = np.asarray(calibration.residuals, dtype=np.float64)
    n_all, d = residuals.shape
    idx = np.arange(n_all)
    max_poses = max(int(max_equations) // d, 1)
    if n_all > max_poses:
        idx = np.sort(np.random.default_rng(seed).choice(n_all, size=max_poses, replace=False))
    q = np.asarray(joint_positions, dtype=np.float64)[idx]
    n = q.shape[0]
    layout = calibration.model.layout
    est = np.flatnonzero(calibration.estimated)
    _, jac = measurement.predict_and_jacobian(layout, calibration.estimate, q)
    w_row = row_weights(measurement, n)
    w = np.ones(n * d) if w_row is None else np.asarray(w_row, dtype=np.float64)
    a_mat = jac.reshape(n * d, layout.size)[:, est] / calibration.column_scale[est] * w[:, None]
    u, sv, _ = np.linalg.svd(a_mat, full_matrices=False)
    fit = u[:, : int(np.sum(sv > 1e-10 * sv[0]))]
    r = residuals[idx].reshape(-1) * w
    m = r.size - fit.shape[1]
    w_pose = w[:d]
    shape = np.asarray(shape, dtype=np.float64)
    scale = float(np.trace(w_pose[:, None] * shape * w_pose[None, :])) / d
    if not np.isfinite(scale) or scale <= 0.0:
        shape, scale = np.diag(1.0 / w_pose**2), 1.0
    shape = shape / scale  # whitened trace d
    ww = np.outer(w, w)
    n_cov = linalg.block_diag(*noise[idx]) * ww
    white = np.kron(np.eye(n), shape) * ww
    kron_ones = np.kron(np.ones((n, n)), shape) * ww
    distance = chordal_distance(q, q)
    noise_level = float(np.trace(n_cov)) / r.size
    mean_square = float(r @ r) / max(m, 1)

    def nll(log_s: float, c: float, log_l: float) -> float:
        # log|Q^T V Q| = log|V| + log|U^T V^-1 U| and
        # r^T Q (Q^T V Q)^-1 Q^T r = r^T (V^-1 - V^-1 U (U^T V^-1 U)^-1 U^T V^-1) r.
        s = float(np.exp(log_s))
        cov = n_cov + s * (1.0 - c) * white
        if c > 0.0:
            rho = kernel_correlation(distance, float(np.exp(log_l)))
            cov = cov + s * c * np.repeat(np.repeat(rho, d, axis=0), d, axis=1) * kron_ones
        try:
            chol = linalg.cholesky(cov, lower=True)
            vi_u = linalg.cho_solve((chol, True), fit)
            vi_r = linalg.cho_solve((chol, True), r)
            chol_u = linalg.cholesky(fit.T @ vi_u, lower=True)
        except (linalg.LinAlgError, ValueError):
            return float("inf")
        z = linalg.solve_triangular(chol_u, fit.T @ vi_r, lower=True)
        quad = float(r @ vi_r - z @ z)
        return float(np.sum(np.log(np.diag(chol))) + np.sum(np.log(np.diag(chol_u))) + 0.5 * quad)

    s0 = max(mean_square - noise_level, 1e-3 * max(noise_level, 1e-30))
    floor = max(noise_level, 1e-30)
    lo_s, hi_s = np.log(1e-6 * floor), np.log(1e4 * max(mean_square, floor))
    lo_l, hi_l = np.log(FIELD_LENGTH_BOUNDS[0]), np.log(FIELD_LENGTH_BOUNDS[1])
    independent = optimize.minimize_scalar(lambda a: nll(a, 0.0, 0.0), bounds=(lo_s, hi_s), method="bounded")
    best = (float(independent.fun), float(independent.x), 0.0, float(np.log(0.5)))
    for length in (0.1, 0.5, 2.0):
        res = optimize.minimize(
            lambda t: nll(t[0], t[1], t[2]),
            x0=np.array([np.clip(np.log(s0), lo_s, hi_s), 0.5, np.log(length)]),
            method="L-BFGS-B",
            bounds=[(lo_s, hi_s), (0.0, 1.0), (lo_l, hi_l)],
        )
        if res.fun < best[0]:
            best = (float(res.fun), float(res.x[0]), float(res.x[1]), float(res.x[2]))
    fun, log_s, c, log_l = best
    free = [0] if c <= 1e-6 else ([0, 1, 2] if c < 1.0 - 1e-6 else [0, 2])
    hess = central_hessian(lambda x: nll(x[0], min(max(x[1], 0.0), 1.0), x[2]), np.array([log_s, c, log_l]), free)
    try:
        var_log_s = float(np.linalg.inv(hess)[0, 0])
    except np.linalg.LinAlgError:
        var_log_s = float("nan")
    dof = 2.0 / var_log_s if np.isfinite(var_log_s) and var_log_s > 0 else float(m)
    const = 0.5 * m * np.log(2 * np.pi)
    unit: Array = np.asarray((1.0 - c) * white, dtype=np.float64)
    if c > 0.0:
        rho = kernel_correlation(distance, float(np.exp(log_l)))
        unit = np.asarray(unit + c * np.repeat(np.repeat(rho, d, axis=0), d, axis=1) * kron_ones, dtype=np.float64)
    scale = _leave_one_out_scale(r, fit, n_cov, unit, d, (float(np.exp(lo_s)), float(np.exp(hi_s))))
    if scale is None:  # no scale explains the prediction errors (a degenerate shape): the likelihood's
        scale = float(np.exp(log_s))
    factors = _leave_one_out_components(r, fit, n_cov, unit, d, scale)
    return FieldEstimate(
        correlated_fraction=float(c),
        length_scale=float(np.exp(log_l)),
        per_pose_covariance=shape * np.outer(factors, factors),
        likelihood_per_pose_covariance=float(np.exp(log_s)) * shape,
        log_likelihood=-fun - const,
        independent_log_likelihood=-float(independent.fun) - const,
        dof=float(min(max(dof, 1.0), m)),
        poses_used=int(n),
    )


def _leave_one_out_scale(
    r: Array, fit: Array, noise: Array, unit: Array, d: int, bounds: tuple[float, float]
) -> float | None:
    """The field's scale ``s`` at which the leave-one-out prediction errors have the spread the
    field states for them.

    For the (linearised) least-squares fit with hat matrix ``H = U U^T`` the prediction error of
    pose i by a fit without it is ``(I - H_ii)^-1 r_i`` exactly, with covariance
    ``(I - H_ii)^-1 [P V P]_ii (I - H_ii)^-T`` (``P = I - H``, ``V = N + s K``): the statement a
    calibration makes at a configuration it did not see, cross term included. Its standardised
    square is ``r_i^T [P V P]_ii^-1 r_i``; ``s`` makes their mean equal to ``d`` (bisection: the
    mean decreases with ``s``). The restricted likelihood fixes the correlation (``c``, ``l``);
    this estimate of the scale depends only on the per-pose blocks, so a misstated correlation
    (too smooth a field, too much absorbed by the fit) shows as larger prediction errors and a
    larger scale, not as an over-confident statement (cross-validated variance estimation is the
    robust one under a misspecified kernel: Bachoc 2013, Comput. Stat. Data Anal. 66).
    """
    proj = np.eye(r.size) - fit @ fit.T
    n = r.size // d
    idx = np.arange(n)
    pnp = (proj @ noise @ proj).reshape(n, d, n, d)[idx, :, idx, :]
    pkp = (proj @ unit @ proj).reshape(n, d, n, d)[idx, :, idx, :]
    # The residual's part in the fit space (a regularised fit leaves some) is no prediction error:
    # the model's residual is P (e + eps), as in the restricted likelihood's contrasts.
    r_pose = (proj @ r).reshape(n, d)

    def excess(log_s: float) -> float:
        blocks = pnp + float(np.exp(log_s)) * pkp
        sol = np.linalg.solve(blocks + 1e-300 * np.eye(d), r_pose[..., None])[..., 0]
        return float(np.mean(np.sum(r_pose * sol, axis=1))) / d - 1.0

    lo, hi = np.log(bounds[0]), np.log(bounds[1])
    if excess(lo) <= 0.0:
        return float(bounds[0])
    if excess(hi) >= 0.0:
        return None
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if excess(mid) > 0.0:
            lo = mid
        else:
            hi = mid
    return float(np.exp(0.5 * (lo + hi)))


def _leave_one_out_components(
    r: Array, fit: Array, noise: Array, unit: Array, d: int, scale: float, iterations: int = 40
) -> Array:
    """Per-component factors ``f_j`` of the field (``Sigma_m = diag(f) S diag(f)``) at which every
    component's leave-one-out prediction errors have the spread the field states for them.

    The pooled scale of :func:`_leave_one_out_scale` matches their mean over the components;
    the correlation length is shared by all components, and a component the field states too
    smooth (say the rotations of a 6-DOF pose, or one axis) would keep a too narrow statement.
    Here, with ``e_i = (I - H_ii)^-1 r_i`` and its stated covariance ``M_i`` (as there), every
    component's mean of ``e_ij^2 / M_i,jj`` is brought to 1 by the fixed-point iteration
    ``f_j <- f_j sqrt(mean)``; starting from ``f = sqrt(s)``. Returns ``f``, shape (d,).
    """
    n = r.size // d
    proj = np.eye(r.size) - fit @ fit.T
    idx = np.arange(n)
    lever = (fit @ fit.T).reshape(n, d, n, d)[idx, :, idx, :]
    inv = np.linalg.pinv(np.eye(d)[None] - lever)
    pnp = (proj @ noise @ proj).reshape(n, d, n, d)[idx, :, idx, :]
    err = np.einsum("pij,pj->pi", inv, (proj @ r).reshape(n, d))
    factors = np.full(d, np.sqrt(max(scale, 0.0)))
    if not np.all(factors > 0.0):
        return factors
    for _ in range(iterations):
        scaled = unit * np.outer(np.tile(factors, n), np.tile(factors, n))
        pkp = (proj @ scaled @ proj).reshape(n, d, n, d)[idx, :, idx, :]
        stated = np.einsum("pij,pjk,plk->pil", inv, pnp + pkp, inv)
        ratio = np.mean(err**2 / np.maximum(np.diagonal(stated, axis1=1, axis2=2), np.finfo(float).tiny), axis=0)
        if np.max(np.abs(ratio - 1.0)) < 1e-3:
            break
        factors = factors * np.sqrt(ratio)
    return np.asarray(factors, dtype=np.float64)


def standardised_innovations(residuals: Array) -> Array | None:
    """The residuals centred and whitened to identity covariance, shape (n, d); None when their
    covariance is singular (a direction without scatter: normal innovations then).

    Resampling them keeps the shape of the residual distribution (its tails, its mixture of
    directions) in the drawn model errors, at exactly the field's covariance.
    """
    r = np.asarray(residuals, dtype=np.float64)
    if r.shape[0] < 2 * r.shape[1]:
        return None
    centred = r - r.mean(axis=0)
    evals, evecs = np.linalg.eigh(centred.T @ centred / r.shape[0])
    if evals[0] <= 1e-12 * max(float(evals[-1]), np.finfo(float).tiny):
        return None
    return np.asarray(centred @ (evecs / np.sqrt(evals)) @ evecs.T, dtype=np.float64)


def _psd_factor(matrix: Array) -> Array:
    """A factor ``F`` with ``F F^T = matrix`` (Cholesky; symmetric eigen-factor when singular)."""
    sym = 0.5 * (matrix + matrix.T)
    try:
        return np.asarray(np.linalg.cholesky(sym), dtype=np.float64)
    except np.linalg.LinAlgError:
        evals, evecs = np.linalg.eigh(sym)
        return np.asarray(evecs * np.sqrt(np.clip(evals, 0.0, None)), dtype=np.float64)


@dataclass(frozen=True, eq=False)
class FieldNormal:
    """Joint draw of the field at calibration poses and (negated) at test configurations.

    A :class:`~robocal_uncertainty.montecarlo.distributions.Distribution` of size
    ``(n_t + n_c) d``: pose-major ``e_t`` (the calibration poses' model errors), then
    ``-e_c`` (the test configurations'), see the module docstring. The draws are
    ``(F_s (x) Sigma_m^(1/2)) z``; ``z`` is standard normal, or, with `innovations`, resampled
    from them (the residuals' own distribution, standardised): the covariance is the same either
    way, and with ``c = 0`` the latter is the independent residual bootstrap.

    Parameters
    ----------
    calibration_joints : ndarray, shape (n_t, n_joints) [rad]
    test_joints : ndarray, shape (n_c, n_joints) [rad]
    estimate : FieldEstimate
    innovations : ndarray, shape (m, d), optional
        Zero-mean vectors with identity covariance (:func:`standardised_innovations`).
    """

    calibration_joints: Array
    test_joints: Array
    estimate: FieldEstimate
    innovations: Array | None = None
    _tt: Array = field(init=False, repr=False)
    _ct: Array = field(init=False, repr=False)
    _cc: Array = field(init=False, repr=False)
    _root: Array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        qt = np.asarray(self.calibration_joints, dtype=np.float64)
        qc = np.asarray(self.test_joints, dtype=np.float64)
        if qt.ndim != 2 or qc.ndim != 2 or qt.shape[1] != qc.shape[1]:
            msg = f"field draw: joint arrays of shapes {qt.shape} and {qc.shape} do not match"
            raise ConfigError(msg)
        c = float(self.estimate.correlated_fraction)
        ell = float(self.estimate.length_scale)
        n_t = qt.shape[0]
        c_tt = c * kernel_correlation(chordal_distance(qt, qt), ell) + (1.0 - c) * np.eye(n_t)
        l_tt = _psd_factor(c_tt + _JITTER * np.eye(n_t))
        r_ct = c * kernel_correlation(chordal_distance(qc, qt), ell)
        # B = c R_ct L^-T: Cov(B z_t, L z_t) = c R_ct.
        b = np.linalg.lstsq(l_tt, r_ct.T, rcond=None)[0].T
        if qc.shape[0] <= JOINT_TEST_MAX:
            c_cc = c * kernel_correlation(chordal_distance(qc, qc), ell) + (1.0 - c) * np.eye(qc.shape[0])
            cc = _psd_factor(c_cc - b @ b.T + _JITTER * np.eye(qc.shape[0]))
        else:
            cc = np.sqrt(np.clip(1.0 - np.sum(b * b, axis=1), 0.0, None))
        root = _psd_factor(np.asarray(self.estimate.per_pose_covariance, dtype=np.float64))
        object.__setattr__(self, "_tt", l_tt)
        object.__setattr__(self, "_ct", b)
        object.__setattr__(self, "_cc", cc)
        object.__setattr__(self, "_root", root)

    @property
    def dimension(self) -> int:
        """Components per configuration (d)."""
        return int(self._root.shape[0])

    @property
    def size(self) -> int:
        return (self._tt.shape[0] + self._ct.shape[0]) * self.dimension

    def mean_vector(self) -> Array:
        return np.zeros(self.size)

    def scalar_covariance(self) -> Array:
        """Correlation (scalar) of ``(e_t, -e_c)`` as drawn, shape (n_t + n_c, n_t + n_c)."""
        l_tt, b = self._tt, self._ct
        cc = self._cc @ self._cc.T if self._cc.ndim == 2 else np.diag(self._cc**2)
        top = np.hstack((l_tt @ l_tt.T, -(b @ l_tt.T).T))
        bottom = np.hstack((-(b @ l_tt.T), b @ b.T + cc))
        return np.asarray(np.vstack((top, bottom)), dtype=np.float64)

    def covariance(self) -> Array:
        """Covariance of the drawn vector, shape (size, size) (the GUM's input covariance)."""
        root = self._root
        return np.asarray(np.kron(self.scalar_covariance(), root @ root.T), dtype=np.float64)

    def _instances(self, values: Array) -> Array:
        """``F_s`` applied over the instance axis 1 of `values` (..., n_t + n_c, m), as drawn."""
        n_t = self._tt.shape[0]
        head, tail = values[:, :n_t], values[:, n_t:]
        e_t = np.einsum("ts,nsm->ntm", self._tt, head, optimize=True)
        e_c = np.einsum("ct,ntm->ncm", self._ct, head, optimize=True)
        if self._cc.ndim == 2:
            e_c = e_c + np.einsum("cs,nsm->ncm", self._cc, tail, optimize=True)
        else:
            e_c = e_c + self._cc[None, :, None] * tail
        return np.asarray(np.concatenate((e_t, -e_c), axis=1), dtype=np.float64)

    def sample(self, rng: np.random.Generator, n: int) -> Array:
        """``n`` draws, shape (n, size): ``(F_s (x) Sigma_m^(1/2)) z`` with one standard normal
        vector ``z`` per draw, consumed in a fixed order."""
        n_t, n_c, d = self._tt.shape[0], self._ct.shape[0], self.dimension
        if self.innovations is None:
            z = rng.standard_normal((int(n), n_t + n_c, d))
        else:
            z = self.innovations[rng.integers(0, self.innovations.shape[0], size=(int(n), n_t + n_c))]
        values = self._instances(z) @ self._root.T
        return np.asarray(values.reshape(int(n), self.size), dtype=np.float64)

    def whitened_sensitivities(self, sensitivities: Array) -> Array:
        """``S (F_s (x) Sigma_m^(1/2))``: sensitivities to the standard normal `z` the draws are
        made of, shape (n_out, size), so ``S Cov S^T`` is their Gram matrix (the GUM's
        propagation without the dense covariance of the draws).

        Parameters
        ----------
        sensitivities : ndarray, shape (n_out, size)
            Derivatives of the outputs by the drawn vector ``(e_t, -e_c)``, pose-major.
        """
        n_out = sensitivities.shape[0]
        n_inst, d = self.size // self.dimension, self.dimension
        per_component = sensitivities.reshape(n_out, n_inst, d) @ self._root  # (o, N, d)
        n_t = self._tt.shape[0]
        head, tail = per_component[:, :n_t], per_component[:, n_t:]
        # (S F)_t = S_t L_tt - S_c B, (S F)_c = -S_c L_cc.
        out_t = np.einsum("ote,ts->ose", head, self._tt, optimize=True) - np.einsum(
            "oce,ct->ote", tail, self._ct, optimize=True
        )
        if self._cc.ndim == 2:
            out_c = -np.einsum("oce,cs->ose", tail, self._cc, optimize=True)
        else:
            out_c = -tail * self._cc[None, :, None]
        return np.asarray(np.concatenate((out_t, out_c), axis=1).reshape(n_out, self.size), dtype=np.float64)
