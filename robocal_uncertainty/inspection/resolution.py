"""Max/min intervals honest about what one scan cannot resolve.

Why
---
A profile deviation is max minus min of the normal deviations over a region. Its noise bias
``E[f(x + e)] - f(x)`` depends on the true form ``x``: a broad extreme (a smooth form) has many
points near the maximum and a large bias; a narrow bump or dent has few and a small one. Method
``denoised`` samples the error around the denoised cloud x̂, so its bias is that of x̂'s form.
Where the smoother flattened a local feature of a few micrometres over a few millimetres that
the noise hides from the residual check, x̂ has a broader extreme than the truth, the sampled
bias is too large and the interval lies below the truth; where narrow windows kept some noise
in x̂, x̂ is rougher than the truth and the interval lies above it. Over simulated parts with one
such feature the side-profile intervals held the truth in 81-88 % of the scans the check did
not flag. The maximum thickness (a maximum over pressure-side points of a minimum over the
suction side) and the chord (a maximum over point pairs) are max/min parameters too: a bump or
dent the check misses on a side changed the thickness bias the same way (its interval held the
truth in 90.4 % of the unflagged ``side`` scans).

Model
-----
The scan does not tell how rough the true form is between two limits: the smoothest form the
data support, the fit of the one window Mallows' Cp chooses for the whole contour (no local
narrowing, no twicing), and the roughest, the measured deviations themselves (every extreme a
single point, the smallest bias any form can give). The stated 95 % interval of a max/min
parameter (:data:`ENVELOPE_PARAMETERS`) is the union of the intervals at the denoised cloud and
at these two limits:

``low = min(low_MC, f(y) - q97.5(Δ_smooth))``, ``high = max(high_MC, f(y) - q2.5(Δ_rough))``,

``Δ_c = P(c + e') - P(c)``, ``c`` the points moved along their normals to the limit's
deviations, segmentation and registration frozen at the measured cloud (as the batched model
freezes them), ``e'`` the instrument's sources (:data:`ENVELOPE_DRAWS` draws, seeded). ``P`` is
the profile (max - min per region; the per-point sources along the normals, the ``common``
ones, a smooth scale error, left out: they barely change a profile), or the thickness and chord
of :class:`~.frozen_model.FrozenSectionModel` (every source, the 2-D displacements: a scale error
changes a length). The interval is asymmetric and wider than the denoised Monte Carlo's; it is a
coverage interval under the stated model (the true roughness somewhere between the two limits)
and over-covers a part whose form is as smooth as the smooth limit, which the coverage study
reports.

The smooth limit's own fit noise (standard deviation ``s_i`` per point) stands out at its
extremes: over a plateau of the true form (an eroded edge flattened to a line) the fit's maximum
is one noisy point above its neighbours, so the sampled noise bias is that of a narrow extreme,
too small, and the lower limit lay above the truth (suction-side profile, erosion family: 91.5 %
of the unflagged scans). For the profiles the smooth limit is therefore taken flat wherever it
lies within ``PLATEAU_FACTOR·s_i`` of its region's maximum or minimum: points the fit cannot tell
from the extreme count as extreme. One standard deviation, fixed before the family rerun; it
widens the profile intervals downwards only where the fit is flat to within its noise.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal_uncertainty.core.instruments.cmm import ErrorSource
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.inspection.frozen_model import build_frozen_model
from robocal_uncertainty.inspection.section import (
    PARAMETER_NAMES,
    SectionEvaluation,
    chord_length,
    max_thickness,
    profile_deviations,
)
from robocal_uncertainty.inspection.segmentation import PRESSURE_SIDE, SUCTION_SIDE

__all__ = [
    "ENVELOPE_DRAWS",
    "ENVELOPE_PARAMETERS",
    "ENVELOPE_STREAM",
    "PLATEAU_FACTOR",
    "PROFILE_PARAMETERS",
    "ResolutionEnvelope",
    "plateau_extremes",
    "resolution_envelope",
]

PROFILE_PARAMETERS: tuple[str, ...] = tuple(name for name in PARAMETER_NAMES if name.startswith("profile"))
"""The four profile parameters (leading edge, trailing edge, pressure side, suction side)."""

ENVELOPE_PARAMETERS: tuple[str, ...] = ("max_thickness", "chord_length", *PROFILE_PARAMETERS)
"""The max/min parameters the envelope widens, in the order of the envelope's arrays."""

ENVELOPE_DRAWS = 2000
"""Draws of the instrument's sources for the quantiles at the two roughness limits."""

ENVELOPE_STREAM = 2**32 - 23
"""Spawn key of the envelope's draws under the Monte Carlo's root seed: ``SeedSequence(seed,
spawn_key=(ENVELOPE_STREAM,))``, a block index the Monte Carlo never reaches."""

PLATEAU_FACTOR = 1.0
"""Points of the smooth limit within this many of their fit's standard deviations of their
region's extreme are taken at the extreme, for the profiles (see the module docstring)."""

_BATCH = 500


@dataclass(frozen=True)
class ResolutionEnvelope:
    """Error quantiles of the max/min parameters at the smoothest and the roughest form the scan supports.

    Attributes
    ----------
    measured : ndarray, shape (6,) [m]
        The parameters of the measured cloud ``f(y)`` (:data:`ENVELOPE_PARAMETERS` order).
    smooth_high : ndarray, shape (6,) [m]
        Upper quantile ``(1 + p)/2`` of ``Δ`` at the smooth limit (one Cp window, no twicing).
    rough_low : ndarray, shape (6,) [m]
        Lower quantile ``(1 - p)/2`` of ``Δ`` at the rough limit (the measured deviations).
    coverage_probability : float
        p.
    n_draws : int
        Draws.
    seed : int
        Root seed (draws from ``SeedSequence(seed, spawn_key=(ENVELOPE_STREAM,))``).
    plateau_factor : float
        Flattening of the smooth limit's profile extremes, in its fit's standard deviations
        (0: none, when no standard deviations were given).
    """

    measured: NDArray[np.float64]
    smooth_high: NDArray[np.float64]
    rough_low: NDArray[np.float64]
    coverage_probability: float
    n_draws: int
    seed: int
    plateau_factor: float = 0.0

    def widen(self, name: str, low: float, high: float) -> tuple[float, float]:
        """The stated interval of parameter `name` from the Monte Carlo one ``[low, high]`` [m].

        :data:`ENVELOPE_PARAMETERS`: ``[min(low, f(y) - smooth_high), max(high, f(y) - rough_low)]``;
        any other parameter is returned unchanged.
        """
        if name not in ENVELOPE_PARAMETERS:
            return low, high
        k = ENVELOPE_PARAMETERS.index(name)
        return (
            min(low, float(self.measured[k] - self.smooth_high[k])),
            max(high, float(self.measured[k] - self.rough_low[k])),
        )


def plateau_extremes(
    deviation: ArrayLike, std: ArrayLike, labels: ArrayLike, factor: float = PLATEAU_FACTOR
) -> NDArray[np.float64]:
    """Deviations with every point within ``factor·std`` of its region's maximum (minimum) set to it.

    Parameters
    ----------
    deviation : array_like, shape (n,) [m]
        Signed normal deviations (the smooth limit).
    std : array_like, shape (n,) [m]
        Standard deviation of each deviation's noise.
    labels : array_like of int, shape (n,)
        Region code per point (the profile regions).
    factor : float
        Band width in standard deviations (>= 0).

    Returns
    -------
    ndarray, shape (n,) [m]
        The flattened deviations; a region's maximum and minimum, hence its profile, unchanged.
    """
    d = np.asarray(deviation, dtype=np.float64)
    band = factor * np.asarray(std, dtype=np.float64)
    codes = np.asarray(labels)
    out = d.copy()
    for region in np.unique(codes):
        at = codes == region
        top, bottom = d[at].max(), d[at].min()
        x, b = d[at], band[at]
        # Where the bands of a nearly flat region overlap, a point goes to the nearer extreme:
        # the maximum and the minimum themselves stay where they are.
        in_top, in_bottom = x >= top - b, x <= bottom + b
        nearer_top = top - x <= x - bottom
        up = in_top & (~in_bottom | nearer_top)
        down = in_bottom & ~up
        out[np.flatnonzero(at)[up]] = top
        out[np.flatnonzero(at)[down]] = bottom
    return out


def _at_deviations(evaluation: SectionEvaluation, deviation: NDArray[np.float64]) -> SectionEvaluation:
    """The measured evaluation with its points moved along the normals to ``deviation``;
    segmentation and registration frozen, thickness and chord re-evaluated."""
    reg = evaluation.registration
    points = evaluation.points + (deviation - reg.residual)[:, np.newaxis] * reg.normal
    seg = evaluation.segmentation
    thickness = max_thickness(points[seg.indices(PRESSURE_SIDE)], points[seg.indices(SUCTION_SIDE)])
    chord, i, j = chord_length(points)
    parameters = replace(evaluation.parameters, max_thickness=thickness.value, chord_length=chord)
    return replace(
        evaluation,
        parameters=parameters,
        points=points,
        registration=replace(reg, residual=deviation),
        thickness=thickness,
        chord_points=(i, j),
    )


def _length_errors(
    evaluation: SectionEvaluation, sources: Sequence[ErrorSource], draws: Sequence[NDArray[np.float64]]
) -> NDArray[np.float64]:
    """``Δ`` of the thickness and the chord at ``evaluation``'s points, shape (T, 2) [m]."""
    model = build_frozen_model(evaluation, sources, resegment_edges=False)
    trials = draws[0].shape[0]
    out = np.empty((trials, 2))
    for start in range(0, trials, _BATCH):
        stop = min(trials, start + _BATCH)
        subset_shift = np.zeros((stop - start, model.subset.shape[0], 2))
        for source, values in zip(sources, draws):
            subset_shift += source.displacement(values[start:stop], model.subset)
        out[start:stop] = model.lengths(subset_shift)
    return out - model.base[:2]


def resolution_envelope(
    evaluation: SectionEvaluation,
    sources: Sequence[ErrorSource],
    smooth: ArrayLike,
    *,
    seed: int,
    coverage: float = 0.95,
    n_draws: int = ENVELOPE_DRAWS,
    smooth_std: ArrayLike | None = None,
    plateau_factor: float = PLATEAU_FACTOR,
) -> ResolutionEnvelope:
    """Quantiles of the max/min parameters' error at the two roughness limits (see the module docstring).

    Parameters
    ----------
    evaluation : SectionEvaluation
        Evaluation of the measured cloud (its residuals are the rough limit; its labels,
        normals and points are used).
    sources : sequence of ErrorSource
        Instrument sources at the measured points.
    smooth : array_like, shape (n,) [m]
        Normal deviations of the smooth limit, contour order.
    seed : int
        Root seed (the Monte Carlo's).
    coverage : float
        Coverage probability p in (0, 1).
    n_draws : int
        Draws (>= 100).
    smooth_std : array_like, shape (n,) [m], optional
        Standard deviation of the smooth limit's fit noise per point; None: the profile extremes
        are not flattened.
    plateau_factor : float
        :data:`PLATEAU_FACTOR` (>= 0), used with `smooth_std`.

    Returns
    -------
    ResolutionEnvelope
    """
    reg = evaluation.registration
    labels = evaluation.segmentation.labels
    rough = reg.residual
    flat, plateau, factor = _envelope_limits(evaluation, smooth, coverage, n_draws, smooth_std, plateau_factor)
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(ENVELOPE_STREAM,)))
    # Per-point sources first, then the common ones, from the one stream.
    ordered = [s for s in sources if s.kind != "common"] + [s for s in sources if s.kind == "common"]
    draws = [source.draw(rng, n_draws) for source in ordered]
    noise = np.zeros((n_draws, rough.shape[0]))
    for source, values in zip(ordered, draws):
        if source.kind != "common":
            noise += source.normal_displacement(values, reg.normal)
    tail = (1.0 - coverage) / 2.0
    smooth_eval = _at_deviations(evaluation, flat)
    measured = np.concatenate([evaluation.parameters.as_array()[:2], profile_deviations(rough, labels)])
    rough_error = np.concatenate(
        [
            _length_errors(evaluation, ordered, draws),
            profile_deviations(rough + noise, labels) - measured[2:],
        ],
        axis=1,
    )
    smooth_error = np.concatenate(
        [
            _length_errors(smooth_eval, ordered, draws),
            profile_deviations(plateau + noise, labels) - profile_deviations(plateau, labels),
        ],
        axis=1,
    )
    return ResolutionEnvelope(
        measured=measured,
        smooth_high=np.quantile(smooth_error, 1.0 - tail, axis=0),
        rough_low=np.quantile(rough_error, tail, axis=0),
        coverage_probability=coverage,
        n_draws=n_draws,
        seed=seed,
        plateau_factor=factor,
    )


def _envelope_limits(
    evaluation: SectionEvaluation,
    smooth: ArrayLike,
    coverage: float,
    n_draws: int,
    smooth_std: ArrayLike | None,
    plateau_factor: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """The checked smooth limit, its flattened extremes (:func:`plateau_extremes`) and the factor used."""
    if not 0.0 < coverage < 1.0:
        msg = f"coverage must be in (0, 1), got {coverage!r}"
        raise ConfigError(msg)
    if isinstance(n_draws, bool) or not isinstance(n_draws, int) or n_draws < 100:
        msg = f"n_draws must be an integer >= 100, got {n_draws!r}"
        raise ConfigError(msg)
    rough = evaluation.registration.residual
    flat = np.asarray(smooth, dtype=np.float64)
    if flat.shape != rough.shape:
        msg = f"smooth deviations must have shape {rough.shape}, got {flat.shape}"
        raise ConfigError(msg)
    if not (np.isfinite(plateau_factor) and plateau_factor >= 0.0):
        msg = f"plateau_factor must be finite and >= 0, got {plateau_factor!r}"
        raise ConfigError(msg)
    if smooth_std is None:
        return flat, flat, 0.0
    std = np.asarray(smooth_std, dtype=np.float64)
    if std.shape != rough.shape or not np.all(np.isfinite(std)) or np.any(std < 0.0):
        msg = f"smooth_std must be finite, >= 0 and of shape {rough.shape} [m]"
        raise ConfigError(msg)
    labels = evaluation.segmentation.labels
    return flat, plateau_extremes(flat, std, labels, plateau_factor), float(plateau_factor)
