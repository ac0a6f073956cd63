"""Denoised reference cloud for the Monte Carlo of the max/min-defined section parameters.

Why
---
Maximum thickness, chord and profile deviation are extreme values over points. The per-point
instrument noise biases them (the largest of many noisy values overshoots the largest true
value), and the reference paper's Monte Carlo, which perturbs the *measured* cloud ``y``, adds the noise
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
The widest window ``h`` is chosen among :func:`window_candidates` by Mallows' Cp (Stein's
unbiased risk estimate) with the per-point noise variance of the instrument model along the
normal, which the CMM model states (no estimate from the data is needed):
``Cp(h) = Σ (r - r̂)² - Σ σ²ᵢ + 2 Σ σ²ᵢ Sᵢᵢ``, ``S`` the smoother's hat matrix. Cp is one risk
for the whole contour: a bump or dent a few millimetres wide barely moves it, and the window it
picks flattens the feature. So the window is then chosen per point (intersection of confidence
intervals, Lepski / Goldenshluger-Nemirovski): going from the narrowest candidate up to the Cp
choice, a point keeps the widest window whose fit ± :data:`ICI_FACTOR` standard deviations
(``sqrt(Σ_j S_ij² σ_j²)``) still overlaps the intervals of every narrower one. Finally the
residuals are smoothed once more and added back (twicing, ``r̂ = (2S - S²) r``), which restores
most of a peak a local quadratic flattens. The common (thermal) source is a smooth scale error,
not noise, and stays in ``x̂``.

Residual check
--------------
:class:`ResidualCheck`: the residuals ``r - r̂`` of a cloud whose form the smoother follows are
the instrument noise through ``I - (2S - S²)``. A scan statistic over runs of consecutive
standardised residuals, against its null simulated from the instrument's own per-point sources,
flags a cloud with structure the smoother left (a feature narrower than the window, or one the
windows could not follow); its intervals are then not verified for that cloud.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import sparse

from robocal_uncertainty.core.instruments.cmm import ErrorSource
from robocal_uncertainty.errors import ConfigError, InputError
from robocal_uncertainty.inspection.section import SectionEvaluation

__all__ = [
    "CHECK_DRAWS",
    "CHECK_LEVEL",
    "ICI_FACTOR",
    "SCAN_LENGTHS",
    "TRANSLATION_THRESHOLD",
    "DenoisedCloud",
    "ResidualCheck",
    "denoise_section",
    "normal_noise_variance",
    "residual_check",
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
    local_half_width : ndarray, shape (n,) [m]
        Window half-width used at each point (at most ``half_width``).
    check : ResidualCheck
        Whether the residuals left after denoising look like the instrument noise alone.
    smooth_deviation : ndarray, shape (n,) [m]
        Fit of the one window ``half_width`` at every point, without local narrowing or twicing:
        the smoothest form the data support (:mod:`.resolution`).
    smooth_std : ndarray, shape (n,) [m]
        Standard deviation of ``smooth_deviation``'s noise at each point (its window's weights
        and the per-point noise variance): how far its extremes may stand out by noise alone.
    """

    points: NDArray[np.float64]
    deviation: NDArray[np.float64]
    half_width: float
    candidates: tuple[float, ...]
    risk: tuple[float, ...]
    noise_std: NDArray[np.float64]
    local_half_width: NDArray[np.float64]
    check: ResidualCheck
    smooth_deviation: NDArray[np.float64]
    smooth_std: NDArray[np.float64]


def smooth_normal_deviation(
    parameter: ArrayLike,
    deviation: ArrayLike,
    normal: ArrayLike,
    period: float,
    half_width: float,
    *,
    at: ArrayLike | None = None,
    backend: str = "numpy",
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
    backend : str
        ``numpy`` (the reference) or ``numba`` (compiled window loops, the same fit to rounding).

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
    centre = np.arange(u.shape[0]) if at is None else np.asarray(at, dtype=np.intp)
    if _compiled(backend):
        fit, _, leverage, _ = _compiled_fit(u, nrm, period, half_width, centre, r, np.zeros(r.shape[0]))
        return fit, leverage
    weights, source, leverage = _smoother_rows(u, nrm, period, half_width, centre)
    return np.einsum("iw,iw->i", weights, r[source]), leverage


def _compiled(backend: str) -> bool:
    """Whether ``backend`` runs the local fits compiled (``numba``) or in numpy (``numpy``)."""
    if backend not in ("numpy", "numba"):
        msg = f"the denoising runs on numpy or numba, got backend {backend!r}"
        raise ConfigError(msg)
    return backend == "numba"


def _windows(
    u: NDArray[np.float64], period: float, half_width: float, centre: NDArray[np.intp]
) -> tuple[NDArray[np.float64], NDArray[np.intp], NDArray[np.intp]]:
    """``(tripled, lo, hi)``: the parameters over three periods and each centre's window ``tripled[lo:hi]``."""
    if not 0 < half_width < period / 2:
        msg = f"half_width must be in (0, period/2 = {period / 2:.6g} m), got {half_width!r}"
        raise ConfigError(msg)
    tripled = np.concatenate([u - period, u, u + period])
    lo = np.searchsorted(tripled, u[centre] - half_width, side="right")
    hi = np.searchsorted(tripled, u[centre] + half_width, side="left")
    return tripled, lo, hi


def _coefficients(moments: NDArray[np.float64], half_width: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per centre ``c`` (m, 5) with hat-row weights ``w_j (x_j · c)``, and the leverage (m,), from the moments.

    The algebra of :func:`_local_weights` on the weighted moments ``Σ w xxᵀ`` (m, 5, 5): the
    polynomial row ``e0ᵀ inv_p`` plus, per kept translation direction, its gain times the
    P-orthogonal translation column, collected into one vector of regressor coefficients.
    """
    gram_p = moments[:, :3, :3]
    if np.any(np.linalg.cond(gram_p) > 1e12):
        msg = f"a {half_width * 1e3:.3g} mm window holds too few points for a local quadratic"
        raise InputError(msg)
    inv_p = np.linalg.inv(gram_p)
    b = inv_p @ moments[:, :3, 3:5]
    leverage: NDArray[np.float64] = np.array(inv_p[:, 0, 0], dtype=np.float64)
    gram_q = moments[:, 3:5, 3:5] - np.swapaxes(b, 1, 2) @ moments[:, :3, 3:5]
    value, vector = np.linalg.eigh(gram_q)
    keep = value > TRANSLATION_THRESHOLD**2 * moments[:, 0, 0, np.newaxis]
    g = np.zeros((moments.shape[0], 2))
    for k in range(2):
        direction = vector[:, :, k]
        at_centre = -np.einsum("il,il->i", b[:, 0, :], direction)
        gain = np.where(keep[:, k], at_centre / np.where(keep[:, k], value[:, k], 1.0), 0.0)
        g += gain[:, np.newaxis] * direction
        leverage += gain * at_centre
    coef = np.empty((moments.shape[0], 5))
    coef[:, :3] = inv_p[:, 0, :] - np.einsum("ilk,ik->il", b, g)
    coef[:, 3:] = g
    return coef, leverage


def _compiled_fit(
    u: NDArray[np.float64],
    nrm: NDArray[np.float64],
    period: float,
    half_width: float,
    centre: NDArray[np.intp],
    r: NDArray[np.float64],
    variance: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``(fit, sd, leverage, coef)`` at ``centre`` by the compiled window loops (no hat rows kept)."""
    from robocal_uncertainty.kernels import section_denoise_numba as kernels

    tripled, lo, hi = _windows(u, period, half_width, centre)
    nrm = np.ascontiguousarray(nrm)
    moments = np.empty((centre.shape[0], 5, 5))
    kernels.window_moments(tripled, nrm, lo, hi, centre, float(half_width), moments)
    coef, leverage = _coefficients(moments, half_width)
    fit = np.empty(centre.shape[0])
    sd = np.empty(centre.shape[0])
    kernels.window_fit(tripled, nrm, lo, hi, centre, float(half_width), coef, r, variance, fit, sd)
    return fit, sd, leverage, coef


def _local_weights(
    tripled: NDArray[np.float64],
    nrm: NDArray[np.float64],
    lo: NDArray[np.intp],
    hi: NDArray[np.intp],
    centre: NDArray[np.intp],
    half_width: float,
) -> tuple[NDArray[np.float64], NDArray[np.intp], NDArray[np.float64]]:
    """Hat-matrix rows of the local fit at the points ``centre`` (windows ``tripled[lo:hi]``).

    Returns ``(weights, source, leverage)``: the fit at ``centre[i]`` is
    ``Σ_w weights[i, w] · r[source[i, w]]``; shapes (m, width), (m, width), (m,).
    """
    n = nrm.shape[0]
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
    # centre point (only their P-orthogonal part moves the fit there).
    x = np.stack(
        [
            np.ones_like(d),
            d,
            d * d,
            near[..., 0] * here[:, np.newaxis, 0] + near[..., 1] * here[:, np.newaxis, 1] - 1.0,
            near[..., 1] * here[:, np.newaxis, 0] - near[..., 0] * here[:, np.newaxis, 1],
        ],
        axis=-1,
    )
    moments = np.matmul(np.swapaxes(x * w[..., np.newaxis], 1, 2), x)  # (m, 5, 5) weighted sums
    gram_p = moments[:, :3, :3]
    if np.any(np.linalg.cond(gram_p) > 1e12):
        msg = f"a {half_width * 1e3:.3g} mm window holds too few points for a local quadratic"
        raise InputError(msg)
    inv_p = np.linalg.inv(gram_p)
    b = inv_p @ moments[:, :3, 3:5]  # (m, 3, 2): Q's projection on P
    # The polynomial fit at the centre: e0ᵀ inv_p Pᵀ W r.
    weights = np.einsum("iwl,il->iw", x[..., :3], inv_p[:, 0, :])
    leverage = inv_p[:, 0, 0].copy()
    # Q_res = Q - P b (W-orthogonal to P); its Gram from the moments.
    q_res = x[..., 3:5] - np.einsum("iwl,ilk->iwk", x[..., :3], b)
    gram_q = moments[:, 3:5, 3:5] - np.swapaxes(b, 1, 2) @ moments[:, :3, 3:5]
    value, vector = np.linalg.eigh(gram_q)
    keep = value > TRANSLATION_THRESHOLD**2 * moments[:, 0, 0, np.newaxis]
    for k in range(2):
        direction = vector[:, :, k]
        at_centre = -np.einsum("il,il->i", b[:, 0, :], direction)  # Q_res·direction at d = 0
        gain = np.where(keep[:, k], at_centre / np.where(keep[:, k], value[:, k], 1.0), 0.0)
        weights += gain[:, np.newaxis] * np.einsum("iwl,il->iw", q_res, direction)
        leverage += gain * at_centre
    return weights * w, source, leverage


def _smoother_rows(
    u: NDArray[np.float64],
    nrm: NDArray[np.float64],
    period: float,
    half_width: float,
    centre: NDArray[np.intp],
) -> tuple[NDArray[np.float64], NDArray[np.intp], NDArray[np.float64]]:
    """:func:`_local_weights` at ``centre``, in chunks; rows zero-padded to a common width."""
    tripled, lo, hi = _windows(u, period, half_width, centre)
    width = int((hi - lo).max())
    weights = np.zeros((centre.shape[0], width))
    source = np.zeros((centre.shape[0], width), dtype=np.intp)
    leverage = np.empty(centre.shape[0])
    for start in range(0, centre.shape[0], _CHUNK):
        rows = slice(start, start + _CHUNK)
        part, index, leverage[rows] = _local_weights(tripled, nrm, lo[rows], hi[rows], centre[rows], half_width)
        weights[rows, : part.shape[1]] = part
        source[rows, : part.shape[1]] = index
        source[rows, part.shape[1] :] = index[:, :1]
    return weights, source, leverage


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


@dataclass(frozen=True, eq=False)
class ResidualCheck:
    """Per-scan check that the denoised cloud left no structure in the residuals.

    The residuals ``r - r̂`` of a cloud whose form the smoother follows are the instrument noise
    filtered by ``I - S`` (``S`` the smoother's hat matrix). Their standardised values are summed
    over every run of L consecutive points along the contour (L in :data:`SCAN_LENGTHS`), and the
    statistic is the largest ``|sum|/√L``: a bump, dent or edge flattening the windows could not
    follow leaves a run of same-signed residuals and a large statistic. Its null distribution is
    simulated: ``n_draws`` draws of the instrument's per-point sources (their own distributions,
    along the normals) pass through the same ``I - S``. The p-value is
    ``(1 + #{null >= observed}) / (n_draws + 1)``; the scan is flagged when it is <= ``level``.

    Attributes
    ----------
    statistic : float
        Observed ``max |Σ z| / √L``.
    p_value : float
        Simulated p-value.
    flagged : bool
        ``p_value <= level``: the intervals are not verified for this cloud.
    level : float
        Flagging level.
    n_draws : int
        Null draws.
    seed : int
        Root seed of the null draws.
    location : float
        Nominal-curve parameter [m] of the middle of the most significant run.
    extent : float
        Length [m] of that run along the nominal curve.
    points : int
        Points in that run.
    half_width : float
        Local window half-width [m] at ``location``.
    """

    statistic: float
    p_value: float
    flagged: bool
    level: float
    n_draws: int
    seed: int
    location: float
    extent: float
    points: int
    half_width: float

    def describe(self) -> str:
        """One sentence for reports (lengths in mm)."""
        where = (
            f"strongest over {self.points} points ({self.extent * 1e3:.1f} mm) at {self.location * 1e3:.1f} mm "
            f"along the nominal contour, local window half-width {self.half_width * 1e3:.1f} mm"
        )
        if self.flagged:
            return (
                f"residual check FLAGGED this cloud (p = {self.p_value:.3f} <= {self.level}): the denoised cloud "
                f"leaves form structure in the residuals ({where}), e.g. a local feature narrower than the "
                "smoothing window"
            )
        return f"residual check passed (p = {self.p_value:.3f} > {self.level}; {where})"


SCAN_LENGTHS = (1, 2, 4, 8, 16, 32, 64, 128)
"""Run lengths [points] of the residual check's scan statistic."""
CHECK_LEVEL = 0.05
"""p-value at or below which :class:`ResidualCheck` flags a cloud."""
CHECK_DRAWS = 199
"""Null draws of the residual check."""
ICI_FACTOR = 2.5
"""Half-width of the local confidence intervals of the window choice, in standard deviations."""


def _scan_statistic(z: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.intp], NDArray[np.intp]]:
    """``max_L max_i |Σ_{i..i+L-1} z| / √L`` per row of z (k, n), circular; with its L and i."""
    k, n = z.shape
    lengths = [length for length in SCAN_LENGTHS if length < n]
    padded = np.concatenate(
        [np.zeros((k, 1)), np.cumsum(np.concatenate([z, z[:, : max(lengths)]], axis=1), axis=1)], axis=1
    )
    best = np.full(k, -1.0)
    best_length = np.zeros(k, dtype=np.intp)
    best_start = np.zeros(k, dtype=np.intp)
    for length in lengths:
        sums = np.abs(padded[:, length : length + n] - padded[:, :n]) / np.sqrt(length)
        at = np.argmax(sums, axis=1)
        value = sums[np.arange(k), at]
        better = value > best
        best = np.where(better, value, best)
        best_length = np.where(better, length, best_length)
        best_start = np.where(better, at, best_start)
    return best, best_length, best_start


def residual_check(
    residual: ArrayLike,
    smoother: Callable[[NDArray[np.float64]], NDArray[np.float64]],
    sources: Sequence[ErrorSource],
    normals: ArrayLike,
    parameter: ArrayLike,
    half_widths: ArrayLike,
    *,
    seed: int = 0,
    n_draws: int = CHECK_DRAWS,
    level: float = CHECK_LEVEL,
) -> ResidualCheck:
    """Scan statistic of the standardised residuals against their simulated null (:class:`ResidualCheck`).

    Parameters
    ----------
    residual : array_like, shape (n,) [m]
        Measured minus denoised normal deviations, contour order.
    smoother : callable
        The (linear) smoother applied to each row of a (k, n) array of deviations.
    sources : sequence of ErrorSource
        Instrument sources at the points (``common`` ones are a smooth scale error and left out).
    normals : array_like, shape (n, 2)
        Unit normals.
    parameter : array_like, shape (n,) [m]
        Nominal-curve parameters (for the location).
    half_widths : array_like, shape (n,) [m]
        Local window half-widths.
    seed : int
        Root seed of the null draws.
    n_draws : int
        Null draws.
    level : float
        Flagging level.
    """
    nrm = np.asarray(normals, dtype=np.float64)
    res = np.asarray(residual, dtype=np.float64)
    u = np.asarray(parameter, dtype=np.float64)
    n = res.shape[0]
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    noise = np.zeros((n_draws, n))
    for source in sources:
        if source.kind == "common":
            continue
        noise += source.normal_displacement(source.draw(rng, n_draws), nrm)
    null_residual = noise - smoother(noise)
    # Each residual standardised by its standard deviation under the null (from the draws).
    scale = np.maximum(null_residual.std(axis=0), 1e-15)
    null, _, _ = _scan_statistic(null_residual / scale)
    observed, length, start = _scan_statistic((res / scale)[np.newaxis, :])
    value = float(observed[0])
    p = (1.0 + float((null >= value).sum())) / (n_draws + 1.0)
    run = (int(start[0]) + np.arange(int(length[0]))) % n
    span = u[run]
    period_guess = float(u.max() + np.diff(np.sort(u)).min()) if n > 1 else 0.0
    unwrapped = np.where(span < span[0], span + period_guess, span)
    middle = run[run.size // 2]
    return ResidualCheck(
        statistic=value,
        p_value=p,
        flagged=p <= level,
        level=level,
        n_draws=n_draws,
        seed=seed,
        location=float(u[middle]),
        extent=float(unwrapped.max() - unwrapped.min()),
        points=int(length[0]),
        half_width=float(np.asarray(half_widths, dtype=np.float64)[middle]),
    )


def denoise_section(
    evaluation: SectionEvaluation,
    sources: Sequence[ErrorSource],
    period: float,
    *,
    half_width: float | None = None,
    check_seed: int = 0,
    backend: str = "numpy",
) -> DenoisedCloud:
    """Denoised reference cloud of a measured section, and the residual check.

    Parameters
    ----------
    evaluation : SectionEvaluation
        Evaluation of the measured cloud (its registration gives deviations, normals, feet).
    sources : sequence of ErrorSource
        The instrument sources at the measured points (their per-point variance weights Cp,
        the local window choice and the residual check).
    period : float
        Perimeter of the nominal curve [m].
    half_width : float, optional
        One window half-width for every point [m]; None: the largest by Mallows' Cp among
        :func:`window_candidates`, narrowed per point by the intersection of confidence
        intervals (see the module docstring).
    check_seed : int
        Root seed of the residual check's null draws.
    backend : str
        ``numpy`` (the reference) or ``numba``: the local fits' window loops compiled, the same
        cloud to rounding (the hat matrix's entries summed in another order).

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
    r = reg.residual
    compiled = _compiled(backend)
    risks = _cp_risks(reg.parameter, r, reg.normal, variance, period, candidates, backend)
    best = int(np.argmin(risks))
    tried = candidates[: best + 1] if half_width is None else candidates
    if compiled:
        fit, smooth, sd, chosen, hat = _compiled_local_choice(reg.parameter, r, reg.normal, variance, period, tried)
    else:
        fit, smooth, sd, chosen, rows = _local_choice(reg.parameter, r, reg.normal, variance, period, tried)
        hat = _hat_matrix(rows, chosen, n)
    # Twicing (Tukey): smooth the residuals once more and add them back, r̂ = (2S - S²) r. A local
    # quadratic flattens a peak narrower than its window, and a flattened peak gives the Monte
    # Carlo more points near the maximum, hence too large a noise bias and an interval below the
    # truth; the second pass restores most of the peak at a small cost in noise.
    fit = fit + hat @ (r - fit)

    def smoother(values: NDArray[np.float64]) -> NDArray[np.float64]:
        """(2S - S²) applied to each row of ``values`` (k, n)."""
        once = np.asarray(hat @ values.T)
        return np.asarray(2.0 * once - hat @ once).T

    local = np.asarray(tried, dtype=np.float64)[chosen]
    check = residual_check(r - fit, smoother, sources, reg.normal, reg.parameter, local, seed=check_seed)
    points = evaluation.points - (r - fit)[:, np.newaxis] * reg.normal
    return DenoisedCloud(
        points=points,
        deviation=fit,
        half_width=candidates[best] if half_width is None else float(half_width),
        candidates=tuple(candidates),
        risk=tuple(risks),
        noise_std=np.sqrt(variance),
        local_half_width=local,
        check=check,
        smooth_deviation=smooth,
        smooth_std=sd,
    )


def _cp_risks(
    u: NDArray[np.float64],
    r: NDArray[np.float64],
    normal: NDArray[np.float64],
    variance: NDArray[np.float64],
    period: float,
    candidates: Sequence[float],
    backend: str = "numpy",
) -> list[float]:
    """Mallows' Cp risk of each candidate half-width [m²], scaled to all points."""
    n = r.shape[0]
    # Cp at every ``stride``-th point (an unbiased risk estimate of that subset; the window
    # spans tens of points, so the subset ranks the windows as the whole would, at a third
    # of the cost), scaled to all points.
    stride = max(1, n // _CP_POINTS)
    subset = np.arange(0, n, stride)
    risks = []
    for h in candidates:
        fit, leverage = smooth_normal_deviation(u, r, normal, period, h, at=subset, backend=backend)
        v = variance[subset]
        risk = ((r[subset] - fit) ** 2).sum() - v.sum() + 2.0 * (v * leverage).sum()
        risks.append(float(risk) * n / subset.shape[0])
    return risks


def _local_choice(
    u: NDArray[np.float64],
    r: NDArray[np.float64],
    normal: NDArray[np.float64],
    variance: NDArray[np.float64],
    period: float,
    tried: Sequence[float],
) -> tuple[
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.intp],
    list[tuple[NDArray[np.float64], NDArray[np.intp]]],
]:
    """Per point the widest window of ``tried`` that the intersection of confidence intervals keeps.

    Returns ``(fit, smooth, smooth_sd, chosen, rows)``: the fit at the chosen windows (n,), the
    widest window's fit and its standard deviation (n,), the chosen index into ``tried`` (n,)
    and each window's smoother rows ``(weights, source)``.
    """
    n = r.shape[0]
    everywhere = np.arange(n)
    # Local choice (intersection of confidence intervals, Lepski): per point the widest window
    # up to the Cp choice whose fit ± ICI_FACTOR·sd still overlaps those of every narrower one.
    lower = np.full(n, -np.inf)
    upper = np.full(n, np.inf)
    alive = np.ones(n, dtype=bool)
    chosen = np.zeros(n, dtype=np.intp)
    rows: list[tuple[NDArray[np.float64], NDArray[np.intp]]] = []
    fits = np.empty((len(tried), n))
    sd = np.zeros(n)
    for k, h in enumerate(tried):
        weights, source, _ = _smoother_rows(u, normal, period, h, everywhere)
        fits[k] = np.einsum("iw,iw->i", weights, r[source])
        sd = np.sqrt(np.einsum("iw,iw->i", weights**2, variance[source]))
        lower = np.maximum(lower, fits[k] - ICI_FACTOR * sd)
        upper = np.minimum(upper, fits[k] + ICI_FACTOR * sd)
        alive &= lower <= upper
        chosen[alive] = k
        rows.append((weights, source))
    return fits[chosen, everywhere], fits[len(tried) - 1].copy(), sd, chosen, rows


def _compiled_local_choice(
    u: NDArray[np.float64],
    r: NDArray[np.float64],
    normal: NDArray[np.float64],
    variance: NDArray[np.float64],
    period: float,
    tried: Sequence[float],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.intp], sparse.csr_matrix]:
    """:func:`_local_choice` and :func:`_hat_matrix` by the compiled window loops.

    Returns ``(fit, smooth, smooth_sd, chosen, hat)``; only the chosen window's hat row of each
    point is built (the numpy path keeps every candidate's rows).
    """
    from robocal_uncertainty.kernels import section_denoise_numba as kernels

    n = r.shape[0]
    everywhere = np.arange(n)
    lower = np.full(n, -np.inf)
    upper = np.full(n, np.inf)
    alive = np.ones(n, dtype=bool)
    chosen = np.zeros(n, dtype=np.intp)
    fits = np.empty((len(tried), n))
    coefs = np.empty((len(tried), n, 5))
    sd = np.zeros(n)
    for k, h in enumerate(tried):
        fits[k], sd, _, coefs[k] = _compiled_fit(u, normal, period, h, everywhere, r, variance)
        lower = np.maximum(lower, fits[k] - ICI_FACTOR * sd)
        upper = np.minimum(upper, fits[k] + ICI_FACTOR * sd)
        alive &= lower <= upper
        chosen[alive] = k
    widths = np.asarray(tried, dtype=np.float64)[chosen]
    tripled = np.concatenate([u - period, u, u + period])
    lo = np.searchsorted(tripled, u - widths, side="right")
    hi = np.searchsorted(tripled, u + widths, side="left")
    indptr = np.empty(n + 1, dtype=np.intp)
    size = int((hi - lo).sum())
    indices = np.empty(size, dtype=np.intp)
    data = np.empty(size)
    coef = np.ascontiguousarray(coefs[chosen, everywhere])
    kernels.window_rows(tripled, np.ascontiguousarray(normal), lo, hi, everywhere, widths, coef, indptr, indices, data)
    hat = sparse.csr_matrix((data, indices, indptr), shape=(n, n))
    return fits[chosen, everywhere], fits[len(tried) - 1].copy(), sd, chosen, hat


def _hat_matrix(
    rows: Sequence[tuple[NDArray[np.float64], NDArray[np.intp]]], chosen: NDArray[np.intp], n: int
) -> sparse.csr_matrix:
    """The (n, n) hat matrix whose row i is the chosen window's row (duplicate columns summed)."""
    data, cols, row_ids = [], [], []
    for k, (weights, source) in enumerate(rows):
        take = np.flatnonzero(chosen == k)
        if take.size == 0:
            continue
        data.append(weights[take].ravel())
        cols.append(source[take].ravel())
        row_ids.append(np.repeat(take, weights.shape[1]))
    matrix = sparse.coo_matrix(
        (np.concatenate(data), (np.concatenate(row_ids), np.concatenate(cols))), shape=(n, n)
    ).tocsr()
    matrix.sum_duplicates()
    return matrix
