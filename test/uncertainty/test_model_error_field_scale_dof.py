"""The uncertainty of the field's scale, against brute force.

* The effective degrees of freedom of the leave-one-out scale (Satterthwaite under the fitted
  field) against the spread of that scale over many draws of a field, each refitted with every
  pose left out in turn (brute-force least squares, not the hat-matrix identity).
* The draws with an uncertain scale: Student-t marginals (``scipy.stats.t``), their covariance
  against the GUM's, and the GUM's factored sensitivities against that covariance.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from robocal_uncertainty.core.model_error_field import chordal_distance, kernel_correlation
from robocal_uncertainty.uncertainty.model_error_draws import FieldEstimate, FieldNormal, _leave_one_out_dof


def test_leave_one_out_dof_matches_the_spread_of_brute_force_refits() -> None:
    rng = np.random.default_rng(29)
    n, d, k = 30, 3, 8
    q = rng.uniform(-1.5, 1.5, (n, 6))
    design = rng.normal(size=(n * d, k))
    fit = np.linalg.svd(design, full_matrices=False)[0]
    corr = 0.8 * kernel_correlation(chordal_distance(q, q), 1.0) + 0.2 * np.eye(n)
    shape = np.array([[1.0, 0.3, 0.0], [0.3, 1.5, 0.2], [0.0, 0.2, 0.8]])
    unit = np.kron(corr, shape)
    noise = 0.05 * np.eye(n * d)
    factors = np.array([1.0, 0.7, 1.3])
    total = noise + unit * np.outer(np.tile(factors, n), np.tile(factors, n))
    nu = _leave_one_out_dof(np.zeros(n * d), fit, noise, unit, d, factors, heavy_tails=False)[0]
    # Brute force: the prediction error of pose i by the least-squares fit of the others.
    draws = rng.multivariate_normal(np.zeros(n * d), total, size=6000).reshape(-1, n, d)
    loo = np.empty_like(draws)
    rows = np.arange(n * d).reshape(n, d)
    for i in range(n):
        keep = np.delete(rows, i, axis=0).reshape(-1)
        beta = np.linalg.lstsq(design[keep], draws.reshape(-1, n * d)[:, keep].T, rcond=None)[0]
        loo[:, i] = draws[:, i] - (design[rows[i]] @ beta).T
    z2 = loo**2 / np.var(loo, axis=0)  # standardised by their own spread
    scale = np.mean(z2, axis=1)  # each component's mean square, per draw
    empirical = 2.0 * np.mean(scale, axis=0) ** 2 / np.var(scale, axis=0)
    assert np.all(nu < n)  # the correlated errors are seen by fewer independent patches
    np.testing.assert_allclose(nu, empirical, rtol=0.1)


def test_heavy_tails_lower_the_degrees_of_freedom() -> None:
    rng = np.random.default_rng(3)
    n, d = 200, 1
    fit = np.linalg.svd(rng.normal(size=(n, 2)), full_matrices=False)[0]
    unit, noise = np.eye(n), 1e-6 * np.eye(n)
    normal = _leave_one_out_dof(rng.normal(size=n), fit, noise, unit, d, np.ones(1))[0]
    heavy = _leave_one_out_dof(rng.standard_t(5, size=n), fit, noise, unit, d, np.ones(1))[0]
    gaussian = _leave_one_out_dof(rng.normal(size=n), fit, noise, unit, d, np.ones(1), heavy_tails=False)[0]
    assert 0.6 * gaussian[0] < normal[0] <= gaussian[0]
    assert heavy[0] < 0.6 * gaussian[0]  # t_5: kurtosis 9, factor 1/4 in expectation


def test_uncertain_scale_draws_student_t_with_the_gum_covariance() -> None:
    rng = np.random.default_rng(7)
    q_t = rng.uniform(-2, 2, (6, 6))
    q_c = np.concatenate((q_t[:1] + 0.05, rng.uniform(-2, 2, (1, 6))))
    sigma = np.array([[4.0, 1.0, 0.0], [1.0, 2.0, 0.0], [0.0, 0.0, 1.0]]) * 1e-8
    dof = np.array([5.0, 12.0, 1e9])
    est = FieldEstimate(correlated_fraction=0.8, length_scale=0.5, per_pose_covariance=sigma, scale_dof=dof)
    known = FieldNormal(q_t, q_c, FieldEstimate(correlated_fraction=0.8, length_scale=0.5, per_pose_covariance=sigma))
    draw = FieldNormal(q_t, q_c, est)
    samples = draw.sample(np.random.default_rng(11), 400_000)
    sd = np.sqrt(np.diag(known.covariance()))
    for j, nu in enumerate(dof):
        z = samples[:, -3 + j] / sd[-3 + j]  # the far test configuration, component j
        for p in (0.9, 0.975, 0.995):
            np.testing.assert_allclose(np.quantile(z, p), stats.t.ppf(p, nu), rtol=0.03)
    cov = draw.covariance()
    scale = np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
    np.testing.assert_allclose(np.cov(samples.T) / scale, cov / scale, atol=0.02)
    np.testing.assert_allclose(np.diag(cov)[-3:] / np.diag(known.covariance())[-3:], dof / (dof - 2), rtol=1e-6)
    sens = rng.normal(size=(4, draw.size))
    white = draw.whitened_sensitivities(sens)
    np.testing.assert_allclose(white @ white.T, sens @ cov @ sens.T, rtol=1e-6)


def test_tail_dof_from_the_kurtosis_of_the_prediction_errors() -> None:
    """Multivariate t errors (a scale mixture of normals) give back about their degrees of
    freedom; normal errors give normal tails (infinite, or far beyond the t's range)."""
    rng = np.random.default_rng(8)
    n, d = 400, 3
    fit = np.linalg.svd(rng.normal(size=(n * d, 4)), full_matrices=False)[0]
    unit, noise = np.eye(n * d), 1e-9 * np.eye(n * d)
    tails = []
    for seed in range(6):
        g = np.random.default_rng(seed)
        mix = np.sqrt(6.0 / g.chisquare(6.0, size=(n, 1)))
        tails.append(_leave_one_out_dof((g.normal(size=(n, d)) * mix).reshape(-1), fit, noise, unit, d, np.ones(d))[1])
        gauss = _leave_one_out_dof(g.normal(size=n * d), fit, noise, unit, d, np.ones(d))[1]
        assert gauss > 30.0
    assert 4.5 < np.median(tails) < 10.0  # t_6; a sample kurtosis of t_6 is biased low and wide


def test_t_process_draws_keep_the_covariance_with_t_marginals() -> None:
    rng = np.random.default_rng(9)
    q_t = rng.uniform(-2, 2, (30, 6))
    q_c = rng.uniform(-2, 2, (2, 6))
    sigma = np.diag([4.0, 2.0, 1.0]) * 1e-8
    est = FieldEstimate(correlated_fraction=0.95, length_scale=0.8, per_pose_covariance=sigma, tail_dof=7.0)
    normal = FieldNormal(q_t, q_c, FieldEstimate(correlated_fraction=0.95, length_scale=0.8, per_pose_covariance=sigma))
    # Innovations are ignored for a t-process: its tails do not average out over the poses.
    draw = FieldNormal(q_t, q_c, est, innovations=rng.normal(size=(100, 3)))
    samples = draw.sample(np.random.default_rng(2), 300_000)
    cov = normal.covariance()
    np.testing.assert_allclose(draw.covariance(), cov)
    scale = np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
    np.testing.assert_allclose(np.cov(samples.T) / scale, cov / scale, atol=0.03)
    z = samples[:, -1] / np.sqrt(cov[-1, -1])
    for p in (0.9, 0.975, 0.995):
        np.testing.assert_allclose(np.quantile(z, p), stats.t.ppf(p, 7.0) * np.sqrt(5.0 / 7.0), rtol=0.03)
