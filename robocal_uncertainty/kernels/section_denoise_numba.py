"""The denoising's local fits compiled by numba: window sums and smoother rows without window arrays.

Imported only when numba is installed (the ``fast`` extra), for the section's ``numba`` backend.
The numpy path of :mod:`robocal_uncertainty.inspection.denoise` builds, per chunk of centre
points, arrays of (points x window x 5) regressors and multiplies them: at 5 000 points and
windows up to 1 500 points wide that is most of a scan's time. Here each centre point's window
is walked twice in a loop: once for the 5 x 5 weighted moments of the regressors ``(1, d, d²,
n·n_i - 1, n × n_i)``, and (after the small linear algebra, done batched in numpy by the
caller) once to apply the fit's coefficients: ``weight_j = w_j · (x_j · c_i)``. The weights of
the numpy path are the same numbers up to rounding (sums in another order).

Every kernel takes plain float64 / int64 arrays (no Generator), so numba 0.55 compiles them.
Compiled on first use and cached on disk (``cache=True``).
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, error_model="numpy", inline="always")
def _regressors(tripled, nrm, n, j, u0, hx, hy, half_width, x):  # type: ignore[no-untyped-def]  # noqa: PLR0917
    """Tricube weight of tripled index ``j`` about a centre at ``u0`` with normal (hx, hy); x[:] = its regressors."""
    d = (tripled[j] - u0) / half_width
    a = min(abs(d), 1.0)
    t = 1.0 - a * a * a
    w = t * t * t
    s = j - n if j >= n else j
    s = s - n if s >= n else s
    nx = nrm[s, 0]
    ny = nrm[s, 1]
    x[0] = 1.0
    x[1] = d
    x[2] = d * d
    x[3] = nx * hx + ny * hy - 1.0
    x[4] = ny * hx - nx * hy
    return w


@numba.njit(cache=True, error_model="numpy")
def window_moments(tripled, nrm, lo, hi, centre, half_width, moments):  # type: ignore[no-untyped-def]
    """moments[i] = Σ_window w xxᵀ (5 x 5) at centre point ``centre[i]``, window ``tripled[lo[i]:hi[i]]``."""
    n = nrm.shape[0]
    for i in range(centre.shape[0]):
        c = centre[i]
        u0 = tripled[c + n]
        hx = nrm[c, 0]
        hy = nrm[c, 1]
        # The 15 distinct sums of the symmetric 5 x 5 (x0 = 1): scalars keep them in registers.
        s00 = s01 = s02 = s03 = s04 = 0.0
        s12 = s13 = s14 = 0.0
        s22 = s23 = s24 = 0.0
        s33 = s34 = s44 = 0.0
        for j in range(lo[i], hi[i]):
            d = (tripled[j] - u0) / half_width
            a = min(abs(d), 1.0)
            t = 1.0 - a * a * a
            w = t * t * t
            s = j - n if j >= n else j
            s = s - n if s >= n else s
            nx = nrm[s, 0]
            ny = nrm[s, 1]
            x2 = d * d
            x3 = nx * hx + ny * hy - 1.0
            x4 = ny * hx - nx * hy
            s00 += w
            wd = w * d
            s01 += wd
            s02 += w * x2
            s03 += w * x3
            s04 += w * x4
            s12 += wd * x2
            s13 += wd * x3
            s14 += wd * x4
            w2 = w * x2
            s22 += w2 * x2
            s23 += w2 * x3
            s24 += w2 * x4
            w3 = w * x3
            s33 += w3 * x3
            s34 += w3 * x4
            s44 += w * x4 * x4
        m = moments[i]
        m[0, 0] = s00
        m[0, 1] = m[1, 0] = s01
        m[0, 2] = m[2, 0] = s02
        m[1, 1] = s02  # w d·d = w d²
        m[0, 3] = m[3, 0] = s03
        m[0, 4] = m[4, 0] = s04
        m[1, 2] = m[2, 1] = s12
        m[1, 3] = m[3, 1] = s13
        m[1, 4] = m[4, 1] = s14
        m[2, 2] = s22
        m[2, 3] = m[3, 2] = s23
        m[2, 4] = m[4, 2] = s24
        m[3, 3] = s33
        m[3, 4] = m[4, 3] = s34
        m[4, 4] = s44


@numba.njit(cache=True, error_model="numpy")
def window_fit(tripled, nrm, lo, hi, centre, half_width, coef, r, variance, fit, sd):  # type: ignore[no-untyped-def]  # noqa: PLR0917
    """fit[i] = Σ_window weight_j r_j and sd[i] = sqrt(Σ weight_j² variance_j), weight_j = w_j (x_j · coef[i])."""
    n = nrm.shape[0]
    x = np.empty(5)
    for i in range(centre.shape[0]):
        c = centre[i]
        u0 = tripled[c + n]
        hx = nrm[c, 0]
        hy = nrm[c, 1]
        c0, c1, c2, c3, c4 = coef[i, 0], coef[i, 1], coef[i, 2], coef[i, 3], coef[i, 4]
        total = 0.0
        spread = 0.0
        for j in range(lo[i], hi[i]):
            w = _regressors(tripled, nrm, n, j, u0, hx, hy, half_width, x)
            weight = w * (c0 + x[1] * c1 + x[2] * c2 + x[3] * c3 + x[4] * c4)
            s = j - n if j >= n else j
            s = s - n if s >= n else s
            total += weight * r[s]
            spread += weight * weight * variance[s]
        fit[i] = total
        sd[i] = np.sqrt(spread)


@numba.njit(cache=True, error_model="numpy")
def window_rows(tripled, nrm, lo, hi, centre, half_widths, coef, indptr, indices, data):  # type: ignore[no-untyped-def]  # noqa: PLR0917
    """CSR rows (columns ascending) of the smoother at the points ``centre``; row i's half-width ``half_widths[i]``.

    ``indptr`` (m + 1,) is filled here; ``indices`` and ``data`` hold ``Σ (hi - lo)`` entries.
    A window that wraps past the end of the contour lists its wrapped part (columns 0, 1, ...) first.
    """
    n = nrm.shape[0]
    x = np.empty(5)
    k = 0
    indptr[0] = 0
    for i in range(centre.shape[0]):
        c = centre[i]
        u0 = tripled[c + n]
        hx = nrm[c, 0]
        hy = nrm[c, 1]
        # The first tripled index whose column wraps to a lower one (a multiple of n in the window).
        split = hi[i]
        for boundary in (n, 2 * n):
            if lo[i] < boundary < hi[i]:
                split = boundary
        for part in range(2):
            start = split if part == 0 else lo[i]
            stop = hi[i] if part == 0 else split
            for j in range(start, stop):
                w = _regressors(tripled, nrm, n, j, u0, hx, hy, half_widths[i], x)
                weight = w * (
                    x[0] * coef[i, 0] + x[1] * coef[i, 1] + x[2] * coef[i, 2] + x[3] * coef[i, 3] + x[4] * coef[i, 4]
                )
                indices[k] = j % n
                data[k] = weight
                k += 1
        indptr[i + 1] = k
