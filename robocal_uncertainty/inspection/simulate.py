"""Simulated CMM scans of a nominal section with known true deviations (no instrument noise).

The true part is the nominal curve displaced along its outward normal by a form error
``a·sin(2π·waves·u/P + phase)`` (u the curve parameter, P the perimeter) plus an optional
deviation function of u (local features: :mod:`.coverage_study`), then rotated by the
twist about the stacking point and shifted by the offset. Points are spaced along the nominal
parameter with a density ``1 + edge_density·|κ|/max|κ|`` (κ the curvature), so the edges get
denser scanning than the sides, as CMM blade scans do. Probe vectors are the outward normals.
Instrument errors are added separately (:func:`~robocal_uncertainty.core.instruments.cmm.point_displacements`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal_uncertainty.errors import InputError
from robocal_uncertainty.inspection.nominal_curve import NominalCurve
from robocal_uncertainty.inspection.point_cloud import PointCloud
from robocal_uncertainty.inspection.registration import polygon_centroid, rotation

__all__ = ["scan_parameters", "simulate_section_scan"]


def scan_parameters(curve: NominalCurve, n_points: int, *, edge_density: float = 4.0) -> NDArray[np.float64]:
    """Nominal-curve parameters of ``n_points`` scan points, denser where the curve bends.

    Parameters
    ----------
    curve : NominalCurve
        Nominal curve.
    n_points : int
        Number of points (>= 20).
    edge_density : float
        Extra relative point density at the largest curvature (>= 0, dimensionless).

    Returns
    -------
    ndarray, shape (n_points,) [m]
        Increasing parameters in [0, period).
    """
    if isinstance(n_points, bool) or not isinstance(n_points, (int, np.integer)) or n_points < 20:
        msg = f"n_points must be an integer >= 20, got {n_points!r}"
        raise InputError(msg)
    if not (math.isfinite(edge_density) and edge_density >= 0):
        msg = f"edge_density must be finite and >= 0, got {edge_density!r}"
        raise InputError(msg)
    fine = np.linspace(0.0, curve.period, 64 * int(n_points), endpoint=False)
    kappa = np.abs(curve.curvature(fine))
    density = 1.0 + edge_density * kappa / kappa.max()
    cumulative = np.concatenate([[0.0], np.cumsum(density)])
    grid = np.concatenate([fine, [curve.period]])
    targets = np.arange(int(n_points)) * cumulative[-1] / int(n_points)
    return np.asarray(np.interp(targets, cumulative, grid))


def simulate_section_scan(
    curve: NominalCurve,
    n_points: int,
    *,
    offset: ArrayLike = (0.0, 0.0),
    twist: float = 0.0,
    form_amplitude: float = 0.0,
    form_waves: int = 3,
    form_phase: float = 0.0,
    pivot: ArrayLike | None = None,
    edge_density: float = 4.0,
    height: float = 0.0,
    deviation: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None = None,
    parameters: ArrayLike | None = None,
) -> PointCloud:
    """A noise-free scan of the nominal section with a known form error, offset and twist.

    Parameters
    ----------
    curve : NominalCurve
        Nominal curve.
    n_points : int
        Number of scan points (>= 20).
    offset : array_like, shape (2,) [m]
        True axial and circumferential offsets.
    twist : float
        True twist about ``pivot`` [rad], counterclockwise positive.
    form_amplitude : float
        Amplitude of the sinusoidal form error along the outward normal [m].
    form_waves : int
        Number of form-error waves around the contour.
    form_phase : float
        Phase of the form error [rad].
    pivot : array_like, shape (2,) [m], optional
        Stacking point; default the nominal area centroid.
    edge_density : float
        See :func:`scan_parameters`.
    height : float
        Section height z of every point [m].
    deviation : callable, optional
        ``deviation(u)`` [m], shape (n,), for the nominal-curve parameters u [m] of the points:
        an extra form error along the outward normal, added to the sinusoid.
    parameters : array_like, shape (n_points,) [m], optional
        Nominal-curve parameters of the scan points, in scan order (a measured cloud's point
        layout: its registered feet); default :func:`scan_parameters` (``edge_density``).

    Returns
    -------
    PointCloud
        Points [m] in contour order and outward unit probe vectors.
    """
    if parameters is None:
        u = scan_parameters(curve, n_points, edge_density=edge_density)
    else:
        u = np.asarray(parameters, dtype=np.float64)
        if u.shape != (n_points,) or not np.isfinite(u).all():
            msg = f"parameters must be {n_points} finite nominal-curve parameters [m], got shape {u.shape}"
            raise InputError(msg)
    centre = polygon_centroid(curve.section.points) if pivot is None else np.asarray(pivot, dtype=np.float64)
    normal = curve.outward_normal(u)
    form = form_amplitude * np.sin(2 * math.pi * form_waves * u / curve.period + form_phase)
    if deviation is not None:
        extra = np.asarray(deviation(u), dtype=np.float64)
        if extra.shape != u.shape or not np.isfinite(extra).all():
            msg = f"deviation(u) must give finite values of shape {u.shape}, got shape {extra.shape}"
            raise InputError(msg)
        form = form + extra
    true = curve.point(u) + form[:, np.newaxis] * normal
    r = rotation(float(twist))
    moved = (true - centre) @ r.T + centre + np.asarray(offset, dtype=np.float64)
    probe = normal @ r.T
    points = np.column_stack([moved, np.full(moved.shape[0], float(height))])
    vectors = np.column_stack([probe, np.zeros(moved.shape[0])])
    return PointCloud(points, vectors, f"simulated scan of {curve.section.source}")
