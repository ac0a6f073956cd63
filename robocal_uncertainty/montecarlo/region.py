"""Hyper-ellipsoidal coverage region for vector outputs (JCGM 102 §7.7.2).

The region is ``(η - ȳ)ᵀ V⁻¹ (η - ȳ) <= k_p²`` with ȳ and V the Monte Carlo mean and
covariance and k_p chosen so that the fraction p of the Monte Carlo values lie
inside: with ``q = floor(pM + 1/2)``, k_p² is the q-th smallest squared Mahalanobis
distance of the values themselves.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import linalg, stats

from robocal_uncertainty.errors import InputError
from robocal_uncertainty.montecarlo.summary import check_coverage, coverage_window

__all__ = ["EllipsoidalRegion", "coverage_region"]


@dataclass(frozen=True, eq=False)
class EllipsoidalRegion:
    """Coverage region of probability p for an n-component output.

    Attributes
    ----------
    mean : ndarray, shape (n,)
        ȳ, in the output units.
    covariance : ndarray, shape (n, n)
        V (ddof=1), in products of the output units.
    coverage_factor : float
        k_p from the Monte Carlo values (dimensionless).
    normal_coverage_factor : float
        sqrt(χ²_n quantile at p): the k_p a multivariate normal output would have.
    coverage_probability : float
        p.
    n_trials : int
        Number of Monte Carlo values M.
    """

    mean: NDArray[np.float64]
    covariance: NDArray[np.float64]
    coverage_factor: float
    normal_coverage_factor: float
    coverage_probability: float
    n_trials: int
    cholesky: NDArray[np.float64] = field(repr=False)

    @property
    def dimension(self) -> int:
        """Number of output components n."""
        return int(self.mean.shape[0])

    def mahalanobis(self, points: ArrayLike) -> NDArray[np.float64]:
        """Mahalanobis distances sqrt((η-ȳ)ᵀ V⁻¹ (η-ȳ)).

        Parameters
        ----------
        points : array_like, shape (n,) or (m, n)
            Points η, in the output units.

        Returns
        -------
        ndarray, shape () or (m,)
            Distances (dimensionless).
        """
        eta = np.asarray(points, dtype=np.float64)
        single = eta.ndim == 1
        eta = np.atleast_2d(eta)
        if eta.ndim != 2 or eta.shape[1] != self.dimension:
            msg = f"points must have shape ({self.dimension},) or (m, {self.dimension}), got {np.shape(points)}"
            raise InputError(msg)
        distances = _distances(self.cholesky, eta - self.mean)
        return distances[0] if single else distances

    def contains(self, points: ArrayLike) -> bool | NDArray[np.bool_]:
        """Whether points lie in the region: bool for shape (n,), array (m,) for (m, n)."""
        inside = self.mahalanobis(points) <= self.coverage_factor
        return bool(inside) if np.ndim(inside) == 0 else inside


def _distances(cholesky: NDArray[np.float64], centred: NDArray[np.float64]) -> NDArray[np.float64]:
    z = linalg.solve_triangular(cholesky, centred.T, lower=True, check_finite=False)
    return np.asarray(np.sqrt((z * z).sum(axis=0)), dtype=np.float64)


def coverage_region(samples: ArrayLike, coverage: float = 0.95) -> EllipsoidalRegion:
    """Hyper-ellipsoidal coverage region of Monte Carlo vector values (JCGM 102 §7.7.2).

    Parameters
    ----------
    samples : array_like, shape (M, n)
        Finite model values, in the output units; M as for :func:`.summarize`.
    coverage : float
        Coverage probability p, in (0, 1).

    Returns
    -------
    EllipsoidalRegion

    Raises
    ------
    InputError
        When the samples are malformed or their covariance is singular (some output
        component is constant or a linear combination of others).
    """
    p = check_coverage(coverage)
    values = np.asarray(samples, dtype=np.float64)
    if values.ndim != 2 or values.shape[1] < 1:
        msg = f"samples must have shape (M, n), got {np.shape(samples)}"
        raise InputError(msg)
    m, n = values.shape
    q = coverage_window(m, p)
    if not np.isfinite(values).all():
        msg = f"samples contain {int((~np.isfinite(values)).sum())} NaN/inf values"
        raise InputError(msg)
    mean = values.mean(axis=0)
    covariance = np.atleast_2d(np.cov(values, rowvar=False, ddof=1))
    eigenvalues = np.linalg.eigvalsh(covariance)
    # Relative threshold: a rank-deficient V has eigenvalues at round-off level.
    if eigenvalues[0] <= n * np.finfo(np.float64).eps * max(eigenvalues[-1], 0.0):
        rank = int((eigenvalues > n * np.finfo(np.float64).eps * eigenvalues[-1]).sum())
        msg = (
            f"covariance of samples is singular (rank {rank} of {n}): some output is "
            "constant or a linear combination of others; drop it before building a region"
        )
        raise InputError(msg)
    cholesky = np.asarray(np.linalg.cholesky(covariance), dtype=np.float64)
    distances = _distances(cholesky, values - mean)
    k_p = float(np.partition(distances, q - 1)[q - 1])
    for array in (mean, covariance, cholesky):
        array.setflags(write=False)
    return EllipsoidalRegion(
        mean=mean,
        covariance=covariance,
        coverage_factor=k_p,
        normal_coverage_factor=math.sqrt(float(stats.chi2.ppf(p, n))),
        coverage_probability=p,
        n_trials=m,
        cholesky=cholesky,
    )
