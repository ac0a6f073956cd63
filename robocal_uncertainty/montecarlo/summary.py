"""Summaries of Monte Carlo model values (JCGM 101 §7.6-§7.7, §7.9.2).

Coverage intervals use the discrete order-statistic rules of JCGM 101 rather than
interpolated quantiles, so results can be compared digit for digit with the Supplement:
with ``q = floor(pM + 1/2)``, the probabilistically symmetric interval is
``[y_(r), y_(r+q)]`` with ``r = ceil((M - q)/2)`` (§7.7.1) and the shortest interval is
the ``[y_(r), y_(r+q)]`` of least width over ``r = 1..M-q`` (§7.7.2), 1-based.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal_uncertainty.errors import ConfigError, InputError

__all__ = [
    "CoverageInterval",
    "Histogram",
    "IntervalKind",
    "MonteCarloIntervalKind",
    "OutputSummary",
    "Summary",
    "check_coverage",
    "coverage_bounds",
    "coverage_window",
    "minimum_trials",
    "numerical_tolerance",
    "summarize",
]

MonteCarloIntervalKind = Literal["probabilistically_symmetric", "shortest"]
"""Coverage intervals computed from Monte Carlo samples."""

IntervalKind = Literal["probabilistically_symmetric", "shortest", "gum"]
"""``gum``: the GUM interval ``y ± k u_c`` (see :mod:`.gum`)."""

_MC_KINDS: tuple[str, ...] = ("probabilistically_symmetric", "shortest")


@dataclass(frozen=True)
class CoverageInterval:
    """A coverage interval for one output component.

    Attributes
    ----------
    low, high : float
        Endpoints, in the output's unit.
    kind : IntervalKind
        How the interval was chosen.
    coverage_probability : float
        Nominal coverage probability p, in (0, 1).
    """

    low: float
    high: float
    kind: IntervalKind
    coverage_probability: float

    @property
    def width(self) -> float:
        """``high - low``, in the output's unit."""
        return self.high - self.low

    @property
    def half_width(self) -> float:
        """``(high - low)/2``, in the output's unit."""
        return 0.5 * (self.high - self.low)

    def contains(self, value: float) -> bool:
        """Whether ``low <= value <= high``."""
        return self.low <= value <= self.high


@dataclass(frozen=True, eq=False)
class Histogram:
    """Histogram of one output component's model values.

    Attributes
    ----------
    counts : ndarray, shape (bins,)
        Number of model values in each bin.
    edges : ndarray, shape (bins + 1,)
        Bin edges, in the output's unit.
    """

    counts: NDArray[np.int64]
    edges: NDArray[np.float64]

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Histogram):
            return NotImplemented
        return bool(np.array_equal(self.counts, other.counts) and np.array_equal(self.edges, other.edges))

    __hash__ = None  # type: ignore[assignment]  # equal histograms need not hash alike


@dataclass(frozen=True)
class OutputSummary:
    """JCGM 101 §7.6-7.7 summary of one output component.

    Attributes
    ----------
    estimate : float
        y, the mean of the model values, in the output's unit.
    standard_uncertainty : float
        u(y), their standard deviation (ddof=1), in the output's unit.
    probabilistically_symmetric : CoverageInterval
        Interval with probability (1-p)/2 on each side (§7.7.1).
    shortest : CoverageInterval
        Shortest interval of probability p (§7.7.2).
    expanded_from : {"probabilistically_symmetric", "shortest"}
        Which interval defines the expanded uncertainty.
    expanded_uncertainty : float
        U_p, half-width of that interval, in the output's unit.
    coverage_factor : float or None
        k_p = U_p / u(y); None when u(y) == 0.
    relative_expanded_uncertainty : float or None
        U_p / |y| (dimensionless); None when y == 0.
    histogram : Histogram
        Distribution of the model values.
    n_trials : int
        Number of model values M.
    """

    estimate: float
    standard_uncertainty: float
    probabilistically_symmetric: CoverageInterval
    shortest: CoverageInterval
    expanded_from: MonteCarloIntervalKind
    expanded_uncertainty: float
    coverage_factor: float | None
    relative_expanded_uncertainty: float | None
    histogram: Histogram
    n_trials: int

    @property
    def interval(self) -> CoverageInterval:
        """The interval named by ``expanded_from``."""
        if self.expanded_from == "shortest":
            return self.shortest
        return self.probabilistically_symmetric


@dataclass(frozen=True, eq=False)
class Summary:
    """Summary of all output components of a Monte Carlo run.

    Attributes
    ----------
    outputs : tuple of OutputSummary, length n_out
        One summary per output component, in column order.
    covariance : ndarray, shape (n_out, n_out)
        Sample covariance (ddof=1) of the outputs, in products of their units.
    coverage_probability : float
        p used for every interval.
    n_trials : int
        Number of model values M.
    """

    outputs: tuple[OutputSummary, ...]
    covariance: NDArray[np.float64]
    coverage_probability: float
    n_trials: int

    @property
    def correlation(self) -> NDArray[np.float64]:
        """Correlation matrix, shape (n_out, n_out); NaN rows for constant outputs."""
        std = np.sqrt(np.diag(self.covariance))
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.asarray(self.covariance / np.outer(std, std), dtype=np.float64)


def check_coverage(coverage: float, name: str = "coverage") -> float:
    """Return ``coverage`` as a float, raising ConfigError unless 0 < coverage < 1."""
    value = float(coverage)
    if not 0.0 < value < 1.0:
        msg = f"{name} must lie strictly between 0 and 1, got {coverage!r}"
        raise ConfigError(msg)
    return value


def minimum_trials(coverage: float) -> int:
    """J = ceil(100/(1-p)), the smallest M JCGM 101 §7.2.2 accepts for coverage p."""
    p = check_coverage(coverage)
    # Round-off in 1 - p can lift an exact integer ratio just above it (2000 -> 2001).
    return math.ceil(100.0 / (1.0 - p) - 1e-9)


def numerical_tolerance(standard_uncertainty: float, n_dig: int) -> float:
    """Numerical tolerance δ of a standard uncertainty (JCGM 101 §7.9.2).

    Writes ``u = c × 10^l`` with ``c`` an ``n_dig``-digit integer and returns
    ``δ = 10^l / 2``; e.g. u = 0.0539 with n_dig = 2 gives δ = 0.0005.

    Parameters
    ----------
    standard_uncertainty : float
        u >= 0, in the output's unit; u == 0 gives δ = 0.
    n_dig : int
        Number of significant decimal digits regarded as meaningful (>= 1).

    Returns
    -------
    float
        δ, in the output's unit.
    """
    if isinstance(n_dig, bool) or not isinstance(n_dig, (int, np.integer)) or n_dig < 1:
        msg = f"n_dig must be an integer >= 1, got {n_dig!r}"
        raise ConfigError(msg)
    u = float(standard_uncertainty)
    if not (math.isfinite(u) and u >= 0):
        msg = f"standard_uncertainty must be finite and >= 0, got {standard_uncertainty!r}"
        raise InputError(msg)
    if u == 0.0:
        return 0.0
    exponent = math.floor(math.log10(u)) - int(n_dig) + 1
    # Rounding c to n_dig digits can carry into one more digit (0.0999 -> 100e-3).
    if round(u / 10.0**exponent) >= 10 ** int(n_dig):
        exponent += 1
    return 0.5 * 10.0**exponent


def _as_columns(samples: ArrayLike) -> NDArray[np.float64]:
    values = np.asarray(samples, dtype=np.float64)
    if values.ndim == 1:
        values = values[:, np.newaxis]
    if values.ndim != 2 or values.shape[1] < 1:
        msg = f"samples must have shape (M,) or (M, n_out), got {np.shape(samples)}"
        raise InputError(msg)
    bad = ~np.isfinite(values)
    if bad.any():
        msg = f"samples contain {int(bad.sum())} NaN/inf values; they must not be averaged"
        raise InputError(msg)
    return values


def coverage_window(n_trials: int, coverage: float) -> int:
    """q = floor(pM + 1/2), the number of steps an interval spans (JCGM 101 §7.7)."""
    q = math.floor(coverage * n_trials + 0.5)
    if q >= n_trials or q < 1:
        needed = max(math.ceil(0.5 / (1.0 - coverage)), 2)
        while math.floor(coverage * needed + 0.5) >= needed:
            needed += 1
        msg = (
            f"samples must have at least {needed} trials for coverage {coverage} "
            f"(JCGM 101 recommends {minimum_trials(coverage)}), got {n_trials}"
        )
        raise InputError(msg)
    return q


def coverage_bounds(
    sorted_samples: NDArray[np.float64], coverage: float, kind: MonteCarloIntervalKind
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Endpoints of a JCGM 101 coverage interval from sorted model values.

    Parameters
    ----------
    sorted_samples : ndarray, shape (M, n_out)
        Model values sorted along axis 0, in the outputs' units.
    coverage : float
        p, in (0, 1).
    kind : {"probabilistically_symmetric", "shortest"}
        Which interval (§7.7.1 or §7.7.2).

    Returns
    -------
    low, high : ndarray, shape (n_out,)
        Endpoints, in the outputs' units.
    """
    p = check_coverage(coverage)
    if kind not in _MC_KINDS:
        msg = f"kind must be one of {_MC_KINDS}, got {kind!r}"
        raise ConfigError(msg)
    m = sorted_samples.shape[0]
    q = coverage_window(m, p)
    if kind == "probabilistically_symmetric":
        r = math.ceil((m - q) / 2)  # 1-based, per §7.7.1
        return sorted_samples[r - 1].copy(), sorted_samples[r - 1 + q].copy()
    widths = sorted_samples[q:] - sorted_samples[: m - q]
    start = np.argmin(widths, axis=0)
    columns = np.arange(sorted_samples.shape[1])
    return sorted_samples[start, columns], sorted_samples[start + q, columns]


def summarize(
    samples: ArrayLike,
    coverage: float = 0.95,
    *,
    bins: int | str = 100,
    expanded_from: MonteCarloIntervalKind = "probabilistically_symmetric",
) -> Summary:
    """Estimate, standard uncertainty, coverage intervals and histogram of model values.

    Parameters
    ----------
    samples : array_like, shape (M,) or (M, n_out)
        Finite model values, in the outputs' units; M must exceed q = floor(pM + 1/2)
        (M >= 11 at p = 0.95); JCGM 101 asks for M >= J = ceil(100/(1-p)).
    coverage : float
        Coverage probability p, in (0, 1).
    bins : int or str
        Histogram bins, as for :func:`numpy.histogram`.
    expanded_from : {"probabilistically_symmetric", "shortest"}
        Interval whose half-width is reported as the expanded uncertainty.

    Returns
    -------
    Summary
        One :class:`OutputSummary` per column and the covariance matrix.
    """
    p = check_coverage(coverage)
    if expanded_from not in _MC_KINDS:
        msg = f"expanded_from must be one of {_MC_KINDS}, got {expanded_from!r}"
        raise ConfigError(msg)
    if isinstance(bins, bool) or (isinstance(bins, (int, np.integer)) and bins < 1):
        msg = f"bins must be a positive integer or a numpy bin rule, got {bins!r}"
        raise ConfigError(msg)
    values = _as_columns(samples)
    m, n_out = values.shape
    coverage_window(m, p)
    ordered = np.sort(values, axis=0)
    sym_low, sym_high = coverage_bounds(ordered, p, "probabilistically_symmetric")
    short_low, short_high = coverage_bounds(ordered, p, "shortest")
    means = values.mean(axis=0)
    covariance = np.atleast_2d(np.cov(values, rowvar=False, ddof=1))
    stds = np.sqrt(np.diag(covariance))
    outputs = []
    for j in range(n_out):
        symmetric = CoverageInterval(float(sym_low[j]), float(sym_high[j]), "probabilistically_symmetric", p)
        shortest = CoverageInterval(float(short_low[j]), float(short_high[j]), "shortest", p)
        chosen = shortest if expanded_from == "shortest" else symmetric
        estimate, u = float(means[j]), float(stds[j])
        expanded = chosen.half_width
        column = values[:, j]
        lo, hi = float(column.min()), float(column.max())
        if isinstance(bins, int) and hi - lo <= 8 * bins * np.spacing(max(abs(lo), abs(hi), np.finfo(float).tiny)):
            # A (nearly) constant output, e.g. a source that contributes nothing: one bin.
            counts, edges = np.histogram(column, bins=1, range=(lo, hi) if hi > lo else (lo - 0.5, lo + 0.5))
        else:
            counts, edges = np.histogram(column, bins=bins)
        outputs.append(
            OutputSummary(
                estimate=estimate,
                standard_uncertainty=u,
                probabilistically_symmetric=symmetric,
                shortest=shortest,
                expanded_from=expanded_from,
                expanded_uncertainty=expanded,
                coverage_factor=expanded / u if u > 0 else None,
                relative_expanded_uncertainty=expanded / abs(estimate) if estimate != 0 else None,
                histogram=Histogram(counts.astype(np.int64), edges.astype(np.float64)),
                n_trials=m,
            )
        )
    covariance.setflags(write=False)
    return Summary(tuple(outputs), covariance, p, m)
