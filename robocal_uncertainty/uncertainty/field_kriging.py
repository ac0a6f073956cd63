"""The model-error field as a correction: its conditional mean at new configurations (kriging).

A calibration's residuals carry what the kinematic model missed at its poses. Where the model
error is a field correlated over the configurations, that information predicts the error at a
nearby configuration: the best linear predictor of the prediction error ``delta_c`` given the
residuals, and the covariance left after it, are Gaussian conditioning,

``E[delta_c | z] = C_dz C_zz^-1 z``, ``Cov(delta_c | z) = C_dd - C_dz C_zz^-1 C_zd``,

with ``z = Q^T r`` the residuals' contrasts (``Q`` orthonormal, orthogonal to the fit's Jacobian
``A``: ``Q^T r = Q^T (e_t + eps_t)`` whatever the parameters, so nothing of the fit is counted
twice) and ``delta_c = e_c - J_c G (e_t + eps_t)`` (``G`` the fit's gain: what the calibration
moved its prediction by). The correction fades to zero far from the calibration poses (``C_dz``
goes with the field's correlation) and cannot be written into a kinematic model (it is not a
parameter): it travels with the calibration's poses and residuals. This module is the
computation; no command applies it yet.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import linalg

from robocal_uncertainty.core.calibration_file import read_session_state
from robocal_uncertainty.core.kinematics import forward_points, forward_points_and_jacobian
from robocal_uncertainty.core.measurement import POINT
from robocal_uncertainty.core.model_error_field import chordal_distance, kernel_correlation
from robocal_uncertainty.core.robot_model import ParameterLayout, RobotModel, rpy_to_matrix
from robocal_uncertainty.errors import ConfigError

__all__ = ["FieldCorrection", "KrigedPoints", "KrigingBasis", "field_correction", "krige", "kriging_basis"]

Array = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class FieldCorrection:
    """The field's conditional mean and covariance at the test configurations.

    Attributes
    ----------
    mean : ndarray, shape (n_c,)
        ``E[delta_c | z]``: what to add to the calibrated predictions (residual coordinates).
    covariance : ndarray, shape (n_c, n_c)
        ``Cov(delta_c | z)``: the prediction error's covariance once corrected (the kriging
        variance; the parameters' own uncertainty through the fit is in it).
    prior_covariance : ndarray, shape (n_c, n_c)
        ``Cov(delta_c)``: the same without the correction.
    """

    mean: Array
    covariance: Array
    prior_covariance: Array


def field_correction(
    fit_jacobian: Array,
    residuals: Array,
    data_covariance: Array,
    cross_covariance: Array,
    test_covariance: Array,
    prediction_gain: Array,
) -> FieldCorrection:
    """Conditional mean and covariance of the prediction error given the calibration's residuals.

    Parameters
    ----------
    fit_jacobian : ndarray, shape (n_t, k)
        ``A``: the fit's Jacobian at the calibration poses (its columns span what the fit absorbs).
    residuals : ndarray, shape (n_t,)
        ``r``: the calibration's residuals (measured minus predicted).
    data_covariance : ndarray, shape (n_t, n_t)
        ``Cov(e_t + eps_t)``: the field and the measurement noise at the calibration poses.
    cross_covariance : ndarray, shape (n_c, n_t)
        ``Cov(e_c, e_t)``: the field between the test configurations and the calibration poses.
    test_covariance : ndarray, shape (n_c, n_c)
        ``Cov(e_c)``: the field at the test configurations.
    prediction_gain : ndarray, shape (n_c, n_t)
        ``J_c G``: the change of the calibrated predictions per error of the calibration data.

    Returns
    -------
    FieldCorrection
    """
    a_mat = np.asarray(fit_jacobian, dtype=np.float64)
    u_full, sv, _ = np.linalg.svd(a_mat, full_matrices=True)
    rank = int(np.sum(sv > 1e-10 * sv[0])) if sv.size else 0
    q_mat = u_full[:, rank:]
    k_tt = np.asarray(data_covariance, dtype=np.float64)
    k_ct = np.asarray(cross_covariance, dtype=np.float64)
    jg = np.asarray(prediction_gain, dtype=np.float64)
    prior = np.asarray(test_covariance, dtype=np.float64) - k_ct @ jg.T - jg @ k_ct.T + jg @ k_tt @ jg.T
    c_zz = q_mat.T @ k_tt @ q_mat
    c_dz = (k_ct - jg @ k_tt) @ q_mat
    gain = np.linalg.solve(c_zz, c_dz.T).T  # C_dz C_zz^-1
    mean = gain @ (q_mat.T @ np.asarray(residuals, dtype=np.float64))
    posterior = prior - gain @ c_dz.T
    return FieldCorrection(
        mean=np.asarray(mean, dtype=np.float64),
        covariance=np.asarray(0.5 * (posterior + posterior.T), dtype=np.float64),
        prior_covariance=np.asarray(0.5 * (prior + prior.T), dtype=np.float64),
    )


@dataclass(frozen=True, eq=False)
class KrigingBasis:
    """What the correction needs of a calibration: its poses, residuals and field (measurement frame).

    Attributes
    ----------
    joint_positions : ndarray, shape (n_t, n_joints) [rad]
        The calibration poses (model joint order).
    residuals : ndarray, shape (n_t, 3) [m]
        Measured minus calibrated points at those poses.
    noise : ndarray, shape (n_t, 3, 3) [m^2]
        Stated noise covariance of each measured point (tracker and encoders).
    per_pose_covariance : ndarray, shape (3, 3) [m^2]
        ``Sigma_m`` of the field (its per-pose covariance).
    correlated_fraction, length_scale : float
        ``c`` and ``l`` [rad] of the field.
    gain_names : tuple of str, length k
        The estimated parameters (what the fit absorbs).
    gain : ndarray, shape (k, 3 n_t)
        The fit's gain: change of those estimates per measured point error at the poses.
    dof : float
        Degrees of freedom of the field's scale estimate: the intervals take Student-t
        quantiles with them (the scale is estimated, not known).
    variance_factor : float
        Factor on the kriging covariance from the calibration's own held-out folds
        (:func:`cross_validated_factor`; 1: the field's covariance as estimated).
    """

    joint_positions: Array
    residuals: Array
    noise: Array
    per_pose_covariance: Array
    correlated_fraction: float
    length_scale: float
    gain_names: tuple[str, ...]
    gain: Array
    dof: float = float("inf")
    variance_factor: float = 1.0


@dataclass(frozen=True, eq=False)
class KrigedPoints:
    """The field's correction at some configurations, per configuration (measurement frame).

    Attributes
    ----------
    mean : ndarray, shape (n, 3) [m]
        What to add to the calibrated points.
    covariance : ndarray, shape (n, 3, 3) [m^2]
        Covariance of the corrected prediction's error (kriging variance: the field's part,
        and through the fit's gain the parameters' part of the field and the noise).
    prior_covariance : ndarray, shape (n, 3, 3) [m^2]
        The same for the uncorrected prediction.
    dof : float
        Degrees of freedom of the scale (Student-t intervals).
    """

    mean: Array
    covariance: Array
    prior_covariance: Array
    dof: float

    @property
    def std_ratio(self) -> Array:
        """``sqrt(tr Cov / tr prior Cov)`` per configuration, shape (n,): 0 at a calibration pose
        with no noise, 1 far from all of them (the correction knows nothing there)."""
        post = np.trace(self.covariance, axis1=1, axis2=2)
        prior = np.trace(self.prior_covariance, axis1=1, axis2=2)
        return np.asarray(np.sqrt(np.clip(post, 0.0, None) / np.where(prior > 0, prior, 1.0)), dtype=np.float64)

    def coverage_factor(self, probability: float = 0.95) -> float:
        """Two-sided per-axis coverage factor: the Student-t quantile with :attr:`dof`."""
        from scipy import stats

        tail = 0.5 + 0.5 * probability
        return float(stats.norm.ppf(tail) if not np.isfinite(self.dof) else stats.t.ppf(tail, self.dof))


def _correlation(q_a: Array, q_b: Array, basis: KrigingBasis) -> Array:
    return basis.correlated_fraction * kernel_correlation(chordal_distance(q_a, q_b), basis.length_scale)


def _parameter_columns(layout: ParameterLayout, names: tuple[str, ...]) -> list[int]:
    index = {n: i for i, n in enumerate(layout.names)}
    missing = [n for n in names if n not in index]
    if missing:
        msg = f"the field's gain names parameters the model does not have: {', '.join(missing[:3])}"
        raise ConfigError(msg)
    return [index[n] for n in names]


def krige(
    basis: KrigingBasis, layout: ParameterLayout, parameters: Array, joint_positions: Array, *, chunk: int = 256
) -> KrigedPoints:
    """The field's conditional mean and per-configuration covariance at `joint_positions`.

    :func:`field_correction` per configuration block (the full cross-configuration covariance
    is never formed, so a map of thousands of configurations stays linear in their number).

    Parameters
    ----------
    basis : KrigingBasis
    layout : ParameterLayout
    parameters : ndarray, shape (n_params,) [m, rad]
        The calibrated parameter vector.
    joint_positions : ndarray, shape (n, n_joints) [rad]
    chunk : int
        Configurations per block (memory ``~ 9 n_t chunk`` floats).
    """
    q_t = np.asarray(basis.joint_positions, dtype=np.float64)
    q_c = np.atleast_2d(np.asarray(joint_positions, dtype=np.float64))
    n_t, n_c = q_t.shape[0], q_c.shape[0]
    cols = _parameter_columns(layout, basis.gain_names)
    s_m = np.asarray(basis.per_pose_covariance, dtype=np.float64)
    c = basis.correlated_fraction
    corr_tt = _correlation(q_t, q_t, basis) + (1.0 - c) * np.eye(n_t)
    k_tt = np.kron(corr_tt, s_m)
    idx = np.arange(n_t)
    k_tt_blocks = k_tt.reshape(n_t, 3, n_t, 3)
    k_tt_blocks[idx, :, idx, :] += np.asarray(basis.noise, dtype=np.float64)
    _, jac_t = forward_points_and_jacobian(layout, parameters, q_t)
    a_mat = jac_t[:, :, cols].reshape(3 * n_t, len(cols))
    u_full, sv, _ = np.linalg.svd(a_mat, full_matrices=True)
    rank = int(np.sum(sv > 1e-10 * sv[0])) if sv.size else 0
    q_mat = u_full[:, rank:]
    k_tt_q = k_tt @ q_mat
    chol = np.linalg.cholesky(q_mat.T @ k_tt_q)
    z = q_mat.T @ np.asarray(basis.residuals, dtype=np.float64).reshape(-1)
    alpha = np.linalg.solve(chol.T, np.linalg.solve(chol, z))
    gain = np.asarray(basis.gain, dtype=np.float64)
    # Through the fit's gain only k directions of the data reach a prediction: G K_tt G^T and
    # G K_tt Q are formed once (k x k, k x m), never J_c G K_tt per configuration.
    g_k_g = gain @ k_tt @ gain.T
    g_k_q = gain @ k_tt_q
    mean = np.empty((n_c, 3))
    post = np.empty((n_c, 3, 3))
    prior = np.empty((n_c, 3, 3))
    for start in range(0, n_c, chunk):
        q = q_c[start : start + chunk]
        n = q.shape[0]
        _, jac_c = forward_points_and_jacobian(layout, parameters, q)
        j_c = jac_c[:, :, cols].reshape(3 * n, len(cols))
        k_ct = np.kron(_correlation(q, q_t, basis), s_m)
        c_dz = k_ct @ q_mat - j_c @ g_k_q  # Cov(delta_c, z)
        mean[start : start + n] = (c_dz @ alpha).reshape(n, 3)
        # Per-configuration blocks of Cov(delta_c) = K_cc - K_ct (J G)^T - J G K_tc + J G K_tt (J G)^T.
        j3 = j_c.reshape(n, 3, len(cols))
        parameters_part = np.einsum("nia,ab,njb->nij", j3, g_k_g, j3)
        cross = np.einsum("nia,nja->nij", (k_ct @ gain.T).reshape(n, 3, len(cols)), j3)
        block = s_m[None] + parameters_part - cross - np.transpose(cross, (0, 2, 1))
        w3 = np.linalg.solve(chol, c_dz.T).T.reshape(n, 3, -1)
        explained = np.einsum("nia,nja->nij", w3, w3)
        prior[start : start + n] = 0.5 * (block + np.transpose(block, (0, 2, 1)))
        post[start : start + n] = basis.variance_factor * (
            prior[start : start + n] - 0.5 * (explained + np.transpose(explained, (0, 2, 1)))
        )
    return KrigedPoints(mean=mean, covariance=post, prior_covariance=prior, dof=float(basis.dof))


def kriging_basis(data: dict[str, Any], model: RobotModel, *, where: str = "calibration") -> KrigingBasis:
    """The correction's inputs from a calibration file (``model_error.field`` with its residuals).

    Parameters
    ----------
    data : dict
        A calibration file (:func:`~robocal_uncertainty.core.calibration_file.read_calibration`).
    model : RobotModel
        The robot with that calibration applied.
    where : str
        Names the file in errors.

    Raises
    ------
    ConfigError
        The file carries no model-error field, or not its residuals (one line).
    """
    state = read_session_state(data, where=where)
    me_field = None if state is None else state.model_error_field
    field_data = (data.get("model_error") or {}).get("field") if isinstance(data.get("model_error"), dict) else None
    residuals = None if not isinstance(field_data, dict) else field_data.get("residuals_m")
    if state is None or me_field is None or residuals is None:
        what = "no model-error field (model_error.field)" if me_field is None else "the field without its residuals"
        msg = (
            f"{where} carries {what}, so there is no correction to apply: recalibrate with this version "
            "('calibrate --json'; a field is estimated when the model error is significant)"
        )
        raise ConfigError(msg)
    q_t = me_field.joint_positions
    try:
        r = np.asarray(residuals, dtype=np.float64)
    except (TypeError, ValueError) as err:
        msg = f"{where}: model_error.field.residuals_m is not a numeric n x 3 array"
        raise ConfigError(msg) from err
    if r.shape != (q_t.shape[0], 3) or not np.isfinite(r).all():
        msg = f"{where}: model_error.field.residuals_m must be {q_t.shape[0]} x 3 finite values [m], got {r.shape}"
        raise ConfigError(msg)
    layout = model.layout
    params = model.parameter_vector()
    b0 = layout.base_index
    r_wb = rpy_to_matrix(params[b0 + 3 : b0 + 6]) if state.frame == "tracker" else np.eye(3)
    predicted = forward_points(layout, params, q_t)
    distances = np.linalg.norm(predicted + r, axis=1) if state.frame == "tracker" else np.full(q_t.shape[0], 2.0)
    jq = POINT.joint_jacobian(layout, params, q_t)
    noise = state.encoder_noise.covariance(jq, model.prismatic) + POINT.instrument_covariance(
        state.tracker_noise.std(distances)
    )
    rotate = np.kron(np.eye(q_t.shape[0]), r_wb)
    return KrigingBasis(
        joint_positions=q_t,
        residuals=r,
        noise=np.asarray(noise, dtype=np.float64),
        per_pose_covariance=r_wb @ state.model_error_covariance @ r_wb.T,
        correlated_fraction=me_field.correlated_fraction,
        length_scale=me_field.length_scale,
        gain_names=me_field.gain_names,
        gain=me_field.gain @ rotate.T,
        dof=me_field.dof,
    )


def leave_one_out_factor(basis: KrigingBasis, layout: ParameterLayout, parameters: Array) -> tuple[float, Array]:
    """How far the field's own predictions of left-out calibration poses exceed their stated variance.

    Leaving pose ``i`` out and refitting (generalised least squares over the field and noise
    covariance ``C``) predicts its residual with error ``e_i = P_ii^-1 (P r)_i`` and covariance
    ``P_ii^-1``, ``P = C^-1 - C^-1 A (A^T C^-1 A)^-1 A^T C^-1`` (``A`` the fit's Jacobian; the
    closed form of universal kriging's leave-one-out, no refit run). The mean of
    ``e_i^T P_ii e_i / 3`` is 1 when the field's covariance is right at the distances between
    neighbouring poses; a kernel smoother than the error (or a correlated fraction of 1 where
    part of the error is independent) shows as more.

    Returns
    -------
    (float, ndarray of shape (n_t,))
        The factor and each pose's ``e_i^T P_ii e_i / 3``.
    """
    q_t = np.asarray(basis.joint_positions, dtype=np.float64)
    n_t = q_t.shape[0]
    cols = _parameter_columns(layout, basis.gain_names)
    c = basis.correlated_fraction
    k_tt = np.kron(_correlation(q_t, q_t, basis) + (1.0 - c) * np.eye(n_t), basis.per_pose_covariance)
    idx = np.arange(n_t)
    k_tt.reshape(n_t, 3, n_t, 3)[idx, :, idx, :] += np.asarray(basis.noise, dtype=np.float64)
    _, jac_t = forward_points_and_jacobian(layout, parameters, q_t)
    a_mat = jac_t[:, :, cols].reshape(3 * n_t, len(cols))
    u_a, sv, _ = np.linalg.svd(a_mat, full_matrices=False)
    a_mat = u_a[:, : int(np.sum(sv > 1e-10 * sv[0]))]  # an orthonormal basis of the same span
    chol = linalg.cho_factor(k_tt, lower=True)
    ci_a = linalg.cho_solve(chol, a_mat)
    ci_r = linalg.cho_solve(chol, np.asarray(basis.residuals, dtype=np.float64).reshape(-1))
    p_r = ci_r - ci_a @ np.linalg.solve(a_mat.T @ ci_a, ci_a.T @ np.asarray(basis.residuals).reshape(-1))
    ci_blocks = linalg.cho_solve(chol, np.eye(3 * n_t)).reshape(n_t, 3, n_t, 3)[idx, :, idx, :]
    m_inv = np.linalg.inv(a_mat.T @ ci_a)
    ci_a3 = ci_a.reshape(n_t, 3, -1)
    p_blocks = ci_blocks - np.einsum("nia,ab,njb->nij", ci_a3, m_inv, ci_a3)
    p_r3 = p_r.reshape(n_t, 3)
    each = np.einsum("ni,ni->n", p_r3, np.linalg.solve(p_blocks, p_r3[..., None])[..., 0]) / 3.0
    return float(np.mean(each)), np.asarray(each, dtype=np.float64)


CROSS_VALIDATION_FOLDS = 5
"""Folds of :func:`cross_validated_factor`."""


def cross_validated_factor(
    basis: KrigingBasis,
    layout: ParameterLayout,
    parameters: Array,
    *,
    folds: int = CROSS_VALIDATION_FOLDS,
    seed: int = 0,
) -> tuple[float, Array]:
    """How far the correction's errors on the calibration's own held-out folds exceed their stated variance.

    The poses are split into `folds` seeded folds; for each, the parameters are refitted
    (linearised, least squares) on the other poses, the field corrects the fold's residuals
    from theirs (:func:`krige`, the same computation as for a new configuration) and each
    fold pose gives ``m_i = e_i^T (Cov_i + N_i)^-1 e_i / 3`` (``e_i`` the corrected error,
    ``Cov_i`` its kriging covariance, ``N_i`` the pose's noise). The mean of ``m_i`` is 1 when
    the field's covariance is right at the distances a new configuration has from the
    calibration poses; on real series it is not (an exponential kernel fitted to repeated
    poses is too confident a few tenths of a radian away), so the statement scales the
    kriging covariance by it.

    Returns
    -------
    (float, ndarray of shape (n_t,))
        The mean of ``m_i`` and each pose's ``m_i``.
    """
    q_t = np.asarray(basis.joint_positions, dtype=np.float64)
    n_t = q_t.shape[0]
    r = np.asarray(basis.residuals, dtype=np.float64)
    noise = np.asarray(basis.noise, dtype=np.float64)
    cols = _parameter_columns(layout, basis.gain_names)
    _, jac_t = forward_points_and_jacobian(layout, parameters, q_t)
    jac = jac_t[:, :, cols]
    fold_of = np.random.default_rng(np.random.SeedSequence([int(seed), n_t])).permutation(n_t) % max(int(folds), 2)
    each = np.empty(n_t)
    for f in range(max(int(folds), 2)):
        out, rest = np.flatnonzero(fold_of == f), np.flatnonzero(fold_of != f)
        a_rest = jac[rest].reshape(3 * rest.size, len(cols))
        gain_rest = np.linalg.pinv(a_rest, rcond=1e-10)
        delta = gain_rest @ r[rest].reshape(-1)
        refit_rest = r[rest] - (a_rest @ delta).reshape(-1, 3)
        refit_out = r[out] - np.einsum("nik,k->ni", jac[out], delta)
        sub = dataclasses.replace(
            basis,
            joint_positions=q_t[rest],
            residuals=refit_rest,
            noise=noise[rest],
            gain=gain_rest,
            variance_factor=1.0,
        )
        kriged = krige(sub, layout, parameters, q_t[out])
        err = refit_out - kriged.mean
        cov = kriged.covariance + noise[out]
        each[out] = np.einsum("ni,ni->n", err, np.linalg.solve(cov, err[..., None])[..., 0]) / 3.0
    return float(np.mean(each)), each
