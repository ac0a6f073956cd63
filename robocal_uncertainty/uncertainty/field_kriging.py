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

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["FieldCorrection", "field_correction"]

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
