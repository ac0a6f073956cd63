"""Joint encoders: reading errors uniform within +-half-width, revolute [rad] and linear [m].

The robot seed states +-0.005 deg for a revolute joint; no source paper states a prismatic
axis's value, so the linear default is a scale of accuracy class +-5 um (give the axis's own).
The instrument builds one ``montecarlo`` distribution of the reading errors; the simulation's
draws, the calibration source's draws and the GUM variances all come from it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.instruments._values import is_real
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo.distributions import (
    Distribution,
    IndependentCopies,
    IndependentRectangular,
    Rectangular,
)

__all__ = ["LINEAR_ENCODER_HALF_WIDTH", "EncoderNoise"]

Array = NDArray[np.float64]

LINEAR_ENCODER_HALF_WIDTH = 5e-6
"""Default reading error half-width of a prismatic joint [m]: a linear scale of accuracy class
±5 µm (no source paper states one; give the axis's own value)."""


@dataclass(frozen=True)
class EncoderNoise:
    """Joint reading error, uniform within ±`half_width` [rad] for a revolute joint (seed: 0.005
    deg) and ±`linear_half_width` [m] for a prismatic one (default
    :data:`LINEAR_ENCODER_HALF_WIDTH`)."""

    half_width: float = float(np.radians(0.005))
    linear_half_width: float = LINEAR_ENCODER_HALF_WIDTH

    def __post_init__(self) -> None:
        for name, what in (("half_width", "encoder noise half-width"), ("linear_half_width", "linear encoder")):
            value = getattr(self, name)
            if not is_real(value) or not np.isfinite(value) or value < 0:
                msg = f"{what} noise half-width must be finite and >= 0, got {value}"
                raise ConfigError(msg)

    def half_widths(self, prismatic: Sequence[bool]) -> Array:
        """Half-width of each joint, shape (n_joints,) [rad; m where `prismatic`]."""
        linear = np.asarray(prismatic, dtype=bool)
        return np.where(linear, self.linear_half_width, self.half_width).astype(np.float64)

    def distribution(self, prismatic: Sequence[bool], count: int) -> Distribution:
        """The reading errors of `count` configurations of the joints, as one vector.

        Parameters
        ----------
        prismatic : sequence of bool, length n_joints
            Which joints are prismatic (read in m; the others in rad).
        count : int
            Number of configurations read.

        Returns
        -------
        Distribution
            Size ``count * n_joints``, configuration-major; its covariance is the GUM input
            covariance (diagonal, half-width^2 / 3), its draws the Monte Carlo errors. Without a
            prismatic joint, copies of one scalar R(-h, h) (a point mass at 0 when h = 0).
        """
        if any(prismatic):
            return IndependentRectangular(np.tile(self.half_widths(prismatic), count))
        h = self.half_width
        one: Distribution = Rectangular(-h, h) if h > 0 else IndependentRectangular([0.0])
        return IndependentCopies(one, count * len(prismatic))

    def variances(self, prismatic: Sequence[bool]) -> Array:
        """Variance of each joint's reading error, shape (n_joints,) [rad^2; m^2 where `prismatic`]."""
        return IndependentRectangular(self.half_widths(prismatic)).variance_vector()

    def covariance(self, joint_jacobian: Array, prismatic: Sequence[bool]) -> Array:
        """``J diag(var) J^T`` of the reading errors through `joint_jacobian`, shape (..., d, d).

        `joint_jacobian` has shape (..., d, n_joints) [m/rad; m/m in prismatic columns]. Without a
        prismatic joint it is ``var J J^T`` with the one revolute variance, computed as such.
        """
        jq = np.asarray(joint_jacobian, dtype=np.float64)
        if not any(prismatic):
            var = self.variances((False,))[0]
            return np.asarray(var * np.einsum("...ij,...kj->...ik", jq, jq), dtype=np.float64)
        return np.asarray(np.einsum("...ij,j,...kj->...ik", jq, self.variances(prismatic), jq), dtype=np.float64)

    def sample_joints(self, rng: np.random.Generator, shape: tuple[int, ...], prismatic: Sequence[bool]) -> Array:
        """Errors of readings of shape ``(..., n_joints)`` [rad; m in the prismatic columns].

        One draw of :meth:`distribution`; without a prismatic joint the same draws as
        :meth:`sample`.
        """
        count = math.prod(shape[:-1])
        if not any(prismatic):
            prismatic = (False,) * shape[-1]
        return np.asarray(self.distribution(prismatic, count).sample(rng, 1), dtype=np.float64).reshape(shape)

    def sample(self, rng: np.random.Generator, shape: tuple[int, ...]) -> Array:
        """Errors of the given shape [rad], every joint revolute."""
        return self.sample_joints(rng, shape, (False,) * shape[-1])
