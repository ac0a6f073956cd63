"""The uncertainty of the field's scale, against brute force.

* The effective degrees of freedom of the leave-one-out scale (Satterthwaite under the fitted
  field) against the spread of that scale over many draws of a field, each refitted with every
  pose left out in turn (brute-force least squares, not the hat-matrix identity).
* The draws with an uncertain scale: Student-t marginals (``scipy.stats.t``), their covariance
  against the GUM's, and the GUM's factored sensitivities against that covariance.
* The per-pose covariance varying over the workspace: its posterior on errors drawn with scipy's
  Wishart covariances, and the draws' region against such a mixture.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from robocal_uncertainty.core.model_error_field import chordal_distance, kernel_correlation
from robocal_uncertainty.uncertainty.model_error_draws import (
    SHAPE_TAU,
    FieldEstimate,
    FieldNormal,
    _leave_one_out_dof,
    _shape_posterior,
    _whiten_by_the_others,
)


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


def _wishart_mixture(rng: np.random.Generator, n: int, d: int, k: float) -> np.ndarray:
    """``n`` normal vectors, each with its own covariance ``W ~ Wishart(I / k, k)`` (scipy's)."""
    covs = stats.wishart(df=k, scale=np.eye(d) / k).rvs(size=n, random_state=rng)
    return np.einsum("nij,nj->ni", np.linalg.cholesky(covs), rng.normal(size=(n, d)))


def test_shape_posterior_finds_a_covariance_that_varies_and_none_where_it_does_not() -> None:
    """Errors whose covariance varies from pose to pose (Wishart, k = 6: a kurtosis 1.33 times
    a normal's) put the posterior's mass away from ``tau = 0``; normal errors near it."""
    rng = np.random.default_rng(12)
    n, d = 200, 3
    varying, constant = [], []
    for seed in range(3):
        g = np.random.default_rng(seed)
        varying.append(float(_shape_posterior(_wishart_mixture(g, n, d, 6.0), n, seed) @ SHAPE_TAU))
        constant.append(float(_shape_posterior(g.normal(size=(n, d)), n, seed) @ SHAPE_TAU))
    assert 0.3 < np.median(varying) < 0.8  # tau = d / k = 0.5
    assert np.median(constant) < 0.2  # the uniform prior's mean is 0.5
    # Fewer effective poses (correlated errors) leave the posterior nearer its prior.
    few = _shape_posterior(rng.normal(size=(n, d)), 20.0, 0) @ SHAPE_TAU
    assert few > np.median(constant)
    # The whitened leave-one-out errors: unit covariance under the fitted field.
    # Each error whitened by the covariance of the others (brute force: the other rows' mean outer product).
    heavy = rng.standard_t(5, size=(40, d))
    alone = _whiten_by_the_others(heavy)
    for i in (0, 17):
        others = np.delete(heavy, i, axis=0)
        expected = heavy[i] @ np.linalg.solve(others.T @ others / 39, heavy[i])
        np.testing.assert_allclose(alone[i] @ alone[i], expected, rtol=1e-10)
    m = 80
    fit = np.linalg.svd(rng.normal(size=(m * d, 4)), full_matrices=False)[0]
    white, n_eff = _leave_one_out_dof(rng.normal(size=m * d), fit, 1e-9 * np.eye(m * d), np.eye(m * d), d, np.ones(d))[
        1:
    ]
    assert abs(float(np.mean(white**2)) - 1.0) < 0.2  # 240 squares: sd 0.09
    assert 0.9 * m < n_eff <= m  # independent errors: every pose counts


def test_varying_shape_draws_keep_the_covariance_with_the_mixture_region() -> None:
    """Draws with the shape's posterior all on one ``tau``: the field's covariance, and at a test
    configuration the 95 % region (squared Mahalanobis quantile) of scipy's Wishart mixture;
    with the posterior spread over ``tau`` the mixture over it (the hyperparameter's uncertainty
    drawn, not its posterior mean plugged in)."""
    rng = np.random.default_rng(9)
    q_t = rng.uniform(-2, 2, (8, 6))
    q_c = rng.uniform(-2, 2, (2, 6))
    sigma = np.diag([4.0, 2.0, 1.0]) * 1e-8
    base = {"correlated_fraction": 0.95, "length_scale": 0.8, "per_pose_covariance": sigma}
    normal = FieldNormal(q_t, q_c, FieldEstimate(**base))
    cov = normal.covariance()
    at = np.zeros(SHAPE_TAU.size)
    at[8] = 1.0  # tau = 0.5, k = 6
    # Innovations are ignored: a local covariance does not average out over the poses.
    draw = FieldNormal(q_t, q_c, FieldEstimate(**base, shape_weights=at), innovations=rng.normal(size=(100, 3)))
    samples = draw.sample(np.random.default_rng(2), 80_000)
    np.testing.assert_allclose(draw.covariance(), cov)
    scale = np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
    np.testing.assert_allclose(np.cov(samples.T) / scale, cov / scale, atol=0.03)

    def region(w: np.ndarray) -> float:
        """95 % quantile of the squared norm of whitened vectors over its mean."""
        return float(np.quantile(np.sum(w * w, axis=1) / np.mean(np.sum(w * w, axis=1)), 0.95))

    def white(values: np.ndarray) -> np.ndarray:
        return values[:, -3:] / np.sqrt(np.diag(sigma))

    mixture = _wishart_mixture(np.random.default_rng(4), 80_000, 3, 6.0)
    np.testing.assert_allclose(region(white(samples)), region(mixture), rtol=0.02)
    assert region(mixture) > 1.05 * stats.chi2.ppf(0.95, 3) / 3  # wider than one covariance everywhere
    # Half the posterior at tau = 0, half at tau = 0.5: the region of that mixture, not of tau = 0.25.
    half = np.zeros(SHAPE_TAU.size)
    half[[0, 8]] = 0.5
    spread = FieldNormal(q_t, q_c, FieldEstimate(**base, shape_weights=half)).sample(np.random.default_rng(3), 80_000)
    both = np.concatenate((mixture[:40_000], np.random.default_rng(5).normal(size=(40_000, 3))))
    plugged = _wishart_mixture(np.random.default_rng(6), 80_000, 3, 12.0)
    got = region(white(spread))
    np.testing.assert_allclose(got, region(both), rtol=0.02)
    assert abs(got - region(both)) < abs(region(plugged) - region(both))
