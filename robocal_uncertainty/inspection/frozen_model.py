"""The frozen model of the section Monte Carlo: many trials evaluated at once.

The registration correspondences and the side regions are frozen at the unperturbed solution
(:func:`build_frozen_model`), so a block of trials costs a few array operations:

- position, twist and profile: the registration is linearised at its solution (feet and normals
  fixed; the perturbations are microns, the point spacing and edge radii a millimetre or more),
  so the offsets and twist change by ``G @ dn`` (``G`` the least-squares solution matrix, ``dn``
  the normal displacements) and the residuals by ``dn - A @ G @ dn``;
- maximum thickness and chord: not linearised. The candidate pressure-side points,
  suction-side segments and farthest pairs that could attain the max/min under *any* draw of
  the bounded (rectangular) sources are selected once, from the bound on a point's
  displacement, and the max/min is taken over them exactly in every trial; with bounded
  sources this equals the full algorithm on the same frozen segmentation.
- edge regions: grown per trial as the full algorithm grows them (:class:`EdgeWindows`): the
  edge extreme point is the trial's farthest-pair end, and the radius error of each window
  size whose outcome the draws can change is evaluated from the linearised circle fit.

:mod:`.section_mc` draws the trials and states the results; this module only evaluates them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import ConvexHull, QhullError

from robocal_uncertainty.core.instruments.cmm import (
    ErrorSource,
    draw_bound,
)
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.inspection.section import (
    PARAMETER_NAMES,
    SectionEvaluation,
    SectionOptions,
    _candidate_segments,
    point_to_polyline,
)
from robocal_uncertainty.inspection.segmentation import (
    LEADING_EDGE,
    PRESSURE_SIDE,
    REGIONS,
    SUCTION_SIDE,
    TRAILING_EDGE,
    fit_circle,
)

__all__ = ["EdgeWindows", "FrozenSectionModel", "build_frozen_model"]

_EDGE_SLACK = 0.05e-6
"""Slack on the linearised edge-circle error bound [m]: second-order terms are ~0.01 µm."""

_BOUND_MARGIN = 1.0 + 1e-6
"""Relative slack on the candidate windows, so round-off never drops a candidate."""


def _segment_distance(a: NDArray[np.float64], s0: NDArray[np.float64], s1: NDArray[np.float64]) -> NDArray[np.float64]:
    """Distance of points ``a`` (..., 2) to segments s0-s1 (..., 2), broadcast, shape (...) [m]."""
    edge = s1 - s0
    rel = a - s0
    length2 = np.maximum(np.einsum("...i,...i->...", edge, edge), 1e-300)
    t = np.clip(np.einsum("...i,...i->...", rel, edge) / length2, 0.0, 1.0)
    gap = rel - t[..., np.newaxis] * edge
    return np.asarray(np.sqrt(np.einsum("...i,...i->...", gap, gap)))


_Stacked = tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64], NDArray[np.intp], NDArray[np.intp]]
"""One candidate's edge checks as a single product (see :attr:`EdgeWindows.stacked_checks`)."""


@dataclass(frozen=True, eq=False)
class EdgeWindows:
    """Per-trial growth of one edge region (leading or trailing), linearised at the measured cloud.

    The full algorithm's edge region is the window ``e - k .. e + k`` around the edge extreme
    point ``e`` (an end of the farthest pair), grown while the least-squares circle's radius
    error stays within the tolerance. A perturbation can move ``e`` to a neighbour and stop the
    growth one point earlier or later, which moves a junction point between the edge and a side
    and changes the edge profile. Per candidate ``e`` the window sizes whose outcome no draw of
    the bounded sources can change are decided once; for the others the radius error is
    evaluated per trial from the linearised circle fit, ``max |f + (I - H) dn|`` (``f`` the
    circle residuals, ``H`` the fit's hat matrix, ``dn`` the points' normal displacements).

    Attributes
    ----------
    candidates : ndarray of intp, shape (E,)
        Possible extreme points (contour indices).
    certain_stop : ndarray of intp, shape (E,)
        Per candidate, the half-width the growth stops at when no uncertain size fails.
    checks : tuple of tuple
        Per candidate, ``(k, window, residual, projector)`` of each uncertain half-width k in
        increasing order: window indices (m,), circle residuals (m,) [m], ``I - H`` (m, m).
    zone : ndarray of intp, shape (Z,)
        Contour indices (in order) whose label can differ from the frozen one.
    candidate_offset : ndarray of intp, shape (E,)
        Position of each candidate relative to the frozen extreme point along the contour.
    zone_offset : ndarray of intp, shape (Z,)
        Position of each zone point relative to the frozen extreme point along the contour.
    before, after, region : int
        Region code of zone points before / after the edge window, and the edge's own code.
    """

    candidates: NDArray[np.intp]
    certain_stop: NDArray[np.intp]
    checks: tuple[tuple[tuple[int, NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]], ...], ...]
    zone: NDArray[np.intp]
    candidate_offset: NDArray[np.intp]
    zone_offset: NDArray[np.intp]
    before: int
    after: int
    region: int

    def labels(self, choice: NDArray[np.intp], normal_shift: NDArray[np.float64], tolerance: float) -> NDArray[np.int8]:
        """Region codes of the zone points per trial, shape (T, Z).

        Parameters
        ----------
        choice : ndarray of intp, shape (T,)
            Index into ``candidates`` of each trial's extreme point.
        normal_shift : ndarray, shape (T, n) [m]
            Normal displacements of all points.
        tolerance : float
            Radius-error tolerance of the growth [m].
        """
        half = self.certain_stop[choice].copy()
        for c, stacked in enumerate(self.stacked_checks):
            rows = np.flatnonzero(choice == c)
            if rows.size == 0 or stacked is None:
                continue
            window, matrix, residual, starts, ks = stacked
            # All windows are nested in the widest (c - k .. c + k): one product gives the
            # linearised circle residuals of every checked window, side by side.
            moved = np.abs(residual + normal_shift[np.ix_(rows, window)] @ matrix)
            fails = np.maximum.reduceat(moved, starts, axis=1) > tolerance  # (rows, checks)
            first = np.argmax(fails, axis=1)
            failed = fails[np.arange(rows.size), first]
            half[rows[failed]] = ks[first[failed]] - 1
        centre = self.candidate_offset[choice][:, np.newaxis]
        offset = self.zone_offset[np.newaxis, :]
        out = np.where(offset < centre - half[:, np.newaxis], self.before, self.after).astype(np.int8)
        out[np.abs(offset - centre) <= half[:, np.newaxis]] = self.region
        return out

    @cached_property
    def stacked_checks(self) -> tuple[_Stacked | None, ...]:
        """Per candidate, its checks as one product: ``(window, matrix, residual, starts, ks)``.

        ``window`` (m,) the widest window's indices; ``matrix`` (m, Σ m_k) the transposed
        projectors placed at each window's position in it; ``residual`` (Σ m_k,) the circle
        residuals; ``starts`` the first column of each check; ``ks`` their half-widths.
        """
        out: list[_Stacked | None] = []
        for checks in self.checks:
            if not checks:
                out.append(None)
                continue
            widest = checks[-1][0]
            sizes = [2 * k + 1 for k, *_ in checks]
            matrix = np.zeros((2 * widest + 1, sum(sizes)))
            column = 0
            for (k, _, _, projector), size in zip(checks, sizes):
                matrix[widest - k : widest + k + 1, column : column + size] = projector.T
                column += size
            starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.intp)
            residual = np.concatenate([r for _, _, r, _ in checks])
            ks = np.array([k for k, *_ in checks], dtype=np.intp)
            out.append((checks[-1][1], matrix, residual, starts, ks))
        return tuple(out)


@dataclass(frozen=True, eq=False)
class FrozenSectionModel:
    """Section parameters of many perturbed clouds at once (see module docstring).

    Attributes
    ----------
    points : ndarray, shape (n, 2) [m]
        Unperturbed measured points in contour order.
    normals : ndarray, shape (n, 2)
        Outward nominal normals at the registration feet (measured frame).
    residual : ndarray, shape (n,) [m]
        Signed distances to the registered nominal curve.
    labels : ndarray of int8, shape (n,)
        Frozen region codes.
    jacobian : ndarray, shape (n, 3) [1, 1, m]
        Registration model matrix A.
    solve : ndarray, shape (3, n) [1, 1, 1/m]
        G = pinv(A): registration change per normal displacement.
    base : ndarray, shape (9,) [m, rad]
        Parameters of the unperturbed cloud.
    subset : ndarray of intp, shape (m,)
        Points whose full 2-D displacement the thickness and chord need.
    thickness_points : ndarray of intp, shape (ka,)
        Positions in ``subset`` of the candidate pressure-side points.
    thickness_segments : ndarray of intp, shape (ka, ks, 2)
        Positions in ``subset`` of the start/end points of each candidate's suction segments.
    chord_pairs : ndarray of intp, shape (kc, 2)
        Positions in ``subset`` of the candidate farthest pairs.
    bound : float
        Largest displacement of any point under any draw [m] (6σ for unbounded sources).
    edges : tuple of EdgeWindows, or None
        Leading- and trailing-edge growth per trial (re-segmentation of the edge regions);
        None: the segmentation is frozen.
    pair_edges : ndarray of intp, shape (kc, 2), or None
        Per chord pair, the index of its leading- and trailing-edge end in the edges' candidates.
    edge_tolerance : float
        Radius-error tolerance of the edge growth [m].
    """

    points: NDArray[np.float64]
    normals: NDArray[np.float64]
    residual: NDArray[np.float64]
    labels: NDArray[np.int8]
    jacobian: NDArray[np.float64]
    solve: NDArray[np.float64]
    base: NDArray[np.float64]
    subset: NDArray[np.intp]
    thickness_points: NDArray[np.intp]
    thickness_segments: NDArray[np.intp]
    chord_pairs: NDArray[np.intp]
    bound: float
    edges: tuple[EdgeWindows, EdgeWindows] | None = None
    pair_edges: NDArray[np.intp] | None = None
    edge_tolerance: float = 10e-6

    def evaluate(self, normal_shift: NDArray[np.float64], subset_shift: NDArray[np.float64]) -> NDArray[np.float64]:
        """Parameters of T perturbed clouds.

        Parameters
        ----------
        normal_shift : ndarray, shape (T, n) [m]
            Displacement of every point along ``normals``.
        subset_shift : ndarray, shape (T, m, 2) [m]
            Full displacement of the ``subset`` points.

        Returns
        -------
        ndarray, shape (T, 9) [m, rad]
            Columns in :data:`~.section.PARAMETER_NAMES` order.
        """
        trials = normal_shift.shape[0]
        out = np.empty((trials, len(PARAMETER_NAMES)))
        out[:, 0], pair_length2 = self._thickness_and_pairs(subset_shift)
        out[:, 1] = np.sqrt(pair_length2.max(axis=1))
        change = normal_shift @ self.solve_t  # (T, 3)
        out[:, 2:5] = self.base[2:5] + change
        # ``normal_shift - change @ jacobian_t`` column by column: a matmul with an inner
        # dimension of 3 runs about 3x slower than three broadcast updates (profiled at 10^5 trials).
        residual = normal_shift + self.residual
        for k in range(3):
            residual -= change[:, k, np.newaxis] * self.jacobian_t[k]
        if self.edges is None or self.pair_edges is None:
            for region, runs in enumerate(self.region_runs):
                high = np.max([residual[:, a:b].max(axis=1) for a, b in runs], axis=0)
                low = np.min([residual[:, a:b].min(axis=1) for a, b in runs], axis=0)
                out[:, 5 + region] = high - low
            return out
        pair = np.argmax(pair_length2, axis=1)
        zones = [
            (edge.zone, edge.labels(self.pair_edges[pair, e], normal_shift, self.edge_tolerance))
            for e, edge in enumerate(self.edges)
        ]
        for region, runs in enumerate(self.fixed_runs):
            high = np.full(trials, -np.inf)
            low = np.full(trials, np.inf)
            for first, stop in runs:
                high = np.maximum(high, residual[:, first:stop].max(axis=1))
                low = np.minimum(low, residual[:, first:stop].min(axis=1))
            for zone, labels in zones:
                values = residual[:, zone]
                member = labels == region
                high = np.maximum(high, np.where(member, values, -np.inf).max(axis=1))
                low = np.minimum(low, np.where(member, values, np.inf).min(axis=1))
            out[:, 5 + region] = high - low
        return out

    def lengths(self, subset_shift: NDArray[np.float64]) -> NDArray[np.float64]:
        """Maximum thickness and chord of T perturbed clouds, shape (T, 2) [m] (as :meth:`evaluate`).

        Parameters
        ----------
        subset_shift : ndarray, shape (T, m, 2) [m]
            Full displacement of the ``subset`` points.
        """
        out = np.empty((subset_shift.shape[0], 2))
        out[:, 0], pair_length2 = self._thickness_and_pairs(subset_shift)
        out[:, 1] = np.sqrt(pair_length2.max(axis=1))
        return out

    def _thickness_and_pairs(
        self, subset_shift: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Per trial the maximum thickness (T,) [m] and the squared length of each chord pair (T, kc) [m²]."""
        moved = self.points[self.subset] + subset_shift  # (T, m, 2)
        a = moved[:, self.thickness_points, np.newaxis, :]
        s0 = moved[:, self.thickness_segments[..., 0], :]
        s1 = moved[:, self.thickness_segments[..., 1], :]
        thickness = _segment_distance(a, s0, s1).min(axis=2).max(axis=1)
        ends = moved[:, self.chord_pairs[:, 0], :] - moved[:, self.chord_pairs[:, 1], :]
        return thickness, np.einsum("tki,tki->tk", ends, ends)

    @cached_property
    def solve_t(self) -> NDArray[np.float64]:
        """``solve.T`` stored contiguously, shape (n, 3)."""
        return np.ascontiguousarray(self.solve.T)

    @cached_property
    def jacobian_t(self) -> NDArray[np.float64]:
        """``jacobian.T`` stored contiguously, shape (3, n)."""
        return np.ascontiguousarray(self.jacobian.T)

    @cached_property
    def region_runs(self) -> tuple[tuple[tuple[int, int], ...], ...]:
        """Contiguous index runs ``(start, stop)`` of each region (a region through 0 has two)."""
        return _runs(self.labels)

    @cached_property
    def fixed_runs(self) -> tuple[tuple[tuple[int, int], ...], ...]:
        """As :attr:`region_runs`, without the edge zones' points (their labels vary per trial)."""
        labels = self.labels.astype(np.int16)
        for edge in self.edges or ():
            labels[edge.zone] = -1
        return _runs(labels)


def _runs(labels: NDArray[np.integer[Any]]) -> tuple[tuple[tuple[int, int], ...], ...]:
    """Contiguous index runs ``(start, stop)`` of each region code in ``labels``."""
    runs: list[tuple[tuple[int, int], ...]] = []
    for region in range(len(REGIONS)):
        index = np.flatnonzero(labels == region)
        if index.size == 0:
            runs.append(())
            continue
        cuts = np.flatnonzero(np.diff(index) > 1) + 1
        runs.append(tuple((int(part[0]), int(part[-1]) + 1) for part in np.split(index, cuts)))
    return tuple(runs)


def _circle_check(
    points: NDArray[np.float64], window: NDArray[np.intp], bound: NDArray[np.float64], tolerance: float
) -> tuple[str, NDArray[np.float64], NDArray[np.float64]]:
    """Whether the circle fit of ``points[window]`` passes the tolerance under every draw
    (``bound``: largest normal displacement of each point, shape (n,) [m]).

    Returns ``(verdict, residual, projector)``: verdict ``pass``, ``fail`` or ``check`` (the
    draws decide), the circle residuals and ``I - H`` of the linearised fit.
    """
    q = points[window]
    circle = fit_circle(q)
    diff = q - np.asarray(circle.centre)
    distance = np.linalg.norm(diff, axis=1)
    residual = distance - circle.radius
    jacobian = np.column_stack([-diff / distance[:, np.newaxis], -np.ones_like(distance)])
    projector = np.eye(window.size) - jacobian @ np.linalg.pinv(jacobian)
    # Largest change of any residual under normal displacements within ±bound (linearised),
    # plus slack for the second order (displacement²/radius) and the radial/normal angle.
    margin = float((np.abs(projector) @ bound[window]).max()) + _EDGE_SLACK
    error = float(np.abs(residual).max())
    verdict = "pass" if error + margin < tolerance else "fail" if error - margin > tolerance else "check"
    return verdict, residual, projector


_Check = tuple[int, NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]
"""One uncertain window size of an edge candidate: ``(k, window, residual, projector)``."""


def _candidate_growth(
    p: NDArray[np.float64], c: int, start: int, limit: int, bound: NDArray[np.float64], tolerance: float
) -> tuple[int, tuple[_Check, ...]] | None:
    """Where the growth around candidate ``c`` stops when no uncertain size fails, and its uncertain
    sizes; None where the first window could fail or the growth reaches ``limit``."""
    n = p.shape[0]
    if _circle_check(p, np.arange(c - start, c + start + 1) % n, bound, tolerance)[0] != "pass":
        return None
    found: list[_Check] = []
    k = start + 1
    while True:
        if k > limit:
            return None
        window = np.arange(c - k, c + k + 1) % n
        verdict, residual, projector = _circle_check(p, window, bound, tolerance)
        if verdict == "fail":
            return k - 1, tuple(found)
        if verdict == "check":
            found.append((k, window, residual, projector))
        k += 1


def _edge_windows(
    evaluation: SectionEvaluation,
    chord_pairs: NDArray[np.intp],
    options: SectionOptions,
    bound: NDArray[np.float64],
) -> tuple[tuple[EdgeWindows, EdgeWindows], NDArray[np.intp]] | None:
    """Per-trial edge growth of both edges, or None where the frozen segmentation must stand."""
    p = evaluation.points
    n = p.shape[0]
    seg = evaluation.segmentation
    tolerance = options.edge_tolerance
    start = options.initial_half_width
    flow = np.asarray(options.flow_direction, dtype=np.float64)
    first_is_le = p[chord_pairs[:, 0]] @ flow <= p[chord_pairs[:, 1]] @ flow
    ends = np.column_stack(
        [
            np.where(first_is_le, chord_pairs[:, 0], chord_pairs[:, 1]),
            np.where(first_is_le, chord_pairs[:, 1], chord_pairs[:, 0]),
        ]
    )
    gap = min(
        (seg.trailing_edge_point - seg.leading_edge_point) % n, (seg.leading_edge_point - seg.trailing_edge_point) % n
    )
    limit = max(gap // 2 - 1, start)
    edges = []
    pair_edges = np.empty_like(ends)
    for e, (anchor, region) in enumerate(
        ((seg.leading_edge_point, LEADING_EDGE), (seg.trailing_edge_point, TRAILING_EDGE))
    ):
        candidates, inverse = np.unique(ends[:, e], return_inverse=True)
        pair_edges[:, e] = inverse.ravel()
        offset = (candidates - anchor + n // 2) % n - n // 2
        if np.abs(offset).max() > limit // 2:
            return None
        growth = [_candidate_growth(p, int(c), start, limit, bound, tolerance) for c in candidates]
        if any(g is None for g in growth):
            return None
        stops = [g[0] for g in growth if g is not None]
        checks = [g[1] for g in growth if g is not None]
        widest = max(stops)
        low = int(offset.min()) - widest
        high = int(offset.max()) + widest
        zone_offset = np.arange(low - 1, high + 2)
        zone = (anchor + zone_offset) % n
        before_label = int(seg.labels[(anchor + low - 2) % n])
        after_label = int(seg.labels[(anchor + high + 2) % n])
        if REGIONS[before_label] in ("leading_edge", "trailing_edge") or REGIONS[after_label] in (
            "leading_edge",
            "trailing_edge",
        ):
            return None
        edges.append(
            EdgeWindows(
                candidates=candidates,
                certain_stop=np.array(stops, dtype=np.intp),
                checks=tuple(checks),
                zone=zone,
                candidate_offset=offset.astype(np.intp),
                zone_offset=zone_offset,
                before=before_label,
                after=after_label,
                region=region,
            )
        )
    # The zones must hold the frozen edge regions entirely and must not overlap each other.
    zones = np.concatenate([edge.zone for edge in edges])
    if np.unique(zones).size != zones.size:
        return None
    for edge in edges:
        frozen = np.flatnonzero(seg.labels == edge.region)
        if not np.isin(frozen, edge.zone).all():
            return None
    return (edges[0], edges[1]), pair_edges


def _point_bounds(
    sources: Sequence[ErrorSource], normals: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per point, the largest displacement and the largest displacement along the normal [m]."""
    per_point = np.zeros(normals.shape[0])
    along_normal = np.zeros(normals.shape[0])  # what ``normal_shift`` holds
    for source in sources:
        scale = draw_bound(source.distribution)
        if source.kind == "xy":
            per_point += np.sqrt(2.0) * np.abs(source.gain) * scale
            along_normal += np.abs(source.gain) * np.abs(normals).sum(axis=1) * scale
        else:
            per_point += np.linalg.norm(source.gain, axis=1) * scale
            along_normal += np.abs(np.einsum("ij,ij->i", source.gain, normals)) * scale
    return per_point, along_normal


def _thickness_candidates(
    p: NDArray[np.float64], pressure: NDArray[np.intp], suction: NDArray[np.intp], bound: float
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]:
    """Pressure-side points and suction segments that can attain the maximum thickness under
    any draw within ``bound``: ``(points, segments, segment starts, segment ends)``.

    Each pressure point's reach (distance to the suction side) is the minimum over the segments
    that can be nearest (:func:`~.section._candidate_segments`, every tie among them), then the
    full row of distances only for the points kept: the same values as the full matrix.
    """
    a = p[pressure]
    s0, s1 = p[suction[:-1]], p[suction[1:]]
    longest = float(np.sqrt(np.maximum(((s1 - s0) ** 2).sum(axis=1), 1e-300).max()))
    near = _candidate_segments(a, p[suction], longest)
    reach = _segment_distance(a[:, np.newaxis, :], s0[near], s1[near]).min(axis=1)
    _, _, interior = point_to_polyline(a, p[suction])
    best = reach[interior].max()
    keep = np.flatnonzero(reach >= best - 4.0 * bound)
    distance = _segment_distance(a[keep][:, np.newaxis, :], s0[np.newaxis, :, :], s1[np.newaxis, :, :])
    rows = [np.flatnonzero(distance[i] <= reach[k] + 4.0 * bound) for i, k in enumerate(keep)]
    last = suction.size - 2
    if any(r[0] == 0 or r[-1] == last for r in rows):
        msg = (
            "the maximum thickness lies within the error bound of a suction-side end; "
            "the batched model needs it inside the side"
        )
        raise ConfigError(msg)
    width = max(len(r) for r in rows)
    segments = np.array([np.concatenate([r, np.full(width - len(r), r[0])]) for r in rows])
    return pressure[keep], segments, suction[segments], suction[segments + 1]


def _chord_candidates(p: NDArray[np.float64], chord_points: tuple[int, int], bound: float) -> NDArray[np.intp]:
    """Pairs of points that could be the farthest pair under any draw within ``bound``, shape (k, 2).

    A point's largest distance to the hull is at most its distance to the hull's centroid plus
    the hull's radius about it: points whose bound stays below the threshold are skipped, the
    others get the exact distances (the same pairs as over every point).
    """
    n = p.shape[0]
    try:
        hull = ConvexHull(p).vertices
    except QhullError:
        hull = np.arange(n)
    chord0 = float(np.linalg.norm(p[chord_points[0]] - p[chord_points[1]]))
    threshold = chord0 - 4.0 * bound
    centre = p[hull].mean(axis=0)
    radius = float(np.sqrt(((p[hull] - centre) ** 2).sum(axis=1)).max())
    reachable = (np.sqrt(((p - centre) ** 2).sum(axis=1)) + radius) * (1.0 + 1e-9) >= threshold
    tried = np.flatnonzero(reachable)
    far = np.sqrt(((p[tried][:, np.newaxis, :] - p[hull][np.newaxis, :, :]) ** 2).sum(axis=-1)).max(axis=1)
    ends_ok = tried[far >= threshold]
    pair_d = np.sqrt(((p[ends_ok][:, np.newaxis, :] - p[ends_ok][np.newaxis, :, :]) ** 2).sum(axis=-1))
    ii, jj = np.nonzero(np.triu(pair_d >= threshold, k=1))
    return np.column_stack([ends_ok[ii], ends_ok[jj]])


def build_frozen_model(
    evaluation: SectionEvaluation,
    sources: Sequence[ErrorSource],
    options: SectionOptions | None = None,
    *,
    resegment_edges: bool = True,
) -> FrozenSectionModel:
    """Freeze the evaluation's segmentation and correspondences and pick the max/min candidates.

    Parameters
    ----------
    evaluation : SectionEvaluation
        Unperturbed evaluation of the measured cloud.
    sources : sequence of ErrorSource
        The sources that will perturb it (their bounds size the candidate windows).
    options : SectionOptions, optional
        The evaluation's settings (edge tolerance, initial half-width, flow direction).
    resegment_edges : bool
        Grow the edge regions per trial (:class:`EdgeWindows`) instead of freezing them; falls
        back to the frozen regions where the growth cannot be bounded (an edge window reaching
        the other edge, or a first window the draws could fail).

    Returns
    -------
    FrozenSectionModel
    """
    p = evaluation.points
    per_point, along_normal = _point_bounds(sources, evaluation.registration.normal)
    bound = float(per_point.max()) * _BOUND_MARGIN
    seg = evaluation.segmentation
    thick_points, segments, starts, ends = _thickness_candidates(
        p, seg.indices(PRESSURE_SIDE), seg.indices(SUCTION_SIDE), bound
    )
    chord_pairs = _chord_candidates(p, evaluation.chord_points, bound)
    subset, inverse = np.unique(
        np.concatenate([thick_points, starts.ravel(), ends.ravel(), chord_pairs.ravel()]), return_inverse=True
    )
    inverse = inverse.ravel()
    k1 = thick_points.size
    k2 = k1 + starts.size
    k3 = k2 + ends.size
    reg = evaluation.registration
    solve = np.asarray(np.linalg.pinv(reg.jacobian), dtype=np.float64)
    arrays: list[NDArray[Any]] = [p, reg.normal, reg.residual, seg.labels, reg.jacobian, solve]
    for array in arrays:
        array.setflags(write=False)
    opts = SectionOptions() if options is None else options
    growth = _edge_windows(evaluation, chord_pairs, opts, along_normal * _BOUND_MARGIN) if resegment_edges else None
    return FrozenSectionModel(
        points=p,
        normals=reg.normal,
        residual=reg.residual,
        labels=seg.labels,
        jacobian=reg.jacobian,
        solve=solve,
        base=evaluation.parameters.as_array(),
        subset=subset,
        thickness_points=inverse[:k1],
        thickness_segments=np.stack(
            [inverse[k1:k2].reshape(segments.shape), inverse[k2:k3].reshape(segments.shape)], axis=-1
        ),
        chord_pairs=inverse[k3:].reshape(-1, 2),
        bound=bound,
        edges=None if growth is None else growth[0],
        pair_edges=None if growth is None else growth[1],
        edge_tolerance=opts.edge_tolerance,
    )
