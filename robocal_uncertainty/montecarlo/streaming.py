"""Per-block reduction of Monte Carlo model values, so the driver's memory stays bounded.

Each trial block is reduced where it is evaluated (a worker process or Dask worker) to
its count, mean, sum of squared deviations per output, co-moment matrices within groups
of outputs (e.g. the x, y, z of one tool position) and the model values of a few kept
columns. The driver combines the blocks' moments with the exact pairwise update of
Chan, Golub and LeVeque (1979) in block order, so the result is bit-identical whatever
the executor, and equals ``numpy.mean``/``numpy.cov`` of all model values to rounding.

Memory on the driver is ``O(n_out + n_groups g² + n_trials n_keep)`` instead of
``O(n_trials n_out)``: only the kept columns get JCGM 101 coverage intervals.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal_uncertainty.errors import ConfigError, InputError

__all__ = ["Moments", "Reduction"]

Array = NDArray[np.float64]
IndexArray = NDArray[np.intp]
_NO_GROUPS = np.zeros((0, 1), dtype=np.intp)


def _index_array(name: str, value: ArrayLike, ndim: int) -> IndexArray:
    array = np.asarray(value)
    if array.size == 0:
        array = np.zeros((0,) * (ndim - 1) + (array.shape[-1] if array.ndim == ndim else 0,), dtype=np.intp)
    if array.ndim != ndim or not np.issubdtype(array.dtype, np.integer) or (array < 0).any():
        msg = f"{name} must be non-negative integer column indices of {ndim} dimension(s), got shape {array.shape}"
        raise ConfigError(msg)
    result = np.ascontiguousarray(array, dtype=np.intp)
    result.setflags(write=False)
    return result


@dataclass(frozen=True, eq=False)
class Reduction:
    """What each block is reduced to before it leaves the worker.

    Attributes
    ----------
    groups : ndarray of int, shape (n_groups, g)
        Output columns whose g x g covariance is kept, one row per group (e.g.
        ``arange(3 n).reshape(n, 3)`` for n positions). None or shape (0, g) keeps none;
        the variance of every output is always kept.
    keep : ndarray of int, shape (n_keep,)
        Output columns whose model values are all kept (for coverage intervals and
        regions); empty keeps none.
    """

    groups: IndexArray
    keep: IndexArray

    def __init__(self, groups: ArrayLike | None = None, keep: ArrayLike = ()) -> None:
        groups = _NO_GROUPS if groups is None else groups
        object.__setattr__(self, "groups", _index_array("reduction groups", groups, 2))
        object.__setattr__(self, "keep", _index_array("reduction keep", np.asarray(keep, dtype=np.intp), 1))

    def check(self, n_outputs: int) -> None:
        """Raise ConfigError if a column index is not below ``n_outputs``."""
        for name, cols in (("groups", self.groups), ("keep", self.keep)):
            if cols.size and int(cols.max()) >= n_outputs:
                msg = f"reduction {name} names column {int(cols.max())}, but the model has {n_outputs} outputs"
                raise ConfigError(msg)

    def reduce(self, values: Array) -> tuple[Moments, Array]:
        """Moments of a block's model values (n, n_out) and its kept columns (n, n_keep)."""
        self.check(values.shape[1])
        return Moments.of(values, self.groups), np.ascontiguousarray(values[:, self.keep])


@dataclass(frozen=True, eq=False)
class Moments:
    """Count, mean and second moments of model values, combinable block by block.

    Attributes
    ----------
    count : int
        Number of model values M.
    mean : ndarray, shape (n_out,)
        Mean per output, in the outputs' units.
    m2 : ndarray, shape (n_out,)
        Sum of squared deviations from the mean per output, in squared units.
    groups : ndarray of int, shape (n_groups, g)
        Output columns of each co-moment group.
    comoment : ndarray, shape (n_groups, g, g)
        Sum of products of deviations within each group, in products of units.
    """

    count: int
    mean: Array
    m2: Array
    groups: IndexArray
    comoment: Array

    @classmethod
    def of(cls, values: ArrayLike, groups: ArrayLike | None = None) -> Moments:
        """Moments of model values.

        Parameters
        ----------
        values : array_like, shape (M, n_out)
            Finite model values, M >= 1.
        groups : array_like of int, shape (n_groups, g), optional
            Co-moment groups (see :class:`Reduction`); None keeps none.
        """
        data = np.asarray(values, dtype=np.float64)
        if data.ndim != 2 or data.shape[0] < 1:
            msg = f"values must have shape (M, n_out) with M >= 1, got {data.shape}"
            raise InputError(msg)
        cols = _index_array("groups", _NO_GROUPS if groups is None else groups, 2)
        mean = data.mean(axis=0)
        centred = data - mean
        m2 = (centred * centred).sum(axis=0)
        g = cols.shape[1]
        comoment = np.empty((cols.shape[0], g, g))
        # One (M, n_groups) product per entry pair keeps the work vectorised and the
        # temporary memory at M x n_groups.
        for i in range(g):
            ci = centred[:, cols[:, i]]
            for j in range(i, g):
                comoment[:, i, j] = comoment[:, j, i] = (ci * centred[:, cols[:, j]]).sum(axis=0)
        return cls(int(data.shape[0]), mean, m2, cols, comoment)

    def combine(self, other: Moments) -> Moments:
        """Moments of the union of two sets of model values (Chan et al. pairwise update).

        Not commutative in rounding: combine blocks in a fixed order for bit-identical
        results.
        """
        if self.mean.shape != other.mean.shape or not np.array_equal(self.groups, other.groups):
            msg = f"cannot combine moments of {self.mean.shape[0]} and {other.mean.shape[0]} outputs or other groups"
            raise InputError(msg)
        n = self.count + other.count
        delta = other.mean - self.mean
        weight = self.count * other.count / n
        mean = self.mean + delta * (other.count / n)
        m2 = self.m2 + other.m2 + delta * delta * weight
        dg = delta[self.groups]  # (n_groups, g)
        comoment = self.comoment + other.comoment + weight * (dg[:, :, None] * dg[:, None, :])
        return Moments(n, mean, m2, self.groups, comoment)

    @property
    def variance(self) -> Array:
        """Sample variance (ddof=1) per output, shape (n_out,), in squared units."""
        return self.m2 / (self.count - 1) if self.count > 1 else np.full_like(self.m2, np.nan)

    @property
    def std(self) -> Array:
        """Standard uncertainty (ddof=1) per output, shape (n_out,), in the outputs' units."""
        return np.sqrt(self.variance)

    @property
    def group_covariance(self) -> Array:
        """Covariance (ddof=1) within each group, shape (n_groups, g, g)."""
        if self.count < 2:
            return np.full_like(self.comoment, np.nan)
        return self.comoment / (self.count - 1)
