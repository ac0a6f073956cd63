"""The field's correlation drawn from its posterior, and the scales' common error, against
independent references.

* The posterior of ``(c, l)`` on its grid (restricted likelihood, ``log s`` integrated out by
  Laplace's method) against a brute-force one: the contrasts' density from ``scipy.stats``
  with an explicit null-space basis, integrated over a fine grid of ``log s``.
* The mixture's draws: their covariance the weighted sum of each hypothesis's field (sampled,
  and the GUM's factored sensitivities against it).
* The correlation of the components' scale estimates against its analytic value for errors
  with a common local scale, and near zero for normal errors; the correlated scale factors keep
  their Student-t marginals.
"""

from __future__ import annotations

import numpy as np
from scipy import linalg, stats

from robocal_uncertainty.core.model_error_field import chordal_distance, kernel_correlation
from robocal_uncertainty.uncertainty.model_error_draws import (
    HYPER_DRAWS,
    HYPER_LENGTHS,
    FieldEstimate,
    FieldHypothesis,
    FieldNormal,
    _FieldSystem,
    _hyper_grid_posterior,
    _hyper_posterior,
    _scale_correlation,
)


def _system(seed: int, n: int = 12, d: int = 2, c: float = 0.8, ell: float = 0.7) -> _FieldSystem:
    rng = np.random.default_rng(seed)
    q = rng.uniform(-1.5, 1.5, (n, 6))
    dist = chordal_distance(q, q)
    corr = c * kernel_correlation(dist, ell) + (1.0 - c) * np.eye(n)
    shape = np.eye(d)
    cov = np.kron(corr, shape) + 0.05 * np.eye(n * d)
    fit = np.linalg.qr(rng.normal(size=(n * d, 4)))[0]
    r = np.linalg.cholesky(cov) @ rng.normal(size=n * d)
    return _FieldSystem(
        residuals=r,
        fit=fit,
        noise=0.05 * np.eye(n * d),
        white=np.kron(np.eye(n), shape),
        kron_ones=np.kron(np.ones((n, n)), shape),
        distance=dist,
        shape=shape,
        dimension=d,
    )


def _brute_force_posterior(system: _FieldSystem, grid: list[tuple[float, float]]) -> np.ndarray:
    q_null = linalg.null_space(system.fit.T)
    y = q_null.T @ system.residuals
    log_s = np.linspace(np.log(1e-3), np.log(1e2), 120)
    out = np.empty(len(grid))
    for g, (c, ell) in enumerate(grid):
        rho = kernel_correlation(system.distance, ell)
        unit = np.kron(c * rho + (1.0 - c) * np.eye(system.poses), system.shape)
        dens = [
            stats.multivariate_normal(cov=q_null.T @ (system.noise + np.exp(a) * unit) @ q_null).logpdf(y)
            for a in log_s
        ]
        out[g] = np.logaddexp.reduce(dens) + np.log(log_s[1] - log_s[0])
    post = np.exp(out - out.max())
    return post / post.sum()


def test_correlation_posterior_matches_a_brute_force_integral() -> None:
    system = _system(3)
    grid, post, _ = _hyper_grid_posterior(system, 0.0)
    brute = _brute_force_posterior(system, grid)
    assert abs(post.sum() - 1.0) < 1e-12
    assert np.max(np.abs(post - brute)) < 0.01 * brute.max()  # Laplace's method against the quadrature
    assert post[np.argmax(brute)] > 0.5 * brute.max()
    hyp = _hyper_posterior(system, 0.0, seed=5)
    assert abs(sum(h[0] for h in hyp) - 1.0) < 1e-12 and 1 <= len(hyp) <= 8
    mean_log_l = sum(w * np.log(ell) for w, _, ell, _ in hyp)
    exact = float(post @ np.log([g[1] for g in grid]))
    # Systematic resampling along the grid, ordered by the length: the error of a monotone
    # function's mean is at most its range over the number of draws.
    assert abs(mean_log_l - exact) <= np.log(HYPER_LENGTHS[-1] / HYPER_LENGTHS[0]) / HYPER_DRAWS


def test_mixture_draws_have_the_weighted_covariance_of_its_hypotheses() -> None:
    rng = np.random.default_rng(1)
    q_t = rng.uniform(-2, 2, (5, 6))
    q_c = np.concatenate((q_t[:1] + 0.05, rng.uniform(-2, 2, (1, 6))))
    sig_a = np.diag([4.0, 1.0]) * 1e-8
    sig_b = np.array([[2.0, 0.5], [0.5, 3.0]]) * 1e-8
    big = np.full(2, 1e9)  # known scales
    hyps = (
        FieldHypothesis(0.25, 0.3, 0.2, sig_a, big),
        FieldHypothesis(0.75, 0.9, 2.0, sig_b, big),
    )
    est = FieldEstimate(correlated_fraction=0.9, length_scale=2.0, per_pose_covariance=sig_b, hypotheses=hyps)
    draw = FieldNormal(q_t, q_c, est)
    single = [
        FieldNormal(
            q_t,
            q_c,
            FieldEstimate(
                correlated_fraction=h.correlated_fraction,
                length_scale=h.length_scale,
                per_pose_covariance=h.per_pose_covariance,
            ),
        )
        for h in hyps
    ]
    expected = 0.25 * single[0].covariance() + 0.75 * single[1].covariance()
    np.testing.assert_allclose(draw.covariance(), expected, rtol=1e-10, atol=1e-22)
    samples = draw.sample(np.random.default_rng(2), 200_000)
    scale = np.sqrt(np.outer(np.diag(expected), np.diag(expected)))
    np.testing.assert_allclose(np.cov(samples.T) / scale, expected / scale, atol=0.02)
    sens = rng.normal(size=(3, draw.size))
    white = draw.whitened_sensitivities(sens)
    assert white.shape == (3, draw.whitened_size) == (3, 2 * draw.size)
    np.testing.assert_allclose(white @ white.T, sens @ expected @ sens.T, rtol=1e-8)


def test_scale_correlation_finds_a_common_local_scale() -> None:
    rng = np.random.default_rng(4)
    n, d = 40_000, 3
    assert _scale_correlation(rng.normal(size=(n, d))) < 0.02
    # sigma^2 in {0.5, 1.5}: corr(w_j^2, w_k^2) = var(sigma^2) / (3 E sigma^4 - (E sigma^2)^2) = 1 / 11.
    local = np.sqrt(rng.choice([0.5, 1.5], size=(n, 1)))
    assert abs(_scale_correlation(local * rng.normal(size=(n, d))) - 1.0 / 11.0) < 0.015


def test_correlated_scale_factors_keep_student_t_marginals() -> None:
    rng = np.random.default_rng(8)
    q_t = rng.uniform(-2, 2, (4, 6))
    q_c = rng.uniform(-2, 2, (1, 6))
    sigma = np.eye(3) * 1e-8
    dof = np.array([6.0, 9.0, 15.0])
    base = {"correlated_fraction": 0.5, "length_scale": 0.5, "per_pose_covariance": sigma, "scale_dof": dof}
    draw = FieldNormal(q_t, q_c, FieldEstimate(**base, scale_correlation=0.8))
    known = FieldNormal(q_t, q_c, FieldEstimate(**{**base, "scale_dof": None}))
    samples = draw.sample(np.random.default_rng(9), 300_000)
    sd = np.sqrt(np.diag(known.covariance()))[-3:]
    z = samples[:, -3:] / sd
    for j, nu in enumerate(dof):
        for p in (0.9, 0.975, 0.995):
            np.testing.assert_allclose(np.quantile(z[:, j], p), stats.t.ppf(p, nu), rtol=0.03)
    # The common factor correlates the components' magnitudes (independent factors: none).
    assert np.corrcoef(z[:, 0] ** 2, z[:, 1] ** 2)[0, 1] > 0.05
    indep = FieldNormal(q_t, q_c, FieldEstimate(**base)).sample(np.random.default_rng(9), 300_000)[:, -3:] / sd
    assert abs(np.corrcoef(indep[:, 0] ** 2, indep[:, 1] ** 2)[0, 1]) < 0.02


def test_local_variance_lowers_the_scale_dof_as_brute_force_says() -> None:
    """Errors z = sqrt(v) g whose local variance v is shared where the errors are correlated
    (k blocks of m fully correlated poses): the mean of the squares has variance
    (2 + 3 var(v)) / k, against a brute-force draw of such errors (scipy's gamma for v)."""
    from robocal_uncertainty.uncertainty.model_error_draws import _leave_one_out_dof

    k, m, var_v = 6, 4, 0.5
    n = k * m
    unit = np.kron(np.eye(k), np.ones((m, m))) + 1e-9 * np.eye(n)
    fit = np.zeros((n, 0))
    nu = _leave_one_out_dof(np.zeros(n), fit, 1e-12 * np.eye(n), unit, 1, np.ones(1), local_variance=var_v)[0][0]
    rng = np.random.default_rng(12)
    v = stats.gamma(a=1.0 / var_v, scale=var_v).rvs(size=(200_000, k), random_state=rng)
    mean_sq = np.mean(v * rng.normal(size=(200_000, k)) ** 2, axis=1)
    np.testing.assert_allclose(nu, 2.0 / np.var(mean_sq), rtol=0.03)
    plain = _leave_one_out_dof(np.zeros(n), fit, 1e-12 * np.eye(n), unit, 1, np.ones(1))[0][0]
    np.testing.assert_allclose(plain, k, rtol=1e-6)  # a normal field: k independent patches
