"""The field's conditional mean and covariance (kriging) against a dense brute-force draw.

Independent reference: draws of the field at the calibration poses and the test configurations
(one dense Cholesky factor of the kernel), measurement noise, the actual least-squares fit's
residuals and prediction errors; the empirical regression of the prediction error on the
residuals and the scatter left around it must be the function's conditional mean and covariance.
"""

from __future__ import annotations

import numpy as np

from robocal_uncertainty.core.model_error_field import chordal_distance, kernel_correlation
from robocal_uncertainty.uncertainty.field_kriging import field_correction


def _kernel(q_a: np.ndarray, q_b: np.ndarray, c: float, ell: float, s2: float, same: bool) -> np.ndarray:
    corr = c * kernel_correlation(chordal_distance(q_a, q_b), ell)
    return s2 * (corr + (1.0 - c) * np.eye(q_a.shape[0]) if same else corr)


def test_conditional_mean_and_covariance_match_a_brute_force_draw_of_the_field() -> None:
    rng = np.random.default_rng(29)
    n_t, n_c, k = 14, 3, 3
    q_t = rng.uniform(-0.6, 0.6, size=(n_t, 6))
    # Two test configurations near calibration poses, one far from all of them.
    q_c = np.vstack((q_t[:2] + rng.normal(0.0, 0.05, size=(2, 6)), np.full((1, 6), 2.5)))
    c, ell, s2, noise = 0.8, 0.6, 1.0, 0.05
    q_all = np.vstack((q_t, q_c))
    joint = _kernel(q_all, q_all, c, ell, s2, True)
    a_mat = rng.normal(size=(n_t, k))
    gain = np.linalg.solve(a_mat.T @ a_mat, a_mat.T)  # least squares
    j_c = rng.normal(size=(n_c, k))
    jg = j_c @ gain

    m = 200_000
    e = rng.standard_normal((m, n_t + n_c)) @ np.linalg.cholesky(joint).T
    y = e[:, :n_t] + np.sqrt(noise) * rng.standard_normal((m, n_t))
    residuals = y - y @ (a_mat @ gain).T  # the fit's residuals, draw by draw
    delta = e[:, n_t:] - y @ jg.T  # the calibrated prediction's error at q_c
    coef, *_ = np.linalg.lstsq(residuals, delta, rcond=None)
    scatter = np.cov((delta - residuals @ coef).T)

    r0 = residuals[0]
    out = field_correction(
        a_mat,
        r0,
        joint[:n_t, :n_t] + noise * np.eye(n_t),
        joint[n_t:, :n_t],
        joint[n_t:, n_t:],
        jg,
    )
    sd = np.sqrt(np.diag(out.prior_covariance))
    np.testing.assert_allclose(out.prior_covariance, np.cov(delta.T), rtol=0.02, atol=0.01 * sd.max() ** 2)
    np.testing.assert_allclose(out.covariance, scatter, rtol=0.02, atol=0.01 * sd.max() ** 2)
    np.testing.assert_allclose(out.mean, r0 @ coef, atol=0.02 * sd.max())
    # Near the calibration poses the residuals explain part of the error (measured 21 and 35 %
    # of its variance), far from them almost nothing (0.3 %): the correction fades.
    shrink = np.diag(out.covariance) / np.diag(out.prior_covariance)
    assert np.all(shrink[:2] < 0.9)
    assert shrink[2] > 0.98
