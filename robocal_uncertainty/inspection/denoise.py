"""Denoised reference cloud for the Monte Carlo of the max/min-defined section parameters.

Why
---
Maximum thickness, chord and profile deviation are extreme values over points. The per-point
instrument noise biases them (the largest of many noisy values overshoots the largest true
value), and the seed's Monte Carlo, which perturbs the *measured* cloud ``y``, adds the noise
a second time: its distribution is centred about ``f(y) + b`` instead of describing the error
``f(y) - f(x)`` of the measured value (``x`` the true cloud). The error distribution is that of
``Δ = f(x + e') - f(x)``; the Monte Carlo can sample it around a cloud ``x̂`` close to ``x``
if ``x̂`` has the noise smoothed out. This module builds such an ``x̂``.

Smoother
--------
The signed normal deviations ``r(s)`` of the measured points from the registered nominal curve
(``s`` the nominal-curve parameter) are smoothed by local least squares with a tricube window
of half-width ``h`` in ``s``: at each point the model is a quadratic in ``s`` plus, where the
nominal normal turns within the window (the leading and trailing edges), the projection
``n(s)·v`` of a local translation ``v``. The translation term carries the registration misfit,
which a rigid-body offset of a few µm turns into a bump of width the edge radius in ``r(s)``
at an edge (a quadratic over a window of several edge radii would flatten it). Where the
normal turns so little that ``n(s)·v`` differs from a quadratic in ``s`` by less than
:data:`TRANSLATION_THRESHOLD` (RMS over the window, relative to ``|v|``) the term is dropped: it
would only fit noise. The denoised points are the measured points moved along the normals
by the smoothed minus the raw deviation, ``x̂ = y - (r - r̂)·n``.

Window
------
``h`` is chosen among :func:`window_candidates` by Mallows' Cp (Stein's unbiased risk
estimate) with the per-point noise variance of the instrument model along the normal, which
the CMM model states (no estimate from the data is needed):
``Cp(h) = Σ (r - r̂)² - Σ σ²ᵢ + 2 Σ σ²ᵢ Sᵢᵢ``, ``S`` the smoother's hat matrix. The common
(thermal) source is a smooth scale error, not noise, and stays in ``x̂``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal_uncertainty.errors import ConfigError, InputError
from robocal_uncertainty.inspection.cmm_model import ErrorSource
from robocal_uncertainty.inspection.section import SectionEvaluation

__all__ = [
    "TRANSLATION_THRESHOLD",
    "DenoisedCloud",
    "denoise_section",
    "normal_noise_variance",
    "smooth_normal_deviation",
    "window_candidates",
]

TRANSLATION_THRESHOLD = 1e-2
"""RMS (over the window, weighted) of the part of ``n(s)·v/|v|`` not explained by a quadratic
in ``s`` below which the local translation term is dropped [1]."""

_CANDIDATE_FRACTIONS = (0.005, 0.0075, 0.01, 0.015, 0.02, 0.03, 0.045, 0.065, 0.1, 0.15)
"""Default window half-widths as fractions of the nominal perimeter."""
_CHUNK = 256
"""Centre points per vectorised step of the smoother (memory ~ 100 B x chunk x window points)."""
_CP_POINTS = 600
"""About this many points (every k-th) enter the Cp window choice."""
_MIN_SPACINGS = 4.0
"""Smallest window half-width in units of the widest point spacing (>= 9 points per window)."""


@dataclass(frozen=True, eq=False)
class DenoisedCloud:
    """Outcome of :func:`denoise_section`.

    Attributes
    ----------
    points : ndarray, shape (n, 2) [m]
        Denoised points, in the contour order of the evaluation.
    deviation : ndarray, shape (n,) [m]
        Smoothed signed normal deviations ``r̂``.
    half_width : float
        Window half-width used [m of nominal-curve parameter].
    candidates : tuple of float
        Half-widths tried [m] (one when it was given).
    risk : tuple of float
        Cp estimate of the summed squared error ``Σ (r̂ - r_true)²`` over all points, per
        candidate [m²] (from every k-th point, about 600 of them, scaled).
    noise_std : ndarray, shape (n,) [m]
        Per-point standard deviation of the independent noise along the normal.
    """

    points: NDArray[np.float64]
    deviation: NDArray[np.float64]
    half_width: float
    candidates: tuple[float, ...]
    risk: tuple[float, ...]
    noise_std: NDArray[np.float64]


def smooth_normal_deviation(
    parameter: ArrayLike,
    deviation: ArrayLike,
    normal: ArrayLike,
    period: float,
    half_width: float,
    *,
    at: ArrayLike | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Local quadratic (plus local translation at turning normals) fit of a closed contour's deviations.

    Parameters
    ----------
    parameter : array_like, shape (n,) [m]
        Nominal-curve parameter of each point, increasing, in [0, period).
    deviation : array_like, shape (n,) [m]
        Signed normal deviation of each point.
    normal : array_like, shape (n, 2)
        Unit normals at the points.
    period : float
        Perimeter of the nominal curve [m].
    half_width : float
        Window half-width in ``parameter`` [m], below period / 2.
    at : array_like of int, shape (m,), optional
        Indices of the points to fit at (default all).

    Returns
    -------
    fit : ndarray, shape (m,) [m]
        Smoothed deviations at the points ``at``.
    leverage : ndarray, shape (m,)
        Diagonal of the hat matrix there (weight of each point's own deviation in its fit).
    """
    u = np.asarray(parameter, dtype=np.float64)
    r = np.asarray(deviation, dtype=np.float64)
    nrm = np.asarray(normal, dtype=np.float64)
    n = u.shape[0]
    if not 0 < half_width < period / 2:
        msg = f"half_width must be in (0, period/2 = {period / 2:.6g} m), got {half_width!r}"
        raise ConfigError(msg)
    centre = np.arange(n) if at is None else np.asarray(at, dtype=np.intp)
    tripled = np.concatenate([u - period, u, u + period])
    lo = np.searchsorted(tripled, u[centre] - half_width, side="right")
    hi = np.searchsorted(tripled, u[centre] + half_width, side="left")
    fit = np.empty(centre.shape[0])
    leverage = np.empty(centre.shape[0])
    for start in range(0, centre.shape[0], _CHUNK):
        rows = slice(start, start + _CHUNK)
        fit[rows], leverage[rows] = _local_fit(tripled, r, nrm, lo[rows], hi[rows], centre[rows], half_width)
    return fit, leverage


def _local_fit(
    tripled: NDArray[np.float64],
    r: NDArray[np.float64],
    nrm: NDArray[np.float64],
    lo: NDArray[np.intp],
    hi: NDArray[np.intp],
    centre: NDArray[np.intp],
    half_width: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Fit and leverage at the points ``centre`` (windows ``tripled[lo:hi]``)."""
    n = r.shape[0]
    width = int((hi - lo).max())
    index = lo[:, np.newaxis] + np.arange(width)[np.newaxis, :]
    inside = index < hi[:, np.newaxis]
    index = np.where(inside, index, lo[:, np.newaxis])
    d = (tripled[index] - tripled[centre + n][:, np.newaxis]) / half_width
    w = np.where(inside, (1.0 - np.minimum(np.abs(d), 1.0) ** 3) ** 3, 0.0)
    source = index % n
    near = nrm[source]
    here = nrm[centre]
    # Columns: polynomial P = (1, d, d²); translation Q = n(s)·(n_i, t_i) - (1, 0), zero at the
    # centre point (only their P-orthogonal part moves the fit there); then the deviations.
    x = np.stack(
        [
            np.ones_like(d),
            d,
            d * d,
            near[..., 0] * here[:, np.newaxis, 0] + near[..., 1] * here[:, np.newaxis, 1] - 1.0,
            near[..., 1] * here[:, np.newaxis, 0] - near[..., 0] * here[:, np.newaxis, 1],
            r[source],
        ],
        axis=-1,
    )
    moments = np.matmul(np.swapaxes(x * w[..., np.newaxis], 1, 2), x)  # (m, 6, 6) weighted sums
    gram_p = moments[:, :3, :3]
    if np.any(np.linalg.cond(gram_p) > 1e12):
        msg = f"a {half_width * 1e3:.3g} mm window holds too few points for a local quadratic"
        raise InputError(msg)
    inv_p = np.linalg.inv(gram_p)
    b = inv_p @ moments[:, :3, 3:5]  # (m, 3, 2): Q's projection on P
    coef_p = np.einsum("ikl,il->ik", inv_p, moments[:, :3, 5])
    fit = coef_p[:, 0]  # polynomial fit at the centre
    leverage = inv_p[:, 0, 0].copy()
    # Q_res = Q - P b (W-orthogonal to P): Gram and correlation with r from the moments.
    gram_q = moments[:, 3:5, 3:5] - np.swapaxes(b, 1, 2) @ moments[:, :3, 3:5]
    q_r = moments[:, 3:5, 5] - np.einsum("ikl,ik->il", b, moments[:, :3, 5])
    value, vector = np.linalg.eigh(gram_q)
    keep = value > TRANSLATION_THRESHOLD**2 * moments[:, 0, 0, np.newaxis]
    for k in range(2):
        direction = vector[:, :, k]
        at_centre = -np.einsum("il,il->i", b[:, 0, :], direction)  # Q_res·direction at d = 0
        gain = np.where(keep[:, k], at_centre / np.where(keep[:, k], value[:, k], 1.0), 0.0)
        fit += gain * np.einsum("il,il->i", q_r, direction)
        leverage += gain * at_centre
    return fit, leverage


def normal_noise_variance(sources: Sequence[ErrorSource], normals: ArrayLike) -> NDArray[np.float64]:
    """Per-point variance of the independent (per-point) sources along the normals, shape (n,) [m²].

    ``common`` sources (one draw per trial, a smooth scale error) are not noise and are left out.
    """
    nrm = np.asarray(normals, dtype=np.float64)
    variance = np.zeros(nrm.shape[0])
    for source in sources:
        u2 = source.draw_uncertainty**2
        if source.kind == "xy":
            variance += source.gain**2 * u2  # iid x and y errors: any direction gets gain² u²
        elif source.kind == "along":
            variance += np.einsum("ij,ij->i", source.gain, nrm) ** 2 * u2
    return variance


def window_candidates(parameter: ArrayLike, period: float) -> tuple[float, ...]:
    """Default half-widths: 0.5 % to 15 % of the perimeter, at least 4 widest point spacings [m]."""
    u = np.sort(np.asarray(parameter, dtype=np.float64))
    widest = float(np.diff(np.concatenate([u, u[:1] + period])).max())
    smallest = _MIN_SPACINGS * widest
    chosen = [f * period for f in _CANDIDATE_FRACTIONS if f * period >= smallest]
    return tuple(chosen) if chosen else (min(smallest, 0.45 * period),)


def denoise_section(
    evaluation: SectionEvaluation,
    sources: Sequence[ErrorSource],
    period: float,
    *,
    half_width: float | None = None,
) -> DenoisedCloud:
    """Denoised reference cloud of a measured section.

    Parameters
    ----------
    evaluation : SectionEvaluation
        Evaluation of the measured cloud (its registration gives deviations, normals, feet).
    sources : sequence of ErrorSource
        The instrument sources at the measured points (their per-point variance weights Cp).
    period : float
        Perimeter of the nominal curve [m].
    half_width : float, optional
        Window half-width [m]; None: chosen by Cp among :func:`window_candidates`.

    Returns
    -------
    DenoisedCloud
    """
    reg = evaluation.registration
    variance = normal_noise_variance(sources, reg.normal)
    if half_width is None:
        candidates = window_candidates(reg.parameter, period)
    else:
        if not (isinstance(half_width, (int, float)) and np.isfinite(half_width) and half_width > 0):
            msg = f"denoise half-width must be a finite length > 0 [m], got {half_width!r}"
            raise ConfigError(msg)
        candidates = (float(half_width),)
    n = reg.residual.shape[0]
    # Cp at every ``stride``-th point (an unbiased risk estimate of that subset; the window
    # spans tens of points, so the subset ranks the windows as the whole would, at a third
    # of the cost), scaled to all points.
    stride = max(1, n // _CP_POINTS)
    subset = np.arange(0, n, stride)
    risks = []
    for h in candidates:
        fit, leverage = smooth_normal_deviation(reg.parameter, reg.residual, reg.normal, period, h, at=subset)
        v = variance[subset]
        risk = ((reg.residual[subset] - fit) ** 2).sum() - v.sum() + 2.0 * (v * leverage).sum()
        risks.append(float(risk) * n / subset.shape[0])
    best = int(np.argmin(risks))
    fit, _ = smooth_normal_deviation(reg.parameter, reg.residual, reg.normal, period, candidates[best])
    points = evaluation.points - (reg.residual - fit)[:, np.newaxis] * reg.normal
    return DenoisedCloud(
        points=points,
        deviation=fit,
        half_width=candidates[best],
        candidates=tuple(candidates),
        risk=tuple(risks),
        noise_std=np.sqrt(variance),
    )
