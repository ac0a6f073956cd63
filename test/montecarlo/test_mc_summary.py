"""Coverage intervals (JCGM 101 §7.7) against analytic quantiles; §7.9.2 tolerance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from robocal_uncertainty.errors import ConfigError, InputError
from robocal_uncertainty.montecarlo import (
    Normal,
    Rectangular,
    monte_carlo,
    numerical_tolerance,
    summarize,
)

M = 1_000_000


def identity(x: np.ndarray) -> np.ndarray:
    return x[:, 0]


def exponential(x: np.ndarray) -> np.ndarray:
    return -np.log(x[:, 0])  # X ~ R(0, 1) gives Y ~ Exp(1)


def pair_sum(x: np.ndarray) -> np.ndarray:
    return x[:, 0] + x[:, 1]


def test_rectangular_output_exact_quantiles() -> None:
    out = monte_carlo(identity, [Rectangular(2.0, 6.0)], seed=1, trials=M).outputs[0]
    # Exact: 2 + 4 × 0.025 = 2.1 and 2 + 4 × 0.975 = 5.9; se of a uniform quantile is
    # 4 sqrt(p(1-p)/M) = 6.2e-4, so 5 se = 0.0031.
    assert out.probabilistically_symmetric.low == pytest.approx(2.1, abs=0.0031)
    assert out.probabilistically_symmetric.high == pytest.approx(5.9, abs=0.0031)
    # Every window of a flat density has width 0.95 × 4 = 3.8; the shortest can only
    # be a little narrower through sampling noise.
    assert out.shortest.width == pytest.approx(3.8, abs=0.01)
    assert out.standard_uncertainty == pytest.approx(4 / (2 * math.sqrt(3)), rel=0.002)


def test_symmetric_output_intervals_agree() -> None:
    # Sum of two R(-1, 1): triangular on [-2, 2] with exact 2.5 % point -2 + sqrt(0.2).
    out = monte_carlo(pair_sum, [Rectangular(-1.0, 1.0)] * 2, seed=2, trials=M).outputs[0]
    exact = 2.0 - math.sqrt(0.2)
    # Density at the quantile is sqrt(0.2)/4 = 0.112; se = 1.56e-4/0.112 = 0.0014.
    assert out.probabilistically_symmetric.high == pytest.approx(exact, abs=0.007)
    assert out.probabilistically_symmetric.low == pytest.approx(-exact, abs=0.007)
    # For a symmetric unimodal output the shortest interval is the symmetric one.
    assert out.shortest.low == pytest.approx(out.probabilistically_symmetric.low, abs=0.01)
    assert out.shortest.high == pytest.approx(out.probabilistically_symmetric.high, abs=0.01)


def test_asymmetric_output_shortest_is_shorter() -> None:
    out = monte_carlo(exponential, [Rectangular(0.0, 1.0)], seed=3, trials=M).outputs[0]
    # Exp(1): symmetric [ln(1/0.975), ln 40] = [0.0253, 3.689]; shortest [0, ln 20].
    # se of the quantile at q is sqrt(p(1-p)/M)/e^-q: 1.6e-4 (low), 6.2e-3 (ln 40),
    # 4.4e-3 (ln 20); 5 se each.
    sym, short = out.probabilistically_symmetric, out.shortest
    assert sym.low == pytest.approx(math.log(1 / 0.975), abs=8e-4)
    assert sym.high == pytest.approx(math.log(40.0), abs=0.031)
    assert short.low == pytest.approx(0.0, abs=1e-4)
    assert short.high == pytest.approx(math.log(20.0), abs=0.022)
    assert short.width < sym.width - 0.6  # 2.996 versus 3.664
    assert out.expanded_uncertainty == pytest.approx(sym.half_width)
    assert out.coverage_factor == pytest.approx(sym.half_width / out.standard_uncertainty)
    assert out.relative_expanded_uncertainty == pytest.approx(sym.half_width / out.estimate)


def test_expanded_from_shortest_and_histogram() -> None:
    x = np.random.default_rng(0).exponential(size=20_000)
    summary = summarize(x, 0.9, bins=25, expanded_from="shortest")
    out = summary.outputs[0]
    assert out.interval is out.shortest and out.expanded_uncertainty == out.shortest.half_width
    assert out.histogram.counts.sum() == 20_000 and out.histogram.edges.shape == (26,)
    assert out.shortest.coverage_probability == 0.9
    # Exactly q = 18_000 values lie in the discrete JCGM interval [y_(r), y_(r+q)].
    inside = np.count_nonzero((x >= out.shortest.low) & (x <= out.shortest.high))
    assert inside == 18_001


def test_vector_summary_covariance() -> None:
    rng = np.random.default_rng(4)
    samples = rng.multivariate_normal([0.0, 1.0], [[1.0, 0.6], [0.6, 2.0]], size=50_000)
    summary = summarize(samples)
    np.testing.assert_allclose(summary.covariance, np.cov(samples, rowvar=False), rtol=1e-12)
    assert len(summary.outputs) == 2 and summary.n_trials == 50_000
    assert summary.correlation[0, 1] == pytest.approx(0.6 / math.sqrt(2.0), abs=0.02)


def test_degenerate_output_has_no_factors() -> None:
    out = summarize(np.zeros(5_000)).outputs[0]
    assert out.coverage_factor is None and out.relative_expanded_uncertainty is None
    assert out.standard_uncertainty == 0.0 and out.shortest.width == 0.0


@pytest.mark.parametrize(
    ("u", "n_dig", "delta"),
    [
        (2.0, 2, 0.05),  # JCGM 101 9.2.2: 20 × 10^-1
        (0.35, 2, 0.005),  # JCGM 101 7.9.2 example: 35 × 10^-2
        (10.149, 2, 0.5),  # 9.2.4: 10 × 10^0
        (0.0539, 2, 0.0005),  # 9.3: 54 × 10^-3
        (0.0999, 2, 0.005),  # rounds up to 10 × 10^-2
        (2.0, 1, 0.5),
        (0.0, 2, 0.0),
    ],
)
def test_numerical_tolerance(u: float, n_dig: int, delta: float) -> None:
    assert numerical_tolerance(u, n_dig) == pytest.approx(delta, rel=1e-12)


def test_summary_errors() -> None:
    with pytest.raises(
        InputError,
        match=r"samples must have at least 11 trials for coverage 0.95 \(JCGM 101 recommends 2000\), got 10",
    ):
        summarize(np.arange(10.0))
    with pytest.raises(InputError, match="samples contain 1 NaN/inf values"):
        summarize(np.r_[np.arange(3000.0), np.nan])
    with pytest.raises(ConfigError, match="coverage must lie strictly between 0 and 1"):
        summarize(np.arange(3000.0), 1.2)
    with pytest.raises(ConfigError, match="n_dig must be an integer >= 1"):
        numerical_tolerance(1.0, 0)
    with pytest.raises(ConfigError, match="bins must be a positive integer"):
        summarize(np.arange(3000.0), bins=0)


def test_normal_coverage_factor() -> None:
    out = monte_carlo(identity, [Normal(5.0, 0.1)], seed=6, trials=M).outputs[0]
    # se of k_p ≈ se(quantile)/σ = 1.56e-4/(0.1 × 0.0584)... i.e. 0.0027; 5 se.
    assert out.coverage_factor == pytest.approx(1.96, abs=0.014)
    assert out.relative_expanded_uncertainty == pytest.approx(0.196 / 5.0, abs=0.0003)
