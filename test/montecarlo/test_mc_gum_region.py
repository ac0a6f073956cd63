"""GUM propagation (correlations, Welch-Satterthwaite) and JCGM 102 coverage regions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from robocal_uncertainty.errors import ConfigError, InputError
from robocal_uncertainty.montecarlo import (
    CorrelatedNormal,
    Normal,
    Rectangular,
    StudentT,
    coverage_region,
    monte_carlo,
    propagate_gum,
    validate_gum,
)

COV = np.array([[1.0, 0.5], [0.5, 2.0]])


def sum_and_difference(x: np.ndarray) -> np.ndarray:
    return np.column_stack([x[:, 0] + x[:, 1], x[:, 0] - x[:, 1]])


def product(x: np.ndarray) -> np.ndarray:
    return x[:, 0] * x[:, 1]


def test_gum_correlated_vector_output_matches_monte_carlo() -> None:
    inputs = {"x": CorrelatedNormal([1.0, 2.0], COV)}
    gum = propagate_gum(sum_and_difference, inputs)
    jac = np.array([[1.0, 1.0], [1.0, -1.0]])
    # Linear model: J Σ Jᵀ exactly (central differences exact up to round-off).
    np.testing.assert_allclose(gum.covariance, jac @ COV @ jac.T, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(gum.sensitivities, jac, rtol=1e-9)
    assert gum.input_columns == ("x[0]", "x[1]")
    assert gum.outputs[0].standard_uncertainty == pytest.approx(2.0)  # 1 + 2 + 2×0.5
    mc = monte_carlo(sum_and_difference, inputs, seed=8, trials=400_000)
    # se of a covariance element ≤ sqrt(V_ii V_jj (1 + ρ²)/M) ≤ 4 sqrt(2/4e5) = 0.009.
    np.testing.assert_allclose(mc.covariance, gum.covariance, atol=0.045)
    assert validate_gum(gum, mc, output=1, n_dig=1).validated


def test_gum_nonlinear_sensitivities() -> None:
    gum = propagate_gum(product, [Normal(3.0, 0.1), Normal(-2.0, 0.2)])
    # ∂(x1 x2)/∂x1 = x2, ∂/∂x2 = x1; central differences are exact for a bilinear model.
    np.testing.assert_allclose(gum.sensitivities, [[-2.0, 3.0]], rtol=1e-9)
    assert gum.outputs[0].estimate == pytest.approx(-6.0)
    assert gum.outputs[0].standard_uncertainty == pytest.approx(math.hypot(0.2, 0.6))


def test_gum_welch_satterthwaite() -> None:
    # u_c² = 1 + 1 = 2; ν_eff = u_c⁴ / (1⁴/4) = 16; k = t_16(0.975) = 2.1199.
    gum = propagate_gum(lambda x: x.sum(axis=1), [StudentT(0.0, 1.0, 4.0), Normal(0.0, 1.0)])
    g = gum.outputs[0]
    assert g.standard_uncertainty == pytest.approx(math.sqrt(2.0))
    assert g.effective_dof == pytest.approx(16.0)
    assert g.coverage_factor == pytest.approx(stats.t.ppf(0.975, 16))
    assert g.coverage_factor == pytest.approx(2.1199, abs=1e-4)
    normal = propagate_gum(lambda x: x.sum(axis=1), [Normal(0.0, 1.0)] * 2).outputs[0]
    assert math.isinf(normal.effective_dof) and normal.coverage_factor == pytest.approx(1.959964)


def test_gum_errors() -> None:
    with pytest.raises(ConfigError, match="relative_step must lie in"):
        propagate_gum(product, [Normal(0.0, 1.0)] * 2, relative_step=0.0)
    with pytest.raises(ConfigError, match=r"model output must have shape \(5,\)"):
        propagate_gum(lambda x: x[:-1], [Normal(0.0, 1.0)] * 2)
    with pytest.raises(ConfigError, match="model returned 1 non-finite values"):
        propagate_gum(lambda x: np.where(x[:, 0] == 0, np.nan, x[:, 0]), [Normal(0.0, 1.0)])


def test_validation_requires_matching_runs() -> None:
    inputs = [Rectangular(0.0, 1.0)]
    gum = propagate_gum(lambda x: x[:, 0], inputs, coverage=0.9)
    mc = monte_carlo(lambda x: x[:, 0], inputs, seed=0, trials=10_000)
    with pytest.raises(ConfigError, match="coverage probabilities differ"):
        validate_gum(gum, mc)


def test_coverage_region_of_correlated_normal() -> None:
    dist = CorrelatedNormal([1.0, -1.0], [[1.0, 0.8], [0.8, 1.0]])
    samples = dist.sample(np.random.default_rng(10), 200_000)
    region = coverage_region(samples, 0.95)
    assert region.normal_coverage_factor == pytest.approx(2.4477, abs=1e-4)
    # Mahalanobis distance ~ chi(2); density at 2.4477 is 0.122, so se(k_p) =
    # sqrt(0.95 × 0.05 / 2e5)/0.122 = 0.004; 5 se.
    assert region.coverage_factor == pytest.approx(2.4477, abs=0.02)
    fresh = dist.sample(np.random.default_rng(11), 100_000)
    inside = region.contains(fresh)
    assert isinstance(inside, np.ndarray) and inside.shape == (100_000,)
    # Binomial se sqrt(0.0475/1e5) = 7e-4 plus k_p's own error (~1e-3 in coverage).
    assert inside.mean() == pytest.approx(0.95, abs=0.005)
    assert region.contains([1.0, -1.0]) is True
    # The point mean + t·σ·v along an eigenvector v with std σ is at Mahalanobis
    # distance t: minor axis (1, -1)/√2 has σ = sqrt(0.2), major (1, 1)/√2 sqrt(1.8).
    minor = np.array([1.0, -1.0]) / math.sqrt(2.0) * math.sqrt(0.2)
    major = np.array([1.0, 1.0]) / math.sqrt(2.0) * math.sqrt(1.8)
    centre = np.array([1.0, -1.0])
    assert region.contains(centre + 2.2 * minor) and not region.contains(centre + 2.7 * minor)
    assert region.contains(centre + 2.2 * major) and not region.contains(centre + 2.7 * major)
    np.testing.assert_allclose(region.mahalanobis(centre + 2.0 * major), 2.0, atol=0.01)


def test_coverage_region_rejects_singular_covariance() -> None:
    x = np.random.default_rng(0).normal(size=(5_000, 1))
    samples = np.hstack([x, 2.0 * x])
    with pytest.raises(InputError, match=r"covariance of samples is singular \(rank 1 of 2\)"):
        coverage_region(samples)
    region = coverage_region(np.hstack([x, x + 1e-3]) + np.random.default_rng(1).normal(size=(5_000, 2)))
    with pytest.raises(InputError, match=r"points must have shape \(2,\) or \(m, 2\)"):
        region.contains([0.0, 0.0, 0.0])
