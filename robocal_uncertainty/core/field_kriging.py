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
parameter): it travels with the calibration's poses and residuals (the calibration file's
``model_error.field``).

:func:`krige` gives it per configuration (blocks of the same conditional covariance), with the
kriging variance widened where the calibration's own held-out folds showed it too narrow
(:mod:`~robocal_uncertainty.core.field_cross_validation`, computed when the calibration file is
written and read back by :func:`kriging_basis`). It lives in ``core`` beside the field's
estimate because the calibration file stores those folds' factors when it is written."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import cho_solve, solve_triangular

from robocal_uncertainty.core.calibration_file import read_session_state
from robocal_uncertainty.core.kinematics import forward_points, forward_points_and_jacobian
from robocal_uncertainty.core.measurement import POINT
from robocal_uncertainty.core.model_error_field import chordal_distance, kernel_correlation
from robocal_uncertainty.core.robot_model import ParameterLayout, RobotModel, rpy_to_matrix
from robocal_uncertainty.errors import ConfigError

__all__ = [
    "FieldCorrection",
    "KrigedPoints",
    "KrigingBasis",
    "field_correction",
    "krige",
    "kriging_basis",
    "parameter_columns",
]

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
    factor_ratios : ndarray, shape (b,)
        Std ratios (:attr:`KrigedPoints.std_ratio` before any factor) at which
        `factor_axes` were measured (empty: the field's covariance as estimated).
    factor_axes : ndarray, shape (b, 3)
        Per-axis (measurement frame) factors >= 1 on the kriging variance there, from the
        calibration's own held-out folds
        (:func:`~robocal_uncertainty.core.field_cross_validation.cross_validated_factors`);
        interpolated in the std ratio, constant beyond the ends.
    factors_source : {"none", "stored", "computed"}
        Where those factors came from: none asked, read from the calibration file, or computed
        now (a file written before they were stored).
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
    factor_ratios: Array = dataclasses.field(default_factory=lambda: np.zeros(0))
    factor_axes: Array = dataclasses.field(default_factory=lambda: np.zeros((0, 3)))
    factors_source: str = "none"


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


def _widened(basis: KrigingBasis, post: Array, prior: Array) -> Array:
    """`post` with each axis's variance scaled by the cross-validated factor at its std ratio."""
    if basis.factor_ratios.size == 0:
        return post
    ratio = np.sqrt(np.clip(np.trace(post, axis1=1, axis2=2), 0.0, None) / np.trace(prior, axis1=1, axis2=2))
    scale = np.sqrt(
        np.stack([np.interp(ratio, basis.factor_ratios, basis.factor_axes[:, a]) for a in range(3)], axis=1)
    )
    return np.asarray(post * scale[:, :, None] * scale[:, None, :], dtype=np.float64)


def parameter_columns(layout: ParameterLayout, names: tuple[str, ...]) -> list[int]:
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
    cols = parameter_columns(layout, basis.gain_names)
    s_m = np.asarray(basis.per_pose_covariance, dtype=np.float64)
    c = basis.correlated_fraction
    corr_tt = _correlation(q_t, q_t, basis) + (1.0 - c) * np.eye(n_t)
    k_tt = np.kron(corr_tt, s_m)
    idx = np.arange(n_t)
    k_tt_blocks = k_tt.reshape(n_t, 3, n_t, 3)
    k_tt_blocks[idx, :, idx, :] += np.asarray(basis.noise, dtype=np.float64)
    _, jac_t = forward_points_and_jacobian(layout, parameters, q_t)
    a_mat = jac_t[:, :, cols].reshape(3 * n_t, len(cols))
    # The contrasts' projector Q (Q^T K Q)^-1 Q^T, with Q orthogonal to the fit's directions U,
    # is K^-1 - K^-1 U (U^T K^-1 U)^-1 U^T K^-1: one Cholesky factor of K and r columns, never
    # the m x m contrasts' covariance (m = 3 n_t - r), a few times faster on large campaigns.
    u_thin, sv, _ = np.linalg.svd(a_mat, full_matrices=False)
    rank = int(np.sum(sv > 1e-10 * sv[0])) if sv.size else 0
    chol = np.linalg.cholesky(k_tt)
    v_mat = solve_triangular(chol, u_thin[:, :rank], lower=True)  # L^-1 U
    chol_m = np.linalg.cholesky(v_mat.T @ v_mat)  # U^T K^-1 U
    y = solve_triangular(chol, np.asarray(basis.residuals, dtype=np.float64).reshape(-1), lower=True)
    alpha = y - v_mat @ cho_solve((chol_m, True), v_mat.T @ y)  # L^-1 ... : X P r = (L^-1 X^T)^T alpha
    gain = np.asarray(basis.gain, dtype=np.float64)
    # Through the fit's gain only k directions of the data reach a prediction: G K_tt G^T and
    # G K_tt are formed once (k x k, k x 3 n_t), never J_c G K_tt per configuration.
    g_k = gain @ k_tt
    g_k_g = g_k @ gain.T
    mean = np.empty((n_c, 3))
    post = np.empty((n_c, 3, 3))
    prior = np.empty((n_c, 3, 3))
    for start in range(0, n_c, chunk):
        q = q_c[start : start + chunk]
        n = q.shape[0]
        _, jac_c = forward_points_and_jacobian(layout, parameters, q)
        j_c = jac_c[:, :, cols].reshape(3 * n, len(cols))
        k_ct = np.kron(_correlation(q, q_t, basis), s_m)
        # Cov(delta_c, data) = K_ct - J G K_tt, whitened: W = L^-1 Cov^T (triangular solve).
        w_mat = solve_triangular(chol, (k_ct - j_c @ g_k).T, lower=True)
        mean[start : start + n] = (w_mat.T @ alpha).reshape(n, 3)
        # Per-configuration blocks of Cov(delta_c) = K_cc - K_ct (J G)^T - J G K_tc + J G K_tt (J G)^T.
        j3 = j_c.reshape(n, 3, len(cols))
        parameters_part = np.einsum("nia,ab,njb->nij", j3, g_k_g, j3)
        cross = np.einsum("nia,nja->nij", (k_ct @ gain.T).reshape(n, 3, len(cols)), j3)
        block = s_m[None] + parameters_part - cross - np.transpose(cross, (0, 2, 1))
        # Explained: X P X^T = W^T W - T^T T with T = chol(U^T K^-1 U)^-1 V^T W.
        w3 = w_mat.T.reshape(n, 3, -1)
        t3 = solve_triangular(chol_m, v_mat.T @ w_mat, lower=True).T.reshape(n, 3, -1)
        explained = np.einsum("nia,nja->nij", w3, w3) - np.einsum("nia,nja->nij", t3, t3)
        prior[start : start + n] = 0.5 * (block + np.transpose(block, (0, 2, 1)))
        post[start : start + n] = _widened(
            basis, prior[start : start + n] - 0.5 * (explained + np.transpose(explained, (0, 2, 1))), block
        )
    return KrigedPoints(mean=mean, covariance=post, prior_covariance=prior, dof=float(basis.dof))


def kriging_basis(
    data: dict[str, Any], model: RobotModel, *, where: str = "calibration", cross_validate: bool = True
) -> KrigingBasis:
    """The correction's inputs from a calibration file (``model_error.field`` with its residuals).

    Parameters
    ----------
    data : dict
        A calibration file (:func:`~robocal_uncertainty.core.calibration_file.read_calibration`).
    model : RobotModel
        The robot with that calibration applied.
    where : str
        Names the file in errors.
    cross_validate : bool
        Widen the kriging variance by the calibration's own held-out folds: the factors the file
        stores (``model_error.field.cross_validation``), or, for a file written before they were
        stored, computed now (:attr:`KrigingBasis.factors_source` says which); False: the
        field's covariance as estimated.

    Raises
    ------
    ConfigError
        The file carries no model-error field, or not its residuals, or stored factors that
        were computed from other poses or residuals than the file's (one line each).
    """
    state = read_session_state(data, where=where)
    me_field = None if state is None else state.model_error_field
    field_data = (data.get("model_error") or {}).get("field") if isinstance(data.get("model_error"), dict) else None
    residuals = None if not isinstance(field_data, dict) else field_data.get("residuals_m")
    if state is None or me_field is None or residuals is None:
        adequacy = data.get("model_error")
        if me_field is None and isinstance(adequacy, dict) and adequacy.get("adequate") is True:
            # A calibration of this version whose kinematic model explains its points: advising a
            # recalibration would send the user round in a circle.
            msg = (
                f"{where}: the calibration found no significant model error (adequacy test p = "
                f"{float(adequacy.get('p_value', float('nan'))):.3g}), so it estimated no field and there is nothing "
                "to correct: leave out --field-correction"
            )
            raise ConfigError(msg)
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
    basis = KrigingBasis(
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
    if not cross_validate:
        return basis
    # The folds' factors sit beside the field (core.field_cross_validation imports this module).
    from robocal_uncertainty.core.field_cross_validation import cross_validated_factors, stored_factors

    stored = stored_factors(field_data, basis, where=where)
    if stored is not None:
        return dataclasses.replace(basis, factor_ratios=stored[0], factor_axes=stored[1], factors_source="stored")
    cross = cross_validated_factors(basis, layout, params)
    return dataclasses.replace(basis, factor_ratios=cross.ratios, factor_axes=cross.factors, factors_source="computed")
