"""Blade-section parameters from a measured point cloud and the nominal section (the blade reference paper, §2).

Each step is a pure function over arrays, SI units inside:

- :func:`order_along_contour`: measured points sorted by their feet on the nominal curve after
  registration (refuses open sections: a gap over 5 % of the perimeter);
- :func:`max_thickness`: the reference paper's §2.1 steps 8-9, the largest over pressure-side points of
  the distance to the suction side, with the suction side taken as the polyline through its
  points (the reference paper densifies it with a B-spline; the polyline's chord sag is below 0.1 µm at
  the reference paper's point density). Where the suction side is flatter than the largest inscribed
  circle, which holds for blade sections, this is that circle's diameter;
- :func:`chord_length`: leading/trailing edge point method, the distance between the two
  points farthest apart (the extreme points of §2.1 step 1);
- position and twist: :func:`~robocal_uncertainty.inspection.registration.register_to_nominal`;
- :func:`profile_deviations`: per region, max minus min of the signed normal distances to the
  registered nominal curve (periodic cubic interpolating spline through the nominal points).
"""

from __future__ import annotations

import itertools
from dataclasses import astuple, dataclass, fields, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal_uncertainty.core.instruments.cmm import as_points
from robocal_uncertainty.errors import InputError
from robocal_uncertainty.inspection.nominal_curve import NominalCurve
from robocal_uncertainty.inspection.point_cloud import PointCloud
from robocal_uncertainty.inspection.registration import Registration, register_to_nominal
from robocal_uncertainty.inspection.segmentation import (
    PRESSURE_SIDE,
    REGIONS,
    SUCTION_SIDE,
    Segmentation,
    farthest_pair,
    segment_section,
)

__all__ = [
    "PARAMETER_NAMES",
    "PARAMETER_UNITS",
    "SectionEvaluation",
    "SectionOptions",
    "SectionParameters",
    "Thickness",
    "chord_length",
    "evaluate_section",
    "max_thickness",
    "order_along_contour",
    "point_to_polyline",
    "profile_deviations",
]

_OPEN_GAP = 0.05
"""Largest gap between consecutive feet, as a fraction of the perimeter, of a closed section."""
_MIN_POINTS = 20
_SIZE_RATIO = (0.2, 5.0)
"""Accepted range of measured over nominal extent; unit mix-ups are factors of 10 or more."""


@dataclass(frozen=True)
class SectionParameters:
    """The reference paper's five parameter kinds of one section.

    Attributes
    ----------
    max_thickness : float
        Maximum thickness [m].
    chord_length : float
        Chord length, leading/trailing edge point method [m].
    axial_offset : float
        Position offset along x (axial) [m].
    circumferential_offset : float
        Position offset along y (circumferential) [m].
    twist_angle : float
        Twist about the stacking point [rad], counterclockwise positive.
    profile_leading_edge, profile_trailing_edge, profile_pressure_side, profile_suction_side : float
        Profile deviation (max minus min signed normal distance) per region [m].
    """

    max_thickness: float
    chord_length: float
    axial_offset: float
    circumferential_offset: float
    twist_angle: float
    profile_leading_edge: float
    profile_trailing_edge: float
    profile_pressure_side: float
    profile_suction_side: float

    def as_array(self) -> NDArray[np.float64]:
        """Values in :data:`PARAMETER_NAMES` order, shape (9,) [m, rad]."""
        return np.array(astuple(self), dtype=np.float64)

    @classmethod
    def from_array(cls, values: ArrayLike) -> SectionParameters:
        """Inverse of :meth:`as_array`."""
        array = np.asarray(values, dtype=np.float64)
        if array.shape != (len(PARAMETER_NAMES),):
            msg = f"values must have shape ({len(PARAMETER_NAMES)},), got {array.shape}"
            raise InputError(msg)
        return cls(*(float(v) for v in array))


PARAMETER_NAMES: tuple[str, ...] = tuple(f.name for f in fields(SectionParameters))
"""Output names, in column order of every Monte Carlo result."""
PARAMETER_UNITS: tuple[str, ...] = ("m", "m", "m", "m", "rad", "m", "m", "m", "m")
"""SI unit of each parameter."""


@dataclass(frozen=True)
class SectionOptions:
    """Settings of the section evaluation.

    Attributes
    ----------
    edge_tolerance : float
        Radius error that stops the growth of the edge circles [m].
    initial_half_width : int
        Points on each side of an edge extreme point in the first circle fit.
    flow_direction : tuple of float
        Flow direction in the section plane (leading edge upstream), dimensionless.
    pivot : tuple of float or None
        Stacking point of the twist [m]; None: the nominal section's area centroid.
    """

    edge_tolerance: float = 10e-6
    initial_half_width: int = 2
    flow_direction: tuple[float, float] = (1.0, 0.0)
    pivot: tuple[float, float] | None = None


@dataclass(frozen=True)
class Thickness:
    """Maximum thickness and where it is.

    Attributes
    ----------
    value : float
        Maximum thickness [m].
    pressure_point : int
        Index (into the pressure-side points given) of the point attaining it.
    suction_segment : int
        Index of the suction-side polyline segment nearest that point.
    """

    value: float
    pressure_point: int
    suction_segment: int


@dataclass(frozen=True, eq=False)
class SectionEvaluation:
    """Everything :func:`evaluate_section` found.

    Attributes
    ----------
    parameters : SectionParameters
        The section parameters.
    order : ndarray of intp, shape (n,)
        Input point indices in contour order.
    points : ndarray, shape (n, 2) [m]
        Measured points in contour order.
    segmentation : Segmentation
        Regions of the ordered points.
    registration : Registration
        Registration of the ordered points to the nominal curve.
    thickness : Thickness
        Maximum-thickness location (indices into the pressure-side / suction-side points).
    chord_points : tuple of int
        Ordered-point indices of the chord end points.
    """

    parameters: SectionParameters
    order: NDArray[np.intp]
    points: NDArray[np.float64]
    segmentation: Segmentation
    registration: Registration
    thickness: Thickness
    chord_points: tuple[int, int]


def point_to_polyline(
    points: ArrayLike, polyline: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.intp], NDArray[np.bool_]]:
    """Distance of each point to an open polyline, the nearest segment, and whether the foot is
    inside the polyline (not clamped to its first or last vertex).

    Parameters
    ----------
    points : array_like, shape (m, 2) [m]
        Query points.
    polyline : array_like, shape (k, 2) [m]
        Vertices in order, k >= 2.

    Returns
    -------
    distance : ndarray, shape (m,) [m]
    segment : ndarray of intp, shape (m,)
        Index of the nearest segment (vertices ``segment`` and ``segment + 1``).
    interior : ndarray of bool, shape (m,)
        False where the nearest polyline point is its first or last vertex.
    """
    a = as_points(points, "points")
    b = as_points(polyline, "polyline")
    if b.shape[0] < 2:
        msg = f"polyline needs at least 2 vertices, got {b.shape[0]}"
        raise InputError(msg)
    start = b[:-1]
    edge = b[1:] - start
    length2 = np.maximum((edge**2).sum(axis=1), 1e-300)
    candidates = _candidate_segments(a, b, float(np.sqrt(length2.max())))
    rel = a[:, np.newaxis, :] - start[candidates]
    t = np.clip((rel * edge[candidates]).sum(axis=-1) / length2[candidates], 0.0, 1.0)
    gap = rel - t[..., np.newaxis] * edge[candidates]
    dist2 = (gap**2).sum(axis=-1)
    rows = np.arange(a.shape[0])
    # Candidates ascend along each row: the first minimum is the lowest segment index, as over all.
    pick = np.argmin(dist2, axis=1)
    segment = candidates[rows, pick]
    foot = t[rows, pick]
    interior = ~(((segment == 0) & (foot <= 0.0)) | ((segment == edge.shape[0] - 1) & (foot >= 1.0)))
    return np.sqrt(dist2[rows, pick]), segment, interior


_ALL_SEGMENTS = 20_000
"""Point-segment pairs up to which every segment is tried (building a tree costs more)."""


def _candidate_segments(points: NDArray[np.float64], polyline: NDArray[np.float64], longest: float) -> NDArray[np.intp]:
    """Segments that can be nearest to each point, ascending per row (padded with the row's first).

    A segment at distance d from a point has both vertices within d + (its length) of it, and
    the nearest segment is no farther than the nearest vertex: every segment with a vertex within
    (nearest-vertex distance + longest segment) of the point is a candidate, so the nearest one
    (and every tie) is among them and the result equals the search over all segments.
    """
    n_segments = polyline.shape[0] - 1
    if points.shape[0] * n_segments <= _ALL_SEGMENTS:
        return np.broadcast_to(np.arange(n_segments), (points.shape[0], n_segments))
    from scipy.spatial import cKDTree

    tree = cKDTree(polyline)
    nearest, _ = tree.query(points)
    # The relative margin covers the rounding of the distances the bound compares.
    radius = (nearest + longest) * (1.0 + 1e-9) + 1e-12
    near = tree.query_ball_point(points, radius)
    lengths = np.fromiter((len(v) for v in near), dtype=np.intp, count=len(near))
    vertex = np.fromiter(itertools.chain.from_iterable(near), dtype=np.intp, count=int(lengths.sum()))
    row = np.repeat(np.arange(points.shape[0]), lengths)
    # The segments on either side of each vertex, sorted by row then segment, duplicates dropped.
    key = np.unique(
        np.concatenate([row, row]) * n_segments + np.clip(np.concatenate([vertex - 1, vertex]), 0, n_segments - 1)
    )
    row, segment = np.divmod(key, n_segments)
    counts = np.bincount(row, minlength=points.shape[0])
    first = np.cumsum(counts) - counts
    out = np.repeat(segment[first][:, np.newaxis], int(counts.max()), axis=1)
    out[row, np.arange(key.shape[0]) - first[row]] = segment
    return out


def max_thickness(pressure_side: ArrayLike, suction_side: ArrayLike) -> Thickness:
    """Maximum thickness: largest distance from a pressure-side point to the suction side.

    Only pressure-side points whose nearest suction-side point lies inside the suction-side
    polyline count (a point beyond its end would measure a slanted distance to the end vertex).

    Parameters
    ----------
    pressure_side : array_like, shape (m, 2) [m]
        Pressure-side points (any order), m >= 1.
    suction_side : array_like, shape (k, 2) [m]
        Suction-side points in contour order (the polyline), k >= 2.

    Returns
    -------
    Thickness
    """
    distance, segment, interior = point_to_polyline(pressure_side, suction_side)
    if not interior.any():
        msg = "no pressure-side point lies across from the suction side; cannot measure thickness"
        raise InputError(msg)
    best = int(np.argmax(np.where(interior, distance, -np.inf)))
    return Thickness(float(distance[best]), best, int(segment[best]))


def chord_length(points: ArrayLike) -> tuple[float, int, int]:
    """Chord length by the leading/trailing edge point method.

    Parameters
    ----------
    points : array_like, shape (n, 2) [m]
        Section points.

    Returns
    -------
    tuple
        ``(chord [m], i, j)``: the distance of the farthest pair and their indices.
    """
    p = as_points(points, "points")
    i, j = farthest_pair(p)
    return float(np.linalg.norm(p[i] - p[j])), i, j


def profile_deviations(residual: ArrayLike, labels: ArrayLike) -> NDArray[np.float64]:
    """Max minus min signed normal distance per region.

    Parameters
    ----------
    residual : array_like, shape (..., n) [m]
        Signed normal distances to the registered nominal curve.
    labels : array_like of int, shape (n,)
        Region code per point (see :data:`~robocal_uncertainty.inspection.segmentation.REGIONS`).

    Returns
    -------
    ndarray, shape (..., 4) [m]
        Leading edge, trailing edge, pressure side, suction side.
    """
    r = np.asarray(residual, dtype=np.float64)
    codes = np.asarray(labels)
    out = np.empty((*r.shape[:-1], len(REGIONS)))
    for region in range(len(REGIONS)):
        part = r[..., codes == region]
        if part.shape[-1] == 0:
            msg = f"region {REGIONS[region]} has no points"
            raise InputError(msg)
        out[..., region] = part.max(axis=-1) - part.min(axis=-1)
    return out


def order_along_contour(parameter: ArrayLike, period: float) -> NDArray[np.intp]:
    """Indices sorting points by their nominal-curve parameter; refuses open sections.

    Parameters
    ----------
    parameter : array_like, shape (n,) [m]
        Foot parameter of each point on the nominal curve, in [0, period).
    period : float
        Perimeter of the nominal curve [m].

    Returns
    -------
    ndarray of intp, shape (n,)
    """
    u = np.asarray(parameter, dtype=np.float64)
    order = np.argsort(u, kind="stable")
    sorted_u = u[order]
    gaps = np.diff(np.concatenate([sorted_u, sorted_u[:1] + period]))
    widest = int(np.argmax(gaps))
    if gaps[widest] > _OPEN_GAP * period:
        msg = (
            f"the section is open: no points over {gaps[widest] * 1e3:.3g} mm "
            f"({100 * gaps[widest] / period:.0f} % of the contour) after nominal position "
            f"{sorted_u[widest] * 1e3:.3g} mm"
        )
        raise InputError(msg)
    return order


def evaluate_section(
    points: PointCloud | ArrayLike,
    curve: NominalCurve,
    options: SectionOptions | None = None,
) -> SectionEvaluation:
    """All section parameters of a measured cloud against the nominal curve.

    Parameters
    ----------
    points : PointCloud or array_like, shape (n, 2) [m]
        Measured section points (any order), n >= 20; of a PointCloud only x and y are used.
    curve : NominalCurve
        Nominal section curve.
    options : SectionOptions, optional
        Evaluation settings; defaults as documented there.

    Returns
    -------
    SectionEvaluation
    """
    opts = SectionOptions() if options is None else options
    xy = points.xy if isinstance(points, PointCloud) else as_points(points, "points")
    if xy.shape[0] < _MIN_POINTS:
        msg = f"a section needs at least {_MIN_POINTS} points, got {xy.shape[0]}"
        raise InputError(msg)
    size = float(np.ptp(xy, axis=0).max())
    nominal_size = float(np.ptp(curve.section.points, axis=0).max())
    if not _SIZE_RATIO[0] <= size / nominal_size <= _SIZE_RATIO[1]:
        msg = (
            f"the measured points span {size * 1e3:.4g} mm but the nominal section {nominal_size * 1e3:.4g} mm: "
            "a different length unit (mm vs m?) or not this section"
        )
        raise InputError(msg)
    first = register_to_nominal(xy, curve, pivot=opts.pivot)
    order = order_along_contour(first.parameter, curve.period)
    p = xy[order]
    segmentation = segment_section(
        p,
        edge_tolerance=opts.edge_tolerance,
        initial_half_width=opts.initial_half_width,
        flow_direction=opts.flow_direction,
    )
    registration = replace(
        first,
        parameter=first.parameter[order],
        foot=first.foot[order],
        normal=first.normal[order],
        residual=first.residual[order],
        jacobian=first.jacobian[order],
    )
    pressure = p[segmentation.indices(PRESSURE_SIDE)]
    suction = p[segmentation.indices(SUCTION_SIDE)]
    thickness = max_thickness(pressure, suction)
    chord, i, j = chord_length(p)
    profile = profile_deviations(registration.residual, segmentation.labels)
    parameters = SectionParameters(
        thickness.value,
        chord,
        float(registration.offset[0]),
        float(registration.offset[1]),
        registration.twist,
        *(float(v) for v in profile),
    )
    return SectionEvaluation(parameters, order, p, segmentation, registration, thickness, (i, j))
