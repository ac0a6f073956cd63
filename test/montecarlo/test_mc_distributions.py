"""Each input distribution: sample moments against the analytic JCGM 101 §6.4 values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo import (
    Arcsine,
    CorrelatedNormal,
    CurvilinearTrapezoid,
    Distribution,
    Empirical,
    Normal,
    Rectangular,
    StudentT,
    Triangular,
)

M = 400_000

# (distribution, kurtosis used for the standard error of the sample std).
# Kurtoses: normal 3, rectangular 1.8, symmetric triangular 2.4, arcsine 1.5,
# t_10 3 + 6/(10-4) = 4; the asymmetric triangular (2.4) and the curvilinear
# trapezoid (bounded, below 3) use 3 as a safe upper bound.
CASES = [
    (Normal(3.0, 0.5), 3.0),
    (Rectangular(-2.0, 4.0), 1.8),
    (Rectangular.from_centre(10.0, math.sqrt(3.0)), 1.8),
    (Triangular(0.0, 6.0), 2.4),
    (Triangular(0.0, 6.0, mode=1.0), 3.0),
    (Arcsine(-1.0, 3.0), 1.5),
    (StudentT(5.0, 2.0, 10.0), 4.0),
    (CurvilinearTrapezoid(-1.0, 1.0, 0.5), 3.0),
]


@pytest.mark.parametrize(("dist", "kurtosis"), CASES, ids=lambda c: type(c).__name__)
def test_sample_moments_match_analytic(dist: Distribution, kurtosis: float) -> None:
    x = dist.sample(np.random.default_rng(7), M)
    assert x.shape == (M,)
    mean, sigma = dist.expectation, dist.standard_uncertainty  # type: ignore[attr-defined]
    # 5 standard errors: se(mean) = σ/√M, se(s) ≈ σ sqrt((κ-1)/(4M)); a wrong formula
    # (e.g. a missing d²/9 term, ~4 % of σ) is ~40 standard errors off.
    assert abs(x.mean() - mean) <= 5 * sigma / math.sqrt(M)
    assert abs(x.std(ddof=1) - sigma) <= 5 * sigma * math.sqrt((kurtosis - 1) / (4 * M))


def test_analytic_values_of_jcgm101_formulas() -> None:
    # Exact closed forms, compared at round-off level.
    assert Rectangular(-1.0, 1.0).standard_uncertainty == pytest.approx(1 / math.sqrt(3))
    assert Arcsine(-2.0, 2.0).standard_uncertainty == pytest.approx(2.0 / math.sqrt(2.0))
    trap = CurvilinearTrapezoid(-1.0, 1.0, 0.5)
    assert trap.standard_uncertainty == pytest.approx(math.sqrt(4 / 12 + 0.25 / 9))
    assert Triangular(0.0, 6.0, 1.0).expectation == pytest.approx(7 / 3)
    assert StudentT(0.0, 1.0, 2.0).standard_uncertainty == math.inf
    assert StudentT(0.0, 2.0, 6.0).standard_uncertainty == pytest.approx(2 * math.sqrt(1.5))


def test_curvilinear_trapezoid_shape() -> None:
    # JCGM 101 6.4.3: on the central plateau |x| <= w0 - d the density is
    # ln((w0+d)/(w0-d)) / (4d); here w0 = 1, d = 0.5, so the plateau holds 0.5493.
    dist = CurvilinearTrapezoid(-1.0, 1.0, 0.5)
    x = dist.sample(np.random.default_rng(3), M)
    assert x.min() >= -1.5 and x.max() <= 1.5
    expected = 1.0 * math.log(3.0) / 2.0
    fraction = np.mean(np.abs(x) <= 0.5)
    # Binomial standard error sqrt(f(1-f)/M) = 7.9e-4; 5 of them.
    assert abs(fraction - expected) <= 5 * math.sqrt(expected * (1 - expected) / M)


def test_arcsine_is_u_shaped() -> None:
    x = Arcsine(0.0, 1.0).sample(np.random.default_rng(1), M)
    counts, _ = np.histogram(x, bins=10, range=(0.0, 1.0))
    assert counts[0] > 2 * counts[5] and counts[-1] > 2 * counts[4]


def test_correlated_normal_covariance() -> None:
    cov = np.array([[4.0, 1.2, 0.0], [1.2, 1.0, -0.3], [0.0, -0.3, 0.5]])
    dist = CorrelatedNormal([1.0, -2.0, 0.0], cov)
    x = dist.sample(np.random.default_rng(5), M)
    assert x.shape == (M, 3) and dist.size == 3
    np.testing.assert_allclose(x.mean(axis=0), [1.0, -2.0, 0.0], atol=5 * 2 / math.sqrt(M))
    # se of a covariance element <= sqrt(var_i var_j (1+ρ²)/M) <= 4 sqrt(2/M) = 8.9e-3.
    np.testing.assert_allclose(np.cov(x, rowvar=False), cov, atol=5 * 4 * math.sqrt(2 / M))
    np.testing.assert_allclose(dist.standard_uncertainty, np.sqrt(np.diag(cov)))


def test_correlated_normal_singular_uses_eigh() -> None:
    # Rank-1 covariance: Cholesky fails, the eigen factor must still reproduce it.
    dist = CorrelatedNormal([0.0, 0.0], [[1.0, 2.0], [2.0, 4.0]])
    x = dist.sample(np.random.default_rng(0), 1000)
    np.testing.assert_allclose(x[:, 1], 2 * x[:, 0], atol=1e-12)
    np.testing.assert_allclose(dist.factor @ dist.factor.T, dist.covariance(), atol=1e-12)


def test_empirical_resamples_rows() -> None:
    rows = np.array([[0.0, 10.0], [1.0, 11.0], [2.0, 12.0], [3.0, 13.0]])
    dist = Empirical(rows)
    x = dist.sample(np.random.default_rng(2), M)
    np.testing.assert_array_equal(x[:, 1] - x[:, 0], 10.0)  # rows stay intact
    np.testing.assert_allclose(dist.expectation, [1.5, 11.5])
    np.testing.assert_allclose(dist.standard_uncertainty, [math.sqrt(1.25)] * 2)
    # Population std sqrt(1.25) = 1.118; se of the mean 1.118/sqrt(M), 5 of them.
    assert abs(x[:, 0].mean() - 1.5) <= 5 * 1.118 / math.sqrt(M)
    scalar = Empirical([1.0, 2.0, 3.0])
    assert scalar.size == 1 and scalar.sample(np.random.default_rng(0), 5).shape == (5,)


def test_same_generator_state_same_draws() -> None:
    a = Triangular(0.0, 1.0).sample(np.random.default_rng(11), 100)
    b = Triangular(0.0, 1.0).sample(np.random.default_rng(11), 100)
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(
    ("factory", "match"),
    [
        (lambda: Normal(0.0, -1.0), "Normal.std must be >= 0"),
        (lambda: Normal(math.nan, 1.0), "Normal.mean must be finite"),
        (lambda: Rectangular(1.0, 1.0), "Rectangular needs low < high"),
        (lambda: Rectangular.from_centre(0.0, 0.0), "half_width must be > 0"),
        (
            lambda: Triangular(0.0, 1.0, 2.0),
            r"Triangular.mode must lie in \[0.0, 1.0\]",
        ),
        (lambda: Arcsine(2.0, 1.0), "Arcsine needs low < high"),
        (lambda: StudentT(0.0, 1.0, 0.0), "StudentT.dof must be finite and > 0"),
        (lambda: StudentT(0.0, -1.0, 3.0), "StudentT.scale must be >= 0"),
        (
            lambda: CurvilinearTrapezoid(0.0, 1.0, 0.6),
            "half_width_of_limits must lie in",
        ),
        (
            lambda: CorrelatedNormal([0.0, 0.0], [[1.0, 2.0], [2.0, 1.0]]),
            "positive semidefinite",
        ),
        (
            lambda: CorrelatedNormal([0.0, 0.0], [[1.0, 0.5], [0.0, 1.0]]),
            "must be symmetric",
        ),
        (lambda: CorrelatedNormal([0.0, 0.0], np.eye(3)), r"shape \(2, 2\)"),
        (lambda: Empirical([1.0, math.nan]), "Empirical.samples must be finite"),
        (lambda: Empirical(np.zeros((0,))), "Empirical.samples must have shape"),
    ],
)
def test_invalid_parameters_raise_config_error(factory: object, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        factory()  # type: ignore[operator]


def test_negative_sample_count_rejected() -> None:
    with pytest.raises(ConfigError, match="n must be a non-negative integer"):
        Normal(0.0, 1.0).sample(np.random.default_rng(0), -1)
