"""The rectangular distributions draw numpy's uniform values, bit for bit, from one fill."""

from __future__ import annotations

import numpy as np
import pytest

from robocal_uncertainty.montecarlo.distributions import IndependentNormal, IndependentRectangular, Rectangular


@pytest.mark.parametrize(("low", "high"), [(-8.7e-6, 8.7e-6), (0.25, 3.0), (-2.0, -1e-3)])
def test_rectangular_is_numpys_uniform(low: float, high: float) -> None:
    for seed in range(5):
        ours, numpys = np.random.default_rng(seed), np.random.default_rng(seed)
        np.testing.assert_array_equal(Rectangular(low, high).sample(ours, 10_001), numpys.uniform(low, high, 10_001))
        assert ours.random() == numpys.random()  # the stream left where uniform leaves it


def test_independent_rectangular_is_numpys_uniform() -> None:
    rng = np.random.default_rng(7)
    half_widths = rng.uniform(1e-6, 5e-5, 41)
    half_widths[3] = 0.0
    centres = rng.normal(0.0, 1e-3, 41)
    dist = IndependentRectangular(half_widths, centres)
    drawn = np.arange(41) != 3  # a constant component takes no draw
    for seed in range(5):
        ours, numpys = np.random.default_rng(seed), np.random.default_rng(seed)
        expected = np.tile(centres, (333, 1))
        expected[:, drawn] = numpys.uniform(-1.0, 1.0, size=(333, 40)) * half_widths[drawn] + centres[drawn]
        np.testing.assert_array_equal(dist.sample(ours, 333), expected)
        assert ours.random() == numpys.random()
    whole = IndependentRectangular(half_widths[drawn], centres[drawn])  # none constant: drawn whole
    ours, numpys = np.random.default_rng(11), np.random.default_rng(11)
    expected = numpys.uniform(-1.0, 1.0, size=(7, 40)) * half_widths[drawn] + centres[drawn]
    np.testing.assert_array_equal(whole.sample(ours, 7), expected)


def test_independent_normal_draws_only_its_non_constant_components() -> None:
    std = np.array([0.0, 2e-5, 0.0, 1e-5, 3e-5, 0.0])
    mean = np.array([1.0, 0.0, -2.0, 0.5, 0.0, 0.0])
    dist = IndependentNormal(std, mean)
    ours, numpys = np.random.default_rng(3), np.random.default_rng(3)
    sample = dist.sample(ours, 1000)
    z = numpys.standard_normal((1000, 3))
    np.testing.assert_array_equal(sample[:, [0, 2, 5]], np.tile(mean[[0, 2, 5]], (1000, 1)))
    np.testing.assert_array_equal(sample[:, [1, 3, 4]], z * std[[1, 3, 4]] + mean[[1, 3, 4]])
    assert ours.random() == numpys.random()
    # The distribution is unchanged: spreads and means as stated (5 standard errors).
    big = dist.sample(np.random.default_rng(4), 200_000)
    assert big.std(axis=0) == pytest.approx(std, rel=0.02, abs=0.0)
    assert big.mean(axis=0) == pytest.approx(mean, abs=5 * 3e-5 / np.sqrt(200_000))
