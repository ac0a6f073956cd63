"""Probability distributions assigned to input quantities (JCGM 101 §6.4).

Every distribution is a frozen dataclass exposing ``size`` (number of scalar
components), the analytic ``expectation`` and ``standard_uncertainty`` of JCGM 101
§6.4, ``mean_vector()`` and ``covariance()`` (used by the GUM propagation) and
``sample(rng, n)``. Units are whatever the caller uses; a distribution never converts.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal_uncertainty.errors import ConfigError

__all__ = [
    "Arcsine",
    "CorrelatedNormal",
    "CurvilinearTrapezoid",
    "Distribution",
    "Empirical",
    "IndependentCopies",
    "IndependentNormal",
    "IndependentRectangular",
    "Normal",
    "Rectangular",
    "StudentT",
    "Triangular",
]


@runtime_checkable
class Distribution(Protocol):
    """What the Monte Carlo engine and the GUM propagation need from an input."""

    @property
    def size(self) -> int:
        """Number of scalar components (columns) this input contributes."""
        ...

    def mean_vector(self) -> NDArray[np.float64]:
        """Expectation as an array of shape (size,)."""
        ...

    def covariance(self) -> NDArray[np.float64]:
        """Covariance matrix of shape (size, size)."""
        ...

    def sample(self, rng: np.random.Generator, n: int) -> NDArray[np.float64]:
        """Draw ``n`` values: shape (n,) when ``size == 1``, else (n, size)."""
        ...


def _finite(name: str, value: float) -> float:
    number = float(value)
    if not math.isfinite(number):
        msg = f"{name} must be finite, got {value!r}"
        raise ConfigError(msg)
    return number


def _check_n(n: int) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
        msg = f"n must be a non-negative integer, got {n!r}"
        raise ConfigError(msg)
    return int(n)


def _check_limits(cls: str, low: float, high: float) -> None:
    _finite(f"{cls}.low", low)
    _finite(f"{cls}.high", high)
    if not low < high:
        msg = f"{cls} needs low < high, got low={low!r}, high={high!r}"
        raise ConfigError(msg)


class _Scalar(ABC):
    """Shared helpers for the scalar (size 1) distributions."""

    @property
    def size(self) -> int:
        return 1

    @property
    @abstractmethod
    def expectation(self) -> float:
        """Analytic expectation, in the quantity's unit."""

    @property
    @abstractmethod
    def standard_uncertainty(self) -> float:
        """Analytic standard deviation, in the quantity's unit."""

    def mean_vector(self) -> NDArray[np.float64]:
        return np.array([self.expectation], dtype=np.float64)

    @abstractmethod
    def sample(self, rng: np.random.Generator, n: int) -> NDArray[np.float64]:
        """Draw ``n`` values, shape (n,)."""

    def covariance(self) -> NDArray[np.float64]:
        return np.array([[self.standard_uncertainty**2]], dtype=np.float64)


@dataclass(frozen=True)
class Normal(_Scalar):
    """Gaussian N(mean, std²) (JCGM 101 §6.4.7).

    Parameters
    ----------
    mean : float
        Expectation, in the quantity's unit.
    std : float
        Standard deviation (>= 0), in the quantity's unit.
    """

    mean: float
    std: float

    def __post_init__(self) -> None:
        _finite("Normal.mean", self.mean)
        _finite("Normal.std", self.std)
        if self.std < 0:
            msg = f"Normal.std must be >= 0, got {self.std!r}"
            raise ConfigError(msg)

    @property
    def expectation(self) -> float:
        return float(self.mean)

    @property
    def standard_uncertainty(self) -> float:
        return float(self.std)

    def sample(self, rng: np.random.Generator, n: int) -> NDArray[np.float64]:
        """Draw ``n`` values, shape (n,)."""
        return rng.normal(self.mean, self.std, _check_n(n))


@dataclass(frozen=True)
class Rectangular(_Scalar):
    """Rectangular (uniform) R(low, high) (JCGM 101 §6.4.2).

    Parameters
    ----------
    low, high : float
        Limits, ``low < high``, in the quantity's unit.
    """

    low: float
    high: float

    def __post_init__(self) -> None:
        _check_limits("Rectangular", self.low, self.high)

    @classmethod
    def from_centre(cls, centre: float, half_width: float) -> Rectangular:
        """R(centre - half_width, centre + half_width); ``half_width > 0``."""
        if not half_width > 0:
            msg = f"Rectangular half_width must be > 0, got {half_width!r}"
            raise ConfigError(msg)
        return cls(centre - half_width, centre + half_width)

    @property
    def expectation(self) -> float:
        return 0.5 * (self.low + self.high)

    @property
    def standard_uncertainty(self) -> float:
        return (self.high - self.low) / (2.0 * math.sqrt(3.0))

    def sample(self, rng: np.random.Generator, n: int) -> NDArray[np.float64]:
        """Draw ``n`` values, shape (n,)."""
        # numpy's uniform(low, high) is low + (high - low) u, u the generator's next double;
        # one fill of u then those two operations in place give the same values, bit for bit,
        # and leave the stream where uniform leaves it (numpy 2's uniform fills slower).
        values = rng.random(_check_n(n))
        values *= self.high - self.low
        values += self.low
        return values


@dataclass(frozen=True)
class Triangular(_Scalar):
    """Triangular T(low, high, mode) (JCGM 101 §6.4.5 for the symmetric case).

    Parameters
    ----------
    low, high : float
        Limits, ``low < high``, in the quantity's unit.
    mode : float or None
        Peak, ``low <= mode <= high``; None means the midpoint (symmetric).
    """

    low: float
    high: float
    mode: float | None = None

    def __post_init__(self) -> None:
        _check_limits("Triangular", self.low, self.high)
        if self.mode is not None:
            _finite("Triangular.mode", self.mode)
            if not self.low <= self.mode <= self.high:
                msg = f"Triangular.mode must lie in [{self.low!r}, {self.high!r}], got {self.mode!r}"
                raise ConfigError(msg)

    @property
    def peak(self) -> float:
        """The mode actually used (midpoint when ``mode`` is None)."""
        return 0.5 * (self.low + self.high) if self.mode is None else float(self.mode)

    @property
    def expectation(self) -> float:
        return (self.low + self.high + self.peak) / 3.0

    @property
    def standard_uncertainty(self) -> float:
        a, b, c = self.low, self.high, self.peak
        return math.sqrt((a * a + b * b + c * c - a * b - a * c - b * c) / 18.0)

    def sample(self, rng: np.random.Generator, n: int) -> NDArray[np.float64]:
        """Draw ``n`` values, shape (n,)."""
        return rng.triangular(self.low, self.peak, self.high, _check_n(n))


@dataclass(frozen=True)
class Arcsine(_Scalar):
    """U-shaped arc sine distribution U(low, high) (JCGM 101 §6.4.6).

    Sampled as ``(a+b)/2 + (b-a)/2 sin(Φ)``, Φ ~ R(0, 2π) (§6.4.6.4); its standard
    uncertainty is the half-width over √2.

    Parameters
    ----------
    low, high : float
        Limits, ``low < high``, in the quantity's unit.
    """

    low: float
    high: float

    def __post_init__(self) -> None:
        _check_limits("Arcsine", self.low, self.high)

    @property
    def expectation(self) -> float:
        return 0.5 * (self.low + self.high)

    @property
    def standard_uncertainty(self) -> float:
        return 0.5 * (self.high - self.low) / math.sqrt(2.0)

    def sample(self, rng: np.random.Generator, n: int) -> NDArray[np.float64]:
        """Draw ``n`` values, shape (n,)."""
        phi = rng.uniform(0.0, 2.0 * math.pi, _check_n(n))
        return self.expectation + 0.5 * (self.high - self.low) * np.sin(phi)


@dataclass(frozen=True)
class StudentT(_Scalar):
    """Scaled and shifted t distribution t_ν(mean, scale²) (JCGM 101 §6.4.9).

    For a Type A input from ``n`` indications, ``mean`` is their average, ``scale``
    is ``s/√n`` and ``dof = n - 1``. The expectation is ``mean`` (strictly defined
    only for ``dof > 1``); the standard uncertainty is ``scale·sqrt(ν/(ν-2))`` for
    ``dof > 2`` and infinite otherwise (§6.4.9.4). The GUM propagation instead uses
    ``scale`` with ``dof`` degrees of freedom, as the GUM does for Type A inputs.

    Parameters
    ----------
    mean : float
        Location, in the quantity's unit.
    scale : float
        Scale parameter (>= 0), in the quantity's unit.
    dof : float
        Degrees of freedom (> 0).
    """

    mean: float
    scale: float
    dof: float

    def __post_init__(self) -> None:
        _finite("StudentT.mean", self.mean)
        _finite("StudentT.scale", self.scale)
        if self.scale < 0:
            msg = f"StudentT.scale must be >= 0, got {self.scale!r}"
            raise ConfigError(msg)
        if not (math.isfinite(float(self.dof)) and self.dof > 0):
            msg = f"StudentT.dof must be finite and > 0, got {self.dof!r}"
            raise ConfigError(msg)

    @property
    def expectation(self) -> float:
        return float(self.mean)

    @property
    def standard_uncertainty(self) -> float:
        if self.dof <= 2:
            return math.inf
        return self.scale * math.sqrt(self.dof / (self.dof - 2.0))

    def sample(self, rng: np.random.Generator, n: int) -> NDArray[np.float64]:
        """Draw ``n`` values, shape (n,)."""
        return self.mean + self.scale * rng.standard_t(self.dof, _check_n(n))


@dataclass(frozen=True)
class CurvilinearTrapezoid(_Scalar):
    """Rectangular distribution with inexactly known limits (JCGM 101 §6.4.3).

    Each limit is only known to lie within ± ``half_width_of_limits`` (d) of its
    stated value. Sampled per §6.4.3.4: ``a_s = (a - d) + 2d r1``, ``b_s = a + b - a_s``,
    ``x = a_s + (b_s - a_s) r2``. Expectation ``(a+b)/2``, variance
    ``(b-a)²/12 + d²/9``.

    Parameters
    ----------
    low, high : float
        Stated limits a < b, in the quantity's unit.
    half_width_of_limits : float
        d, with ``0 <= d <= (b - a)/2``, in the quantity's unit.
    """

    low: float
    high: float
    half_width_of_limits: float

    def __post_init__(self) -> None:
        _check_limits("CurvilinearTrapezoid", self.low, self.high)
        d = _finite("CurvilinearTrapezoid.half_width_of_limits", self.half_width_of_limits)
        if not 0 <= d <= 0.5 * (self.high - self.low):
            msg = (
                "CurvilinearTrapezoid.half_width_of_limits must lie in "
                f"[0, {0.5 * (self.high - self.low)!r}], got {d!r}"
            )
            raise ConfigError(msg)

    @property
    def expectation(self) -> float:
        return 0.5 * (self.low + self.high)

    @property
    def standard_uncertainty(self) -> float:
        width = self.high - self.low
        d = self.half_width_of_limits
        return math.sqrt(width * width / 12.0 + d * d / 9.0)

    def sample(self, rng: np.random.Generator, n: int) -> NDArray[np.float64]:
        """Draw ``n`` values, shape (n,)."""
        r = rng.random((_check_n(n), 2))
        d = self.half_width_of_limits
        a_s = (self.low - d) + 2.0 * d * r[:, 0]
        b_s = (self.low + self.high) - a_s
        return a_s + (b_s - a_s) * r[:, 1]


def _readonly(array: NDArray[np.float64]) -> NDArray[np.float64]:
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class CorrelatedNormal:
    """Multivariate Gaussian N(mean, covariance) (JCGM 101 §6.4.8).

    Sampled as ``mean + z Lᵀ`` with ``L Lᵀ = covariance``: the Cholesky factor, or,
    for a positive semidefinite but singular covariance (where Cholesky fails), the
    symmetric factor ``V sqrt(Λ)`` from ``eigh``.

    Parameters
    ----------
    mean : array_like, shape (k,)
        Expectation, in the quantities' units.
    covariance : array_like, shape (k, k)
        Symmetric positive semidefinite covariance, in products of those units.
    """

    mean: NDArray[np.float64]
    covariance_matrix: NDArray[np.float64]
    factor: NDArray[np.float64] = field(init=False, repr=False)

    def __init__(self, mean: ArrayLike, covariance: ArrayLike) -> None:
        mu = np.array(mean, dtype=np.float64)
        cov = np.array(covariance, dtype=np.float64)
        if mu.ndim != 1 or mu.shape[0] < 1:
            msg = f"CorrelatedNormal.mean must have shape (k,), got {mu.shape}"
            raise ConfigError(msg)
        k = mu.shape[0]
        if cov.shape != (k, k):
            msg = f"CorrelatedNormal.covariance must have shape ({k}, {k}), got {cov.shape}"
            raise ConfigError(msg)
        if not (np.isfinite(mu).all() and np.isfinite(cov).all()):
            msg = "CorrelatedNormal.mean and covariance must be finite, got NaN or inf"
            raise ConfigError(msg)
        scale = max(float(np.max(np.abs(cov))), np.finfo(np.float64).tiny)
        if not np.allclose(cov, cov.T, rtol=0.0, atol=1e-12 * scale):
            msg = "CorrelatedNormal.covariance must be symmetric, got an asymmetric matrix"
            raise ConfigError(msg)
        cov = 0.5 * (cov + cov.T)
        eigenvalues, eigenvectors = np.linalg.eigh(cov)
        # Round-off makes exact zero eigenvalues slightly negative; tolerate that much.
        if eigenvalues[0] < -1e-10 * scale:
            msg = (
                "CorrelatedNormal.covariance must be positive semidefinite, "
                f"got smallest eigenvalue {eigenvalues[0]:.3g}"
            )
            raise ConfigError(msg)
        try:
            factor = np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            factor = eigenvectors * np.sqrt(np.clip(eigenvalues, 0.0, None))
        object.__setattr__(self, "mean", _readonly(mu))
        object.__setattr__(self, "covariance_matrix", _readonly(cov))
        object.__setattr__(self, "factor", _readonly(np.ascontiguousarray(factor)))

    @property
    def size(self) -> int:
        return int(self.mean.shape[0])

    @property
    def expectation(self) -> NDArray[np.float64]:
        """Expectation, shape (k,)."""
        return self.mean

    @property
    def standard_uncertainty(self) -> NDArray[np.float64]:
        """Standard uncertainties, shape (k,)."""
        return np.sqrt(np.diag(self.covariance_matrix))

    def mean_vector(self) -> NDArray[np.float64]:
        return self.mean.copy()

    def covariance(self) -> NDArray[np.float64]:
        return self.covariance_matrix.copy()

    def sample(self, rng: np.random.Generator, n: int) -> NDArray[np.float64]:
        """Draw ``n`` vectors, shape (n, k)."""
        z = rng.standard_normal((_check_n(n), self.size))
        return self.mean + z @ self.factor.T


@dataclass(frozen=True, eq=False)
class Empirical:
    """Resampling with replacement from given values (e.g. a previous Monte Carlo run).

    The distribution is the discrete one putting mass 1/M on each row, so its
    expectation is the row mean and its covariance the population (ddof=0) one.

    Parameters
    ----------
    samples : array_like, shape (M,) or (M, k)
        Values in the quantities' units, M >= 1, all finite.
    """

    samples: NDArray[np.float64]

    def __init__(self, samples: ArrayLike) -> None:
        values = np.array(samples, dtype=np.float64)
        if values.ndim not in (1, 2) or values.shape[0] < 1 or values.size == 0:
            msg = f"Empirical.samples must have shape (M,) or (M, k) with M >= 1, got {values.shape}"
            raise ConfigError(msg)
        if not np.isfinite(values).all():
            count = int((~np.isfinite(values)).sum())
            msg = f"Empirical.samples must be finite, got {count} NaN/inf values"
            raise ConfigError(msg)
        object.__setattr__(self, "samples", _readonly(values))

    @property
    def size(self) -> int:
        return 1 if self.samples.ndim == 1 else int(self.samples.shape[1])

    @property
    def expectation(self) -> float | NDArray[np.float64]:
        """Row mean: float for 1-D samples, else shape (k,)."""
        mean = self.samples.mean(axis=0)
        return float(mean) if self.samples.ndim == 1 else mean

    @property
    def standard_uncertainty(self) -> float | NDArray[np.float64]:
        """Population standard deviation: float for 1-D samples, else shape (k,)."""
        std = self.samples.std(axis=0)
        return float(std) if self.samples.ndim == 1 else std

    def mean_vector(self) -> NDArray[np.float64]:
        return np.atleast_1d(self.samples.mean(axis=0)).astype(np.float64)

    def covariance(self) -> NDArray[np.float64]:
        columns = self.samples.reshape(self.samples.shape[0], -1)
        centred = columns - columns.mean(axis=0)
        return np.asarray(centred.T @ centred / columns.shape[0], dtype=np.float64)

    def sample(self, rng: np.random.Generator, n: int) -> NDArray[np.float64]:
        """Draw ``n`` rows with replacement: shape (n,) or (n, k)."""
        index = rng.integers(0, self.samples.shape[0], _check_n(n))
        # take: the same rows as self.samples[index], gathered 2-3 times faster.
        return np.take(self.samples, index, axis=0)


def _drawn_components(widths: NDArray[np.float64]) -> NDArray[np.intp] | None:
    """Indices of the components with a non-zero width, or None where every one has one (the
    vector is then drawn whole, as before constant components were skipped)."""
    drawn = np.flatnonzero(widths > 0.0)
    if drawn.size == widths.size:
        return None
    drawn.setflags(write=False)
    return drawn


def _scatter(
    values: NDArray[np.float64], drawn: NDArray[np.intp], constants: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Vectors of ``constants`` with the drawn components' ``values`` put in, shape (n, k)."""
    out = np.empty((values.shape[0], constants.size))
    out[...] = constants
    out[:, drawn] = values
    return out


@dataclass(frozen=True, eq=False)
class IndependentRectangular:
    """Independent rectangular components R(centre_i - a_i, centre_i + a_i), as a vector.

    A laser tracker's MPE a + b L gives every measured coordinate its own half-width, so
    one vector input with per-component half-widths replaces thousands of scalar inputs.

    Parameters
    ----------
    half_widths : array_like, shape (k,)
        Half-widths a_i >= 0, in the quantities' units (0 makes a component constant).
    centres : array_like, shape (k,), optional
        Centres, default 0 (zero-mean errors).
    """

    half_widths: NDArray[np.float64]
    centres: NDArray[np.float64]
    _drawn: NDArray[np.intp] | None = field(default=None, init=False, repr=False, compare=False)

    def __init__(self, half_widths: ArrayLike, centres: ArrayLike | None = None) -> None:
        a = np.array(half_widths, dtype=np.float64).reshape(-1)
        c = np.zeros_like(a) if centres is None else np.array(centres, dtype=np.float64).reshape(-1)
        if a.size < 1 or c.shape != a.shape:
            msg = f"IndependentRectangular needs k >= 1 half-widths and as many centres, got {a.size} and {c.size}"
            raise ConfigError(msg)
        if not (np.isfinite(a).all() and np.isfinite(c).all()) or (a < 0).any():
            msg = "IndependentRectangular half-widths must be finite and >= 0, centres finite"
            raise ConfigError(msg)
        object.__setattr__(self, "half_widths", _readonly(a))
        object.__setattr__(self, "centres", _readonly(c))
        object.__setattr__(self, "_drawn", _drawn_components(a))

    @property
    def size(self) -> int:
        return int(self.half_widths.size)

    def mean_vector(self) -> NDArray[np.float64]:
        return self.centres.copy()

    def variance_vector(self) -> NDArray[np.float64]:
        """Variances a_i^2 / 3, shape (k,): the covariance is diagonal."""
        return np.asarray(self.half_widths**2 / 3.0, dtype=np.float64)

    def covariance(self) -> NDArray[np.float64]:
        return np.diag(self.variance_vector())

    def sample(self, rng: np.random.Generator, n: int) -> NDArray[np.float64]:
        """Draw ``n`` vectors, shape (n, k)."""
        # In place: the same operations (u a + c) without two temporaries of the draw's size.
        # uniform(-1, 1) is -1 + 2 u: the fill of u, then 2 u - 1 (the same values, see Rectangular).
        drawn = self._drawn
        if drawn is None:
            values = rng.random(size=(_check_n(n), self.size))
            values *= 2.0
            values -= 1.0
            values *= self.half_widths
            values += self.centres
            return values
        # Constant components (half-width 0) take no draw: a 6-DOF measurement's position noise
        # is zero in its rotation coordinates, half of the vector.
        u = rng.random(size=(_check_n(n), drawn.size))
        u *= 2.0
        u -= 1.0
        u *= self.half_widths[drawn]
        u += self.centres[drawn]
        return _scatter(u, drawn, self.centres)


@dataclass(frozen=True, eq=False)
class IndependentNormal:
    """Independent normal components N(mean_i, std_i^2), as a vector.

    A diagonal :class:`CorrelatedNormal` without its k x k factor: the orientation noise of
    every pose of a 6-DOF campaign (thousands of components) would otherwise need a dense
    Cholesky (or eigen) factor and a dense product per draw; the distribution is that of
    ``CorrelatedNormal(mean, diag(std**2))``.

    Parameters
    ----------
    std : array_like, shape (k,)
        Standard deviations std_i >= 0, in the quantities' units (0 makes a component constant).
    mean : array_like, shape (k,), optional
        Expectations, default 0.
    """

    std: NDArray[np.float64]
    mean: NDArray[np.float64]
    _drawn: NDArray[np.intp] | None = field(default=None, init=False, repr=False, compare=False)

    def __init__(self, std: ArrayLike, mean: ArrayLike | None = None) -> None:
        s = np.array(std, dtype=np.float64).reshape(-1)
        m = np.zeros_like(s) if mean is None else np.array(mean, dtype=np.float64).reshape(-1)
        if s.size < 1 or m.shape != s.shape:
            msg = f"IndependentNormal needs k >= 1 standard deviations and as many means, got {s.size} and {m.size}"
            raise ConfigError(msg)
        if not (np.isfinite(s).all() and np.isfinite(m).all()) or (s < 0).any():
            msg = "IndependentNormal standard deviations must be finite and >= 0, means finite"
            raise ConfigError(msg)
        object.__setattr__(self, "std", _readonly(s))
        object.__setattr__(self, "mean", _readonly(m))
        object.__setattr__(self, "_drawn", _drawn_components(s))

    @property
    def size(self) -> int:
        return int(self.std.size)

    def mean_vector(self) -> NDArray[np.float64]:
        return self.mean.copy()

    def variance_vector(self) -> NDArray[np.float64]:
        """Variances std_i^2, shape (k,): the covariance is diagonal."""
        return np.asarray(self.std**2, dtype=np.float64)

    def covariance(self) -> NDArray[np.float64]:
        return np.diag(self.variance_vector())

    def sample(self, rng: np.random.Generator, n: int) -> NDArray[np.float64]:
        """Draw ``n`` vectors, shape (n, k)."""
        # In place: the same operations (z s + m) without two temporaries of the draw's size.
        drawn = self._drawn
        if drawn is None:
            values = rng.standard_normal((_check_n(n), self.size))
            values *= self.std
            values += self.mean
            return values
        # Constant components (std 0) take no draw: a 6-DOF measurement's orientation noise is
        # zero in its position coordinates, half of the vector.
        z = rng.standard_normal((_check_n(n), drawn.size))
        z *= self.std[drawn]
        z += self.mean[drawn]
        return _scatter(z, drawn, self.mean)


@dataclass(frozen=True, eq=False)
class IndependentCopies:
    """``count`` independent copies of one distribution, concatenated into one vector.

    E.g. the encoder error of every joint reading of every pose, or a model error
    resampled independently for every pose.

    Parameters
    ----------
    distribution : Distribution
        The distribution of one copy (size m).
    count : int
        Number of copies, >= 1; the vector has size ``count * m``, copy-major.
    """

    distribution: Distribution
    count: int

    def __post_init__(self) -> None:
        if not isinstance(self.distribution, Distribution):
            msg = f"IndependentCopies.distribution must be a Distribution, got {type(self.distribution).__name__}"
            raise ConfigError(msg)
        if isinstance(self.count, bool) or not isinstance(self.count, (int, np.integer)) or self.count < 1:
            msg = f"IndependentCopies.count must be an integer >= 1, got {self.count!r}"
            raise ConfigError(msg)

    @property
    def size(self) -> int:
        return int(self.count) * int(self.distribution.size)

    def mean_vector(self) -> NDArray[np.float64]:
        return np.tile(self.distribution.mean_vector(), int(self.count))

    def block_covariance(self) -> NDArray[np.float64]:
        """Covariance of one copy, shape (m, m); the full covariance is block diagonal."""
        return self.distribution.covariance()

    def covariance(self) -> NDArray[np.float64]:
        return np.asarray(np.kron(np.eye(int(self.count)), self.block_covariance()), dtype=np.float64)

    def sample(self, rng: np.random.Generator, n: int) -> NDArray[np.float64]:
        """Draw ``n`` vectors, shape (n, count * m)."""
        rows = _check_n(n)
        return np.asarray(self.distribution.sample(rng, rows * int(self.count)), dtype=np.float64).reshape(
            rows, self.size
        )
