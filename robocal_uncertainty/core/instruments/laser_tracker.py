"""Laser tracker: error of every measured coordinate uniform within the MPE +-(a + b L).

L is the tracker-to-target distance. The robot seed states +-5 um (b = 0); the blade seed the
manufacturer's MPE form a + b L. The instrument builds one ``montecarlo`` distribution of the
coordinate errors; the simulation's draws, the calibration source's draws and the GUM
variances all come from it, so they cannot drift apart.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal_uncertainty.core.instruments._values import is_real
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo.distributions import IndependentRectangular

__all__ = ["TrackerNoise"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class TrackerNoise:
    """Tracker error per coordinate, uniform within +-(a + b * L).

    Parameters
    ----------
    a : float [m]
        Constant part of the half-width (the seed's 5 um).
    b : float [m/m]
        Distance-proportional part; 0 for the plain +-a model.
    """

    a: float = 5e-6
    b: float = 0.0

    def __post_init__(self) -> None:
        if (
            not (is_real(self.a) and is_real(self.b))
            or not (np.isfinite(self.a) and np.isfinite(self.b))
            or min(self.a, self.b) < 0
        ):
            msg = f"tracker noise a and b must be finite and >= 0, got a={self.a}, b={self.b}"
            raise ConfigError(msg)

    @property
    def kind(self) -> Literal["uniform", "mpe"]:
        """``uniform`` for +-a, ``mpe`` when the half-width grows with distance."""
        return "mpe" if self.b > 0 else "uniform"

    def half_width(self, distance: ArrayLike) -> Array:
        """Half-width [m] of the uniform error for targets at `distance` [m]."""
        return self.a + self.b * np.asarray(distance, dtype=np.float64)

    def std(self, distance: ArrayLike) -> Array:
        """Standard deviation [m] per coordinate: half-width / sqrt(3)."""
        return np.asarray(self.half_width(distance) / np.sqrt(3.0), dtype=np.float64)

    def distribution(
        self, distance: ArrayLike, *, dimension: int = 3, rotation_components: Sequence[int] = ()
    ) -> IndependentRectangular:
        """The errors of every measured component of targets at `distance`, as one vector.

        Parameters
        ----------
        distance : array_like, shape (n,) or any shape [m]
            Tracker-to-target distance of each target.
        dimension : int
            Components per target (3 for a point, 6 for a pose).
        rotation_components : sequence of int
            Components that are orientations: the tracker's position error does not act on
            them (half-width 0; their noise is a separate model).

        Returns
        -------
        IndependentRectangular
            Size ``distance.size * dimension``, target-major; its covariance is the GUM input
            covariance (diagonal, half-width^2 / 3), its draws the Monte Carlo errors [m].
        """
        half = np.repeat(self.half_width(distance).reshape(-1), dimension)
        if len(rotation_components):
            per_target = half.reshape(-1, dimension)
            per_target[:, list(rotation_components)] = 0.0
            half = per_target.reshape(-1)
        return IndependentRectangular(half)

    def sample(self, rng: np.random.Generator, distance: ArrayLike) -> Array:
        """Errors of shape (*distance.shape, 3) [m]: one draw of :meth:`distribution`."""
        shape = np.shape(distance)
        return self.distribution(distance).sample(rng, 1).reshape(*shape, 3)
