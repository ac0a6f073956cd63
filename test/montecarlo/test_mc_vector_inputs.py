"""Vector inputs of many independent components and analytic GUM sensitivities."""

from __future__ import annotations

import numpy as np
import pytest

from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo.distributions import (
    Empirical,
    IndependentCopies,
    IndependentRectangular,
    Normal,
    Rectangular,
)
from robocal_uncertainty.montecarlo.gum import propagate_gum

HALF = np.array([1.0, 2.0, 0.5, 0.0])
WEIGHTS = np.array([[1.0, -2.0, 3.0, 4.0, 0.5, 0.25, -1.0], [0.0, 1.0, 1.0, -1.0, 2.0, 0.0, 3.0]])
ROWS = np.array([[1.0, 2.0], [-1.0, 0.0], [0.0, -2.0]])


def linear(x: np.ndarray) -> np.ndarray:
    return x @ WEIGHTS.T


def test_independent_rectangular_moments_and_samples() -> None:
    dist = IndependentRectangular(HALF, centres=[1.0, 0.0, -1.0, 2.0])
    np.testing.assert_allclose(np.diag(dist.covariance()), HALF**2 / 3.0)
    draws = dist.sample(np.random.default_rng(0), 200_000)
    assert draws.shape == (200_000, 4)
    assert (np.abs(draws - dist.centres) <= HALF).all()
    np.testing.assert_allclose(draws.var(axis=0), HALF**2 / 3.0, rtol=0.02)
    with pytest.raises(ConfigError, match="half-widths"):
        IndependentRectangular([-1.0])


def test_independent_copies_are_independent_and_copy_major() -> None:
    dist = IndependentCopies(Empirical(ROWS), 3)
    assert dist.size == 6
    cov = dist.covariance()
    np.testing.assert_allclose(cov[:2, :2], Empirical(ROWS).covariance())
    assert np.all(cov[:2, 2:] == 0.0)
    draws = dist.sample(np.random.default_rng(1), 100_000)
    np.testing.assert_allclose(np.cov(draws.T, bias=True), cov, atol=0.03)
    with pytest.raises(ConfigError, match="count"):
        IndependentCopies(Normal(0.0, 1.0), 0)


def test_analytic_sensitivities_give_the_finite_difference_result() -> None:
    """For a linear model the analytic and the central-difference GUM coincide, and the
    per-input propagation of diagonal and block-diagonal inputs equals J Sigma J^T."""
    inputs = {
        "box": IndependentRectangular(HALF),
        "pairs": IndependentCopies(Empirical(ROWS), 1),
        "one": Rectangular(-0.3, 0.3),
    }
    finite = propagate_gum(linear, inputs)
    analytic = propagate_gum(linear, inputs, sensitivities=WEIGHTS)
    np.testing.assert_allclose(analytic.covariance, finite.covariance, rtol=1e-9)
    np.testing.assert_allclose(finite.covariance, WEIGHTS @ finite.input_covariance @ WEIGHTS.T, rtol=1e-12)
    assert analytic.relative_step is None
    with pytest.raises(ConfigError, match="sensitivities"):
        propagate_gum(linear, inputs, sensitivities=WEIGHTS[:, :3])
