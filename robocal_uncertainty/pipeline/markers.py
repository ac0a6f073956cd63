"""RViz marker descriptions of an uncertainty result (ROS-free).

:func:`uncertainty_markers` turns a
:class:`~robocal_uncertainty.uncertainty.calibration.results.CalibrationUncertainty` into
:class:`MarkerSpec` values that the uncertainty node copies into a
``visualization_msgs/MarkerArray`` (``robocal/uncertainty_markers``):

* per test configuration, namespace ``coverage_region``: a SPHERE marker drawing the JCGM 102
  coverage ellipsoid ``{y : (y - ybar)^T V^-1 (y - ybar) <= k_p^2}`` of the tool position, at the
  Monte Carlo mean; its axes are the eigenvectors of V (the marker orientation, a right-handed
  rotation as a quaternion) and its diameters ``2 k_p sqrt(eigenvalue)`` times a visibility
  magnification (the marker scale). Micrometre regions are invisible at robot scale, so the
  magnification (a power of ten by default) is stated in a TEXT marker next to it
  (namespace ``coverage_label``) with the largest semi-axis in um;
* namespace ``campaign_points``: a SPHERE_LIST of the campaign's measured points.

Every marker is in ``result.frame_id`` (the robot base frame, e.g. ``base_link``, or the
measurement frame such as the tracker's), the TF name of the positions. Measured points of a
tracker-frame campaign evaluated in the base frame are taken into it with the calibrated base
transform. RViz draws a SPHERE's x, y, z scale along the axes of its pose orientation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.rotation import quaternion_from_matrix as rotation_quaternion
from robocal_uncertainty.errors import InputError
from robocal_uncertainty.uncertainty.calibration import CalibrationUncertainty

__all__ = [
    "MarkerSpec",
    "ellipsoid_axes",
    "quaternion_from_matrix",
    "uncertainty_markers",
    "visibility_scale",
]

Array = NDArray[np.float64]
MarkerKind = Literal["sphere", "sphere_list", "text"]

REGION_COLOR = (1.0, 0.4, 0.0, 0.6)
POINT_COLOR = (0.1, 0.6, 1.0, 0.9)
TEXT_COLOR = (1.0, 1.0, 1.0, 1.0)


@dataclass(frozen=True)
class MarkerSpec:
    """One RViz marker, ROS-free (field meanings as in ``visualization_msgs/Marker``).

    Attributes
    ----------
    namespace : str
    marker_id : int
    kind : {"sphere", "sphere_list", "text"}
    frame_id : str
        TF frame of the pose and points.
    position : ndarray, shape (3,) [m]
    orientation : ndarray, shape (4,)
        Unit quaternion (x, y, z, w).
    scale : ndarray, shape (3,) [m]
        Diameters along the marker's axes (sphere), point diameter (sphere list), text
        height in z (text).
    color : tuple of 4 float
        RGBA in [0, 1].
    points : ndarray, shape (n, 3) [m]
        Sphere-list points (empty otherwise).
    text : str
    """

    namespace: str
    marker_id: int
    kind: MarkerKind
    frame_id: str
    position: Array
    orientation: Array
    scale: Array
    color: tuple[float, float, float, float]
    points: Array = field(default_factory=lambda: np.zeros((0, 3)))
    text: str = ""


def quaternion_from_matrix(rotation: Array) -> Array:
    """Unit quaternion (x, y, z, w) of a proper rotation matrix, shape (3, 3) -> (4,).

    Raises
    ------
    InputError
        Not a rotation (not orthonormal or determinant -1).
    """
    r = np.asarray(rotation, dtype=np.float64)
    if r.shape != (3, 3) or not np.allclose(r @ r.T, np.eye(3), atol=1e-9) or np.linalg.det(r) < 0:
        msg = f"rotation must be a proper 3x3 rotation matrix, got shape {r.shape}"
        raise InputError(msg)
    return np.asarray(rotation_quaternion(r), dtype=np.float64)


def ellipsoid_axes(covariance: Array, coverage_factor: float) -> tuple[Array, Array]:
    """Semi-axes and axis directions of ``{y : y^T V^-1 y <= k^2}``.

    Parameters
    ----------
    covariance : ndarray, shape (3, 3) [m^2]
        V, symmetric positive semi-definite.
    coverage_factor : float
        k_p (dimensionless).

    Returns
    -------
    semi_axes : ndarray, shape (3,) [m]
        ``k sqrt(eigenvalues)``, largest first.
    rotation : ndarray, shape (3, 3)
        Proper rotation whose columns are the matching unit eigenvectors.
    """
    v = np.asarray(covariance, dtype=np.float64)
    if v.shape != (3, 3) or not np.all(np.isfinite(v)):
        msg = f"covariance must be a finite 3x3 matrix, got shape {v.shape}"
        raise InputError(msg)
    values, vectors = np.linalg.eigh(0.5 * (v + v.T))
    order = np.argsort(values)[::-1]
    values, vectors = np.clip(values[order], 0.0, None), vectors[:, order]
    if np.linalg.det(vectors) < 0:
        vectors[:, 2] = -vectors[:, 2]
    return float(coverage_factor) * np.sqrt(values), vectors


def visibility_scale(largest_semi_axis_m: float, *, target_m: float = 0.05) -> float:
    """Power-of-ten magnification drawing the largest semi-axis at about `target_m`.

    Returns 1 for a degenerate (zero or non-finite) region.
    """
    if not (largest_semi_axis_m > 0 and math.isfinite(largest_semi_axis_m)):
        return 1.0
    return float(10.0 ** max(0, math.floor(math.log10(target_m / largest_semi_axis_m))))


def _measured_points(result: CalibrationUncertainty, points: Array, frame: str) -> Array:
    """Campaign points in the result's frame (the calibrated base transform when they differ)."""
    if result.frame == "base" and frame == "tracker":
        world_t_base = result.calibration.model.world_T_base()
        rotation, translation = world_t_base[:3, :3], world_t_base[:3, 3]
        return (points - translation) @ rotation
    return points


def _region_markers(
    result: CalibrationUncertainty, axes: list[tuple[Array, Array]], magnification: float
) -> list[MarkerSpec]:
    """Per test configuration: its coverage ellipsoid (magnified) and a label naming its size."""
    frame_id = result.frame_id
    p = result.coverage_probability
    identity = np.array([0.0, 0.0, 0.0, 1.0])
    markers: list[MarkerSpec] = []
    for i, (pose, (semi, rotation)) in enumerate(zip(result.poses, axes)):
        center = np.asarray(pose.mean, dtype=np.float64)
        diameters = 2.0 * semi * magnification
        markers.append(
            MarkerSpec(
                "coverage_region",
                i,
                "sphere",
                frame_id,
                center,
                quaternion_from_matrix(rotation),
                np.maximum(diameters, 1e-6),
                REGION_COLOR,
            )
        )
        label = f"config {i + 1}: {p * 100:g} % region, largest semi-axis {semi[0] * 1e6:.1f} um (x{magnification:g})"
        markers.append(
            MarkerSpec(
                "coverage_label",
                i,
                "text",
                frame_id,
                center + np.array([0.0, 0.0, float(diameters[0]) / 2.0 + 0.03]),
                identity,
                np.array([0.0, 0.0, 0.02]),
                TEXT_COLOR,
                text=label,
            )
        )
    return markers


def _points_marker(
    result: CalibrationUncertainty, campaign_points: Array, campaign_frame: str, point_diameter_m: float
) -> MarkerSpec:
    """The campaign's measured points, in the result's frame, as one sphere list."""
    frame_id = result.frame_id
    identity = np.array([0.0, 0.0, 0.0, 1.0])
    pts = np.asarray(campaign_points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        msg = f"campaign_points must have shape (n, 3), got {pts.shape}"
        raise InputError(msg)
    return MarkerSpec(
        "campaign_points",
        0,
        "sphere_list",
        frame_id,
        np.zeros(3),
        identity,
        np.full(3, point_diameter_m),
        POINT_COLOR,
        points=_measured_points(result, pts, campaign_frame),
    )


def uncertainty_markers(
    result: CalibrationUncertainty,
    *,
    campaign_points: Array | None = None,
    campaign_frame: str = "base",
    scale: float | None = None,
    target_size_m: float = 0.05,
    point_diameter_m: float = 0.01,
) -> tuple[MarkerSpec, ...]:
    """Marker descriptions of `result` (see the module docstring).

    Parameters
    ----------
    result : CalibrationUncertainty
        Its poses' JCGM 102 regions (or, where degenerate, covariance with the normal
        coverage factor) give the ellipsoids.
    campaign_points : ndarray, shape (n_poses, 3) [m], optional
        Measured points of the campaign, in the campaign's frame.
    campaign_frame : {"base", "tracker"}
        Frame of `campaign_points` (``Campaign.frame``).
    scale : float, optional
        Magnification of every ellipsoid (one for all, so they compare); default: the power
        of ten drawing the largest semi-axis at about `target_size_m`.
    target_size_m : float [m]
    point_diameter_m : float [m]
        Drawn size of the measured points.

    Returns
    -------
    tuple of MarkerSpec
        Per configuration i: ``coverage_region``/i and ``coverage_label``/i; then
        ``campaign_points``/0 when points are given.
    """
    if scale is not None and not (scale > 0 and math.isfinite(scale)):
        msg = f"scale must be a finite number > 0, got {scale!r}"
        raise InputError(msg)
    p = result.coverage_probability
    axes = []
    for pose in result.poses:
        if pose.region is not None:
            k, covariance = pose.region.coverage_factor, pose.region.covariance
        else:
            k, covariance = math.sqrt(float(_chi2_3(p))), pose.covariance
        axes.append(ellipsoid_axes(covariance, k))
    largest = max((float(a[0][0]) for a in axes), default=0.0)
    magnification = scale if scale is not None else visibility_scale(largest, target_m=target_size_m)
    markers = _region_markers(result, axes, magnification)
    if campaign_points is not None:
        markers.append(_points_marker(result, campaign_points, campaign_frame, point_diameter_m))
    return tuple(markers)


def _chi2_3(p: float) -> float:
    from scipy import stats

    return float(stats.chi2.ppf(p, 3))
