"""Segmentation of an ordered section contour into leading edge, trailing edge and the two sides.

The reference paper's steps (§2.1): the two points farthest apart are the leading- and trailing-edge
extreme points; from each, points are added on both sides one at a time and a least-squares
circle is fitted, until the radius error (largest |distance to centre - R| of the fitted points)
exceeds a threshold; the last accepted window is the edge region and its circle the edge circle.
The leading edge is the extreme point further upstream (smaller projection on the flow
direction, +x by default). The suction side is the side bulging further along the camber
direction from the chord line (the convex side); for an uncambered section, the side left of
the leading-to-trailing-edge line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import ConvexHull, QhullError

from robocal_uncertainty.core.instruments.cmm import as_points
from robocal_uncertainty.errors import InputError

__all__ = [
    "LEADING_EDGE",
    "PRESSURE_SIDE",
    "REGIONS",
    "SUCTION_SIDE",
    "TRAILING_EDGE",
    "Circle",
    "Segmentation",
    "farthest_pair",
    "fit_circle",
    "segment_section",
]

REGIONS = ("leading_edge", "trailing_edge", "pressure_side", "suction_side")
"""Region names, in the order of their integer codes 0..3."""
LEADING_EDGE, TRAILING_EDGE, PRESSURE_SIDE, SUCTION_SIDE = range(4)

_MIN_SECTION_POINTS = 20


@dataclass(frozen=True)
class Circle:
    """A fitted circle.

    Attributes
    ----------
    centre : tuple of float, length 2 [m]
        Centre.
    radius : float
        Radius [m].
    radius_error : float
        Largest |distance to centre - radius| of the fitted points [m].
    """

    centre: tuple[float, float]
    radius: float
    radius_error: float


@dataclass(frozen=True, eq=False)
class Segmentation:
    """Regions of an ordered contour.

    Attributes
    ----------
    labels : ndarray of int8, shape (n,)
        Region code of each point (0 leading edge, 1 trailing edge, 2 pressure side,
        3 suction side; see :data:`REGIONS`).
    leading_edge_point : int
        Index of the leading-edge extreme point (one of the farthest pair).
    trailing_edge_point : int
        Index of the trailing-edge extreme point.
    leading_edge_circle : Circle
        Least-squares circle of the leading-edge region.
    trailing_edge_circle : Circle
        Least-squares circle of the trailing-edge region.
    """

    labels: NDArray[np.int8]
    leading_edge_point: int
    trailing_edge_point: int
    leading_edge_circle: Circle
    trailing_edge_circle: Circle

    def indices(self, region: int) -> NDArray[np.intp]:
        """Point indices of region code ``region`` (0..3) in contour order (cyclic: a region
        running through index 0 starts at its first point after the wrap)."""
        index = np.flatnonzero(self.labels == region)
        breaks = np.flatnonzero(np.diff(index) > 1)
        if breaks.size:
            index = np.roll(index, -int(breaks[0] + 1))
        return index


def farthest_pair(points: ArrayLike) -> tuple[int, int]:
    """Indices of the two points farthest apart (the diameter of the set).

    Parameters
    ----------
    points : array_like, shape (n, 2) [m]
        Points, n >= 2.

    Returns
    -------
    tuple of int
        ``(i, j)`` with ``i < j``.
    """
    p = as_points(points, "points")
    if p.shape[0] < 2:
        msg = f"farthest pair needs at least 2 points, got {p.shape[0]}"
        raise InputError(msg)
    try:
        candidates = ConvexHull(p).vertices
    except QhullError:
        candidates = np.arange(p.shape[0])
    q = p[candidates]
    # x and y apart: the same sums as over a (h, h, 2) array, without building it.
    d2 = (q[:, np.newaxis, 0] - q[np.newaxis, :, 0]) ** 2 + (q[:, np.newaxis, 1] - q[np.newaxis, :, 1]) ** 2
    a, b = np.unravel_index(int(np.argmax(d2)), d2.shape)
    i, j = sorted((int(candidates[a]), int(candidates[b])))
    return i, j


def fit_circle(points: ArrayLike) -> Circle:
    """Least-squares (geometric) circle through points.

    Algebraic (Kåsa) fit as the start, then Gauss-Newton on the geometric distances.

    Parameters
    ----------
    points : array_like, shape (n, 2) [m]
        Points, n >= 3, not collinear.

    Returns
    -------
    Circle
    """
    p = as_points(points, "points")
    if p.shape[0] < 3:
        msg = f"a circle fit needs at least 3 points, got {p.shape[0]}"
        raise InputError(msg)
    mean = p.mean(axis=0)
    q = p - mean
    a = np.column_stack([2.0 * q, np.ones(q.shape[0])])
    sol, _, rank, _ = np.linalg.lstsq(a, (q**2).sum(axis=1), rcond=None)
    centre = sol[:2]
    radius = float(np.sqrt(max(sol[2] + centre @ centre, 0.0)))
    if rank < 3 or not np.isfinite(radius) or radius == 0.0:
        msg = "points are collinear; no circle fits them"
        raise InputError(msg)
    for _ in range(20):
        diff = q - centre
        dist = np.linalg.norm(diff, axis=1)
        jac = np.column_stack([-diff / dist[:, np.newaxis], -np.ones_like(dist)])
        step, *_ = np.linalg.lstsq(jac, -(dist - radius), rcond=None)
        centre = centre + step[:2]
        radius += float(step[2])
        if np.max(np.abs(step)) < 1e-15 * max(radius, 1e-300):
            break
    error = float(np.max(np.abs(np.linalg.norm(q - centre, axis=1) - radius)))
    c = centre + mean
    return Circle((float(c[0]), float(c[1])), abs(radius), error)


def _grow_edge(p: NDArray[np.float64], extreme: int, limit: int, start: int, tolerance: float) -> tuple[int, Circle]:
    """Half-width k of the edge window around ``extreme`` and its circle."""
    n = p.shape[0]
    k = start
    circle = fit_circle(p[np.arange(extreme - k, extreme + k + 1) % n])
    if circle.radius_error > tolerance:
        msg = (
            f"the edge at point {extreme} is not circular within {tolerance * 1e6:.3g} µm even over "
            f"{2 * start + 1} points (radius error {circle.radius_error * 1e6:.3g} µm); "
            "raise the edge tolerance or check the cloud"
        )
        raise InputError(msg)
    while k < limit:
        trial = fit_circle(p[np.arange(extreme - k - 1, extreme + k + 2) % n])
        if trial.radius_error > tolerance:
            break
        k += 1
        circle = trial
    return k, circle


def segment_section(
    points: ArrayLike,
    *,
    edge_tolerance: float = 10e-6,
    initial_half_width: int = 2,
    flow_direction: ArrayLike = (1.0, 0.0),
) -> Segmentation:
    """Split an ordered closed contour into leading edge, trailing edge, pressure and suction side.

    Parameters
    ----------
    points : array_like, shape (n, 2) [m]
        Contour points in order along the section (either orientation), n >= 20.
    edge_tolerance : float
        Radius-error threshold that ends the growth of an edge circle [m].
    initial_half_width : int
        Points taken on each side of an extreme point for the first circle (>= 1).
    flow_direction : array_like, shape (2,)
        Direction of the flow in the section plane; the leading edge is upstream.

    Returns
    -------
    Segmentation
    """
    p = as_points(points, "points")
    n = p.shape[0]
    if n < _MIN_SECTION_POINTS:
        msg = f"a section needs at least {_MIN_SECTION_POINTS} points, got {n}"
        raise InputError(msg)
    if not edge_tolerance > 0:
        msg = f"edge_tolerance must be > 0 [m], got {edge_tolerance!r}"
        raise InputError(msg)
    flow = np.asarray(flow_direction, dtype=np.float64)
    i, j = farthest_pair(p)
    le, te = (i, j) if p[i] @ flow <= p[j] @ flow else (j, i)
    gap = min((te - le) % n, (le - te) % n)
    limit = max(gap // 2 - 1, initial_half_width)
    k_le, le_circle = _grow_edge(p, le, limit, initial_half_width, edge_tolerance)
    k_te, te_circle = _grow_edge(p, te, limit, initial_half_width, edge_tolerance)
    labels = np.empty(n, dtype=np.int8)
    # Side a: from the leading edge to the trailing edge in index order; side b: the rest.
    side_a = np.arange(le + k_le + 1, le + (te - le) % n - k_te) % n
    side_b = np.arange(te + k_te + 1, te + (le - te) % n - k_le) % n
    chord = p[te] - p[le]
    left = np.array([-chord[1], chord[0]]) / np.linalg.norm(chord)
    offset_a = float(((p[side_a] - p[le]) @ left).mean()) if side_a.size else 0.0
    offset_b = float(((p[side_b] - p[le]) @ left).mean()) if side_b.size else 0.0
    camber = offset_a + offset_b
    scale = abs(offset_a) + abs(offset_b)
    if abs(camber) <= 1e-9 * max(scale, 1e-300):
        suction_is_a = offset_a > offset_b
    else:
        suction_is_a = offset_a * np.sign(camber) > offset_b * np.sign(camber)
    labels[side_a] = SUCTION_SIDE if suction_is_a else PRESSURE_SIDE
    labels[side_b] = PRESSURE_SIDE if suction_is_a else SUCTION_SIDE
    labels[np.arange(le - k_le, le + k_le + 1) % n] = LEADING_EDGE
    labels[np.arange(te - k_te, te + k_te + 1) % n] = TRAILING_EDGE
    if side_a.size == 0 or side_b.size == 0:
        msg = "segmentation left no pressure or suction side points; lower the edge tolerance"
        raise InputError(msg)
    return Segmentation(labels, int(le), int(te), le_circle, te_circle)
