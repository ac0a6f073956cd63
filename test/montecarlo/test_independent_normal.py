"""IndependentNormal: the diagonal normal vector input of the 6-DOF orientation noise."""

from __future__ import annotations

import numpy as np
import pytest

from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo.distributions import CorrelatedNormal, IndependentNormal
from robocal_uncertainty.montecarlo.gum import propagate_gum


def test_moments_of_the_draws() -> None:
    std = np.array([0.0, 1e-4, 2e-4, 3e-4])
    mean = np.array([1.0, -2.0, 0.5, 0.0])
    draws = IndependentNormal(std, mean).sample(np.random.default_rng(5), 200_000)
    assert draws.shape == (200_000, 4)
    assert np.all(draws[:, 0] == 1.0)
    np.testing.assert_allclose(draws.std(axis=0)[1:], std[1:], rtol=0.01)
    assert np.all(np.abs(draws.mean(axis=0)[1:] - mean[1:]) < 4 * std[1:] / np.sqrt(200_000))
    corr = np.corrcoef(draws[:, 1:].T)
    assert np.max(np.abs(corr - np.eye(3))) < 0.01


def test_gum_of_a_diagonal_input_equals_the_dense_correlated_normal() -> None:
    rng = np.random.default_rng(1)
    std = rng.uniform(0.0, 2.0, 12)
    std[::4] = 0.0
    jac = rng.normal(size=(3, 12))

    def model(x: np.ndarray) -> np.ndarray:
        return x @ jac.T

    fast = propagate_gum(model, [IndependentNormal(std)])
    dense = propagate_gum(model, [CorrelatedNormal(np.zeros(12), np.diag(std**2))])
    np.testing.assert_allclose(fast.covariance, dense.covariance, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(fast.covariance, (jac * std**2) @ jac.T, rtol=1e-12)


@pytest.mark.parametrize(("std", "mean"), [([], None), ([1.0, -1.0], None), ([1.0, np.nan], None), ([1.0], [0.0, 1.0])])
def test_bad_parameters_are_one_line_errors(std: list[float], mean: list[float] | None) -> None:
    with pytest.raises(ConfigError, match="IndependentNormal") as info:
        IndependentNormal(std, mean)
    assert "\n" not in str(info.value)
