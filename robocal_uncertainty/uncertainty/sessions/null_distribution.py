"""The check statistic's distribution when nothing changed: Monte Carlo draws of the stated errors.

With uniform tracker and encoder errors, a model error resampled from its draws and estimated
parts scaled by ``sqrt(nu / chi2_nu)``, the statistic has other tails than a chi-square, whose
p-value would be wrong; the draws give the p-value instead.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import linalg

from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.errors import ConfigError

__all__ = ["NullNoise", "chol_factor", "gls_chi2", "null_statistics", "sqrt_psd"]

Array = NDArray[np.float64]
_NULL_BLOCK = 4096


def sqrt_psd(matrix: Array) -> Array:
    evals, evecs = np.linalg.eigh(matrix)
    return np.asarray(evecs * np.sqrt(np.clip(evals, 0.0, None)), dtype=np.float64)


def chol_factor(matrix: Array) -> Array:
    return np.asarray(np.linalg.cholesky(matrix), dtype=np.float64)


def gls_chi2(r: Array, chol: Array, a_mat: Array) -> float:
    """``r^T C^-1 r`` minus the part the re-registration columns explain (C = chol chol^T)."""
    rw = linalg.solve_triangular(chol, r, lower=True)
    if a_mat.shape[1] == 0:
        return float(rw @ rw)
    aw = linalg.solve_triangular(chol, a_mat, lower=True)
    q, _ = np.linalg.qr(aw)
    rw = rw - q @ (q.T @ rw)
    return float(rw @ rw)


@dataclass(frozen=True)
class NullNoise:
    """The measurement noise of the check campaign's ``n`` poses, drawn for every null trial.

    Attributes
    ----------
    distances : ndarray, shape (n,)
        Tracker-to-target distance of each pose, m (the tracker noise grows with it).
    tracker : TrackerNoise
        The laser tracker's stated errors.
    encoder : EncoderNoise
        The joint encoders' stated errors.
    joint_jacobian : ndarray, shape (n, 3, n_joints)
        Target position per joint reading at each pose, m/rad (m/m for a prismatic joint).
    prismatic : tuple of bool
        Which joints are prismatic (their encoder noise is a length); empty: none.
    """

    distances: Array
    tracker: TrackerNoise
    encoder: EncoderNoise
    joint_jacobian: Array
    prismatic: tuple[bool, ...] = ()


def null_statistics(
    trials: int,
    seed: int,
    chol: Array,
    a_mat: Array,
    noise: NullNoise,
    *,
    model_error: Array,
    kin_jacobian: Array,
    kin_covariance: Array,
    model_error_draws: Array | None = None,
    model_error_dof: float | None = None,
    between_factor: Array | None = None,
    between_dof: float | None = None,
    correlated_factor: Array | None = None,
    correlated_dof: float | None = None,
) -> Array:
    """The check statistic for `trials` draws of the errors "nothing changed" allows, shape (trials,).

    Blocks of :data:`_NULL_BLOCK` draws, each from its own ``SeedSequence(seed).spawn`` child:
    the draws do not depend on anything but the seed and the count. `noise` is the tracker and
    encoder noise of the poses; the model error, parameter and between-session parts are
    keyword-only so that two matrices of one shape cannot be swapped. `correlated_factor`
    (``F F^T`` = covariance over all the poses of a correlated model error and the parameter
    errors, shape (3 n, r)) is drawn normal and scaled by ``sqrt(nu / chi2_nu)`` per draw with
    ``nu`` = `correlated_dof`.
    """
    if isinstance(trials, bool) or not isinstance(trials, int) or trials < 100:
        msg = f"null_trials must be an integer >= 100, got {trials!r}"
        raise ConfigError(msg)
    distances, tracker, encoder, joint_jacobian = noise.distances, noise.tracker, noise.encoder, noise.joint_jacobian
    prismatic = noise.prismatic
    n = distances.size
    n_joints = joint_jacobian.shape[-1]
    if a_mat.shape[1]:
        aw = linalg.solve_triangular(chol, a_mat, lower=True)
        q_mat, _ = np.linalg.qr(aw)
    else:
        q_mat = np.zeros((3 * n, 0))
    me_sqrt = np.linalg.cholesky(model_error + 1e-30 * np.eye(3)) if np.any(model_error) else None
    k_sqrt = None
    if kin_jacobian.shape[1]:
        evals, evecs = np.linalg.eigh(kin_covariance)
        k_sqrt = kin_jacobian @ (evecs * np.sqrt(np.clip(evals, 0.0, None)))
    n_blocks = -(-trials // _NULL_BLOCK)
    out = np.empty(trials)
    for b, child in enumerate(np.random.SeedSequence(seed).spawn(n_blocks)):
        rng = np.random.default_rng(child)
        m = min(_NULL_BLOCK, trials - b * _NULL_BLOCK)
        e = tracker.sample(rng, np.broadcast_to(distances, (m, n)))
        dq = encoder.sample_joints(rng, (m, n, n_joints), prismatic)
        e = e + np.einsum("pij,tpj->tpi", joint_jacobian, dq)
        me = None
        if model_error_draws is not None and model_error_draws.shape[0]:
            me = model_error_draws[rng.integers(0, model_error_draws.shape[0], size=(m, n))]
        elif me_sqrt is not None:
            me = rng.standard_normal((m, n, 3)) @ me_sqrt.T
        if me is not None:
            if model_error_dof is not None and np.isfinite(model_error_dof):
                me = me * np.sqrt(model_error_dof / rng.chisquare(model_error_dof, size=m))[:, None, None]
            e = e + me
        flat = e.reshape(m, 3 * n)
        if between_factor is not None:
            shift = rng.standard_normal((m, between_factor.shape[1])) @ between_factor.T
            if between_dof is not None and np.isfinite(between_dof):
                shift = shift * np.sqrt(between_dof / rng.chisquare(between_dof, size=m))[:, None]
            flat = flat + shift
        if k_sqrt is not None:
            flat = flat + rng.standard_normal((m, k_sqrt.shape[1])) @ k_sqrt.T
        if correlated_factor is not None:
            shift = rng.standard_normal((m, correlated_factor.shape[1])) @ correlated_factor.T
            if correlated_dof is not None and np.isfinite(correlated_dof):
                shift = shift * np.sqrt(correlated_dof / rng.chisquare(correlated_dof, size=m))[:, None]
            flat = flat + shift
        w = linalg.solve_triangular(chol, flat.T, lower=True)
        w = w - q_mat @ (q_mat.T @ w)
        out[b * _NULL_BLOCK : b * _NULL_BLOCK + m] = np.sum(w * w, axis=0)
    return out
