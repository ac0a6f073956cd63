"""The rectangular distributions draw numpy's uniform values, bit for bit, from one fill."""

from __future__ import annotations

import numpy as np
import pytest

from robocal_uncertainty.montecarlo.distributions import IndependentRectangular, Rectangular


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
    for seed in range(5):
        ours, numpys = np.random.default_rng(seed), np.random.default_rng(seed)
        expected = numpys.uniform(-1.0, 1.0, size=(333, 41)) * half_widths + centres
        np.testing.assert_array_equal(dist.sample(ours, 333), expected)
        assert ours.random() == numpys.random()
