"""The blade-section trial compiled by numba: draws and the frozen model, one trial at a time.

Imported only when numba is installed (the ``fast`` extra). One trial's arithmetic is that of
:meth:`~robocal_uncertainty.inspection.frozen_model.FrozenSectionModel.evaluate` fed by
:meth:`~robocal_uncertainty.inspection.section_mc.SectionTrials.evaluate_draws`: the points'
normal displacements summed source by source, the registration change ``G @ dn``, the residuals,
the maximum thickness and chord over the candidate sets, the edge windows grown per trial and
the profiles as max - min per region. The numpy path holds arrays of a whole batch (about
60 kB per trial at 1 836 points, read and written several times); here a trial's numbers stay
in a few rows of the cache, and an edge window's checks stop at the first that fails.

:func:`fused_trials` also draws the trial's values from the sources' own generators
(numpy ``Generator`` objects, whose ``uniform`` numba computes as numpy does: the same
numbers, in the same order), so no batch of draws is ever stored; it needs numba >= 0.56.
:func:`drawn_trials` takes draws already made (numpy's, for other distributions, older numba
and the GUM budget's columns).

Every kernel lives in this one module (numba's disk cache is checked against the source file
of the function it compiled). Compiled on first use and cached on disk (``cache=True``).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

XY, ALONG, COMMON = 0, 1, 2
"""Source kinds (:data:`~robocal_uncertainty.core.instruments.cmm.SourceKind`) as codes."""

MAX_SOURCES = 4
"""Sources a trial draws from (the CMM's four); fewer are padded with empty ones."""


@numba.njit(cache=True, error_model="numpy")
def _normal_shift(draws, sources, ns):  # type: ignore[no-untyped-def]
    """ns[i] = Σ_s (normal displacement of point i by source s), in source order."""
    kinds, counts, _, _, nweight, _ = sources
    n = ns.shape[0]
    for i in range(n):
        ns[i] = 0.0
    for s in range(kinds.shape[0]):
        if counts[s] == 0:
            continue
        d = draws[s]
        w = nweight[s]
        kind = kinds[s]
        if kind == XY:
            for i in range(n):
                ns[i] += d[2 * i] * w[i, 0] + d[2 * i + 1] * w[i, 1]
        elif kind == ALONG:
            for i in range(n):
                ns[i] += d[i] * w[i, 0]
        else:
            c = d[0]
            for i in range(n):
                ns[i] += c * w[i, 0]


@numba.njit(cache=True, error_model="numpy")
def _subset_moved(draws, sources, lengths, points, moved):  # type: ignore[no-untyped-def]
    """moved[j] = points[subset[j]] + Σ_s (displacement of that point by source s)."""
    kinds, counts, _, _, _, sgain = sources
    subset = lengths[0]
    m = subset.shape[0]
    for j in range(m):
        moved[j, 0] = 0.0
        moved[j, 1] = 0.0
    for s in range(kinds.shape[0]):
        if counts[s] == 0:
            continue
        d = draws[s]
        g = sgain[s]
        kind = kinds[s]
        for j in range(m):
            i = subset[j]
            if kind == XY:
                moved[j, 0] += d[2 * i] * g[j, 0]
                moved[j, 1] += d[2 * i + 1] * g[j, 1]
            elif kind == ALONG:
                moved[j, 0] += d[i] * g[j, 0]
                moved[j, 1] += d[i] * g[j, 1]
            else:
                moved[j, 0] += d[0] * g[j, 0]
                moved[j, 1] += d[0] * g[j, 1]
    for j in range(m):
        # numpy adds the displacement to the point: points[subset] + shift.
        moved[j, 0] = points[subset[j], 0] + moved[j, 0]
        moved[j, 1] = points[subset[j], 1] + moved[j, 1]


@numba.njit(cache=True, error_model="numpy")
def _segment_distance(ax, ay, x0, y0, x1, y1):  # type: ignore[no-untyped-def]
    """Distance of point a to segment s0-s1, as :func:`~.frozen_model._segment_distance`."""
    ex = x1 - x0
    ey = y1 - y0
    rx = ax - x0
    ry = ay - y0
    length2 = max(ex * ex + ey * ey, 1e-300)
    t = (rx * ex + ry * ey) / length2
    t = min(max(t, 0.0), 1.0)
    gx = rx - t * ex
    gy = ry - t * ey
    return math.sqrt(gx * gx + gy * gy)


@numba.njit(cache=True, error_model="numpy")
def _thickness_and_chord(lengths, moved, out):  # type: ignore[no-untyped-def]
    """out[0] the maximum thickness, out[1] the chord; returns the farthest pair's index."""
    _, points, segments, pairs = lengths
    best = -np.inf
    for a in range(points.shape[0]):
        ax = moved[points[a], 0]
        ay = moved[points[a], 1]
        near = np.inf
        for k in range(segments.shape[1]):
            p0 = segments[a, k, 0]
            p1 = segments[a, k, 1]
            near = min(near, _segment_distance(ax, ay, moved[p0, 0], moved[p0, 1], moved[p1, 0], moved[p1, 1]))
        best = max(best, near)
    out[0] = best
    far = -np.inf
    pair = 0
    for k in range(pairs.shape[0]):
        dx = moved[pairs[k, 0], 0] - moved[pairs[k, 1], 0]
        dy = moved[pairs[k, 0], 1] - moved[pairs[k, 1], 1]
        length2 = dx * dx + dy * dy
        if length2 > far:  # the first of equal maxima, as numpy's argmax
            far = length2
            pair = k
    out[1] = math.sqrt(far)
    return pair


@numba.njit(cache=True, error_model="numpy")
def _registration(geometry, ns, residual, out):  # type: ignore[no-untyped-def]
    """Offsets and twist (out[2:5]) and the residuals after the linearised registration."""
    base, measured, solve_t, jacobian_t = geometry
    n = ns.shape[0]
    c0 = 0.0
    c1 = 0.0
    c2 = 0.0
    for i in range(n):
        c0 += ns[i] * solve_t[i, 0]
        c1 += ns[i] * solve_t[i, 1]
        c2 += ns[i] * solve_t[i, 2]
    out[2] = base[2] + c0
    out[3] = base[3] + c1
    out[4] = base[4] + c2
    for i in range(n):
        r = ns[i] + measured[i]
        r -= c0 * jacobian_t[0, i]
        r -= c1 * jacobian_t[1, i]
        r -= c2 * jacobian_t[2, i]
        residual[i] = r


@numba.njit(cache=True, error_model="numpy")
def _edge_half_width(edges, e, choice, ns):  # type: ignore[no-untyped-def]
    """Half-width of edge e's window around its candidate ``choice`` (index in the edge's candidates).

    A window's linearised circle residuals are ``f + (I - H) dn`` with the fit's hat matrix
    ``H = U Uᵀ`` of rank 3 (the frozen model holds ``I - H``; its factor ``U`` (m, 3) costs 6m
    operations per window instead of m²). The growth stops at the first window that fails.
    """
    (
        candidate_start,
        certain_stop,
        _,
        check_start,
        check_k,
        window_start,
        windows,
        residuals,
        factor_start,
        factors,
        tolerance,
    ) = edges[:11]
    c = candidate_start[e] + choice
    half = certain_stop[c]
    for check in range(check_start[c], check_start[c + 1]):
        first = window_start[check]
        size = window_start[check + 1] - first
        base = factor_start[check]
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        for i in range(size):
            value = ns[windows[first + i]]
            row = base + 3 * i
            a0 += factors[row] * value
            a1 += factors[row + 1] * value
            a2 += factors[row + 2] * value
        for j in range(size):
            row = base + 3 * j
            fitted = factors[row] * a0 + factors[row + 1] * a1 + factors[row + 2] * a2
            moved = residuals[first + j] + (ns[windows[first + j]] - fitted)
            if abs(moved) > tolerance:
                return check_k[check] - 1
    return half


@numba.njit(cache=True, error_model="numpy")
def _profiles(profile, edges, pair, ns, residual, out):  # type: ignore[no-untyped-def]
    """The four profiles (out[5:9]): max - min of the residuals per region, edge zones per trial."""
    has_edges, run_start, run_stop, run_region = profile
    high = np.full(4, -np.inf)
    low = np.full(4, np.inf)
    for r in range(run_start.shape[0]):
        # A run's extremes in scalars: the loop vectorises (5.2 -> 1.0 us per trial at 1 836
        # points, measured); through the arrays each step waits for the previous store.
        region = run_region[r]
        run_high = high[region]
        run_low = low[region]
        for i in range(run_start[r], run_stop[r]):
            run_high = max(run_high, residual[i])
            run_low = min(run_low, residual[i])
        high[region] = run_high
        low[region] = run_low
    if has_edges:
        candidate_start, _, candidate_offset = edges[0], edges[1], edges[2]
        pair_edges, zone_start, zones, zone_offset, codes = edges[11:16]
        for e in range(2):
            choice = pair_edges[pair, e]
            half = _edge_half_width(edges, e, choice, ns)
            centre = candidate_offset[candidate_start[e] + choice]
            before, after, own = codes[e, 0], codes[e, 1], codes[e, 2]
            for z in range(zone_start[e], zone_start[e + 1]):
                offset = zone_offset[z]
                region = before if offset < centre - half else after
                if abs(offset - centre) <= half:
                    region = own
                value = residual[zones[z]]
                high[region] = max(high[region], value)
                low[region] = min(low[region], value)
    for region in range(4):
        out[5 + region] = high[region] - low[region]


@numba.njit(cache=True, error_model="numpy")
def _trial(draws, model, ns, residual, moved, out):  # type: ignore[no-untyped-def]
    """The nine parameters of one trial (``draws``: one 1-D array per source) into out (9,)."""
    geometry, sources, lengths, profile, edges = model
    _normal_shift(draws, sources, ns)
    _subset_moved(draws, sources, lengths, geometry[4], moved)
    pair = _thickness_and_chord(lengths, moved, out)
    _registration(geometry[:4], ns, residual, out)
    _profiles(profile, edges, pair, ns, residual, out)


@numba.njit(cache=True, error_model="numpy")
def _scratch(model):  # type: ignore[no-untyped-def]
    geometry, _, lengths, _, _ = model
    n = geometry[1].shape[0]
    return np.empty(n), np.empty(n), np.empty((lengths[0].shape[0], 2))


@numba.njit(cache=True, error_model="numpy")
def drawn_trials(draws, model, out):  # type: ignore[no-untyped-def]
    """Parameters of trials whose draws are given: ``draws`` a tuple of MAX_SOURCES (T, n_draws)
    arrays (empty ones for absent sources); out (T, 9)."""
    ns, residual, moved = _scratch(model)
    for t in range(out.shape[0]):
        row = (draws[0][t], draws[1][t], draws[2][t], draws[3][t])
        _trial(row, model, ns, residual, moved, out[t])


@numba.njit(cache=True, error_model="numpy")
def fused_trials(generators, model, out):  # type: ignore[no-untyped-def]
    """Draw and evaluate out.shape[0] trials: source s draws its counts[s] values per trial from
    generators[s] by ``uniform(low[s], high[s])`` (a count of 0: no draws, a source of zero
    magnitude or padding); out (T, 9)."""
    _, counts, low, high, _, _ = model[1]
    ns, residual, moved = _scratch(model)
    b0 = np.zeros(max(counts[0], 1))
    b1 = np.zeros(max(counts[1], 1))
    b2 = np.zeros(max(counts[2], 1))
    b3 = np.zeros(max(counts[3], 1))
    buffers = (b0, b1, b2, b3)
    for t in range(out.shape[0]):
        for s in range(MAX_SOURCES):
            generator = generators[s]
            buffer = buffers[s]
            lo = low[s]
            hi = high[s]
            for j in range(counts[s]):
                buffer[j] = generator.uniform(lo, hi)
        _trial(buffers, model, ns, residual, moved, out[t])


_PCG_MULTIPLIER_HIGH = np.uint64(2549297995355413924)
_PCG_MULTIPLIER_LOW = np.uint64(4865540595714422341)
"""numpy's PCG64 multiplier (PCG_DEFAULT_MULTIPLIER_128), high and low 64 bits."""


@intrinsic
def _mulhi(typingctx, a, b):  # type: ignore[no-untyped-def]
    """High 64 bits of the 128-bit product of two uint64 (one LLVM i128 multiply)."""
    signature = types.uint64(types.uint64, types.uint64)

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        wide = ir.IntType(128)
        product = builder.mul(builder.zext(args[0], wide), builder.zext(args[1], wide))
        return builder.trunc(builder.lshr(product, ir.Constant(wide, 64)), ir.IntType(64))

    return signature, codegen


@numba.njit(cache=True, error_model="numpy")
def _pcg64_uniforms(state, buffer, count, lo, hi):  # type: ignore[no-untyped-def]
    """buffer[:count] = numpy's ``Generator.uniform(lo, hi)`` from a PCG64 state, advanced in place.

    ``state`` (4,) uint64: the 128-bit state and increment as (high, low) words. Each value is
    numpy's: the LCG step ``s = s * M + inc`` (mod 2**128), the XSL-RR output, the top 53 bits
    as a double in [0, 1) and ``lo + (hi - lo) * u``. Inline here, the step costs less than the
    generator's call through its function pointer per value.
    """
    s_high = state[0]
    s_low = state[1]
    inc_high = state[2]
    inc_low = state[3]
    width = hi - lo
    for j in range(count):
        low = s_low * _PCG_MULTIPLIER_LOW
        carried = _mulhi(s_low, _PCG_MULTIPLIER_LOW)  # type: ignore[call-arg,var-annotated]
        high = carried + s_low * _PCG_MULTIPLIER_HIGH + s_high * _PCG_MULTIPLIER_LOW
        s_low = low + inc_low
        s_high = high + inc_high + (np.uint64(1) if s_low < low else np.uint64(0))
        word = s_high ^ s_low
        rot = s_high >> np.uint64(58)
        word = (word >> rot) | (word << ((np.uint64(64) - rot) & np.uint64(63)))
        buffer[j] = lo + width * (numba.float64(word >> np.uint64(11)) * (1.0 / 9007199254740992.0))
    state[0] = s_high
    state[1] = s_low


@numba.njit(cache=True, error_model="numpy")
def fused_pcg64_trials(states, model, out):  # type: ignore[no-untyped-def]
    """:func:`fused_trials` with every source's generator a PCG64 given by its state.

    ``states`` (MAX_SOURCES, 4) uint64, one row per source as :func:`_pcg64_uniforms` takes it,
    advanced in place (the caller writes them back to the generators): the same values as
    :func:`fused_trials`, bit for bit.
    """
    _, counts, low, high, _, _ = model[1]
    ns, residual, moved = _scratch(model)
    b0 = np.zeros(max(counts[0], 1))
    b1 = np.zeros(max(counts[1], 1))
    b2 = np.zeros(max(counts[2], 1))
    b3 = np.zeros(max(counts[3], 1))
    buffers = (b0, b1, b2, b3)
    for t in range(out.shape[0]):
        for s in range(MAX_SOURCES):
            _pcg64_uniforms(states[s], buffers[s], counts[s], low[s], high[s])
        _trial(buffers, model, ns, residual, moved, out[t])
