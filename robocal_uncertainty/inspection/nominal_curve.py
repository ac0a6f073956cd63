"""The nominal section as a smooth closed curve: a periodic cubic interpolating spline.

The curve interpolates the nominal contour points with a C2 periodic cubic spline in x(u) and
y(u), u the cumulative chord length along the contour (closed, so the first point follows the
last). Closest points are found by Newton's method on u, started from the nearest of a dense
sampling; distances are signed positive outward (material excess), since the contour is
counterclockwise. This plays the part of the reference paper's NURBS nominal curve with its
circle-clipping + Newton point-to-curve distance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline
from scipy.spatial import cKDTree

from robocal_uncertainty.core.instruments.cmm import as_points
from robocal_uncertainty.inspection.point_cloud import NominalSection

__all__ = ["ClosestPoints", "NominalCurve"]

_NEWTON_ITERATIONS = 12


@dataclass(frozen=True, eq=False)
class ClosestPoints:
    """Feet of query points on the nominal curve.

    Attributes
    ----------
    parameter : ndarray, shape (m,) [m]
        Curve parameter u (arc-length-like) of each foot, in [0, period).
    foot : ndarray, shape (m, 2) [m]
        Closest curve points.
    normal : ndarray, shape (m, 2)
        Unit outward normals at the feet (dimensionless).
    distance : ndarray, shape (m,) [m]
        Signed distances, positive outside the section.
    """

    parameter: NDArray[np.float64]
    foot: NDArray[np.float64]
    normal: NDArray[np.float64]
    distance: NDArray[np.float64]


class NominalCurve:
    """Periodic cubic spline through a :class:`NominalSection` (see module docstring).

    Parameters
    ----------
    section : NominalSection
        Counterclockwise nominal contour [m].
    oversample : int
        Dense samples per contour interval used to start the closest-point search.
    """

    def __init__(self, section: NominalSection, *, oversample: int = 16) -> None:
        closed = np.concatenate([section.points, section.points[:1]])
        knots = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
        self.section = section
        self.period = float(knots[-1])
        self.spline = CubicSpline(knots, closed, bc_type="periodic", axis=0)
        self._samples_u = np.linspace(0.0, self.period, section.n_points * oversample, endpoint=False)
        self._tree = cKDTree(self.spline(self._samples_u))
        self._step = self.period / self._samples_u.shape[0]

    def point(self, u: ArrayLike) -> NDArray[np.float64]:
        """Curve points at parameters ``u`` [m], shape (m, 2) [m]."""
        return np.asarray(self.spline(np.mod(np.asarray(u, dtype=np.float64), self.period)))

    def tangent(self, u: ArrayLike) -> NDArray[np.float64]:
        """Unit tangents (direction of increasing u, counterclockwise), shape (m, 2)."""
        d = np.asarray(self.spline(np.mod(np.asarray(u, dtype=np.float64), self.period), 1))
        return np.asarray(d / np.linalg.norm(d, axis=-1, keepdims=True))

    def outward_normal(self, u: ArrayLike) -> NDArray[np.float64]:
        """Unit outward normals (tangent turned clockwise), shape (m, 2)."""
        t = self.tangent(u)
        return np.stack([t[..., 1], -t[..., 0]], axis=-1)

    def curvature(self, u: ArrayLike) -> NDArray[np.float64]:
        """Signed curvature [1/m], positive where the contour is convex, shape (m,)."""
        uu = np.mod(np.asarray(u, dtype=np.float64), self.period)
        d1 = np.asarray(self.spline(uu, 1))
        d2 = np.asarray(self.spline(uu, 2))
        cross = d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0]
        return np.asarray(cross / np.linalg.norm(d1, axis=-1) ** 3)

    def closest(self, points: ArrayLike, *, start: ArrayLike | None = None) -> ClosestPoints:
        """Closest curve points of ``points``.

        Parameters
        ----------
        points : array_like, shape (m, 2) [m]
            Query points in the nominal frame.
        start : array_like, shape (m,) [m], optional
            Starting parameters (e.g. the previous iteration's); default: the nearest dense sample.

        Returns
        -------
        ClosestPoints
        """
        q = as_points(points, "points")
        if start is None:
            _, index = self._tree.query(q)
            u = self._samples_u[np.asarray(index)]
        else:
            u = np.mod(np.asarray(start, dtype=np.float64).copy(), self.period)
        for _ in range(_NEWTON_ITERATIONS):
            c = self.spline(u)
            d1 = self.spline(u, 1)
            d2 = self.spline(u, 2)
            r = c - q
            g = np.einsum("ij,ij->i", r, d1)
            dg = np.einsum("ij,ij->i", d1, d1) + np.einsum("ij,ij->i", r, d2)
            step = np.where(dg > 0, -g / np.where(dg > 0, dg, 1.0), -np.sign(g) * self._step)
            step = np.clip(step, -self._step * 4, self._step * 4)
            u = np.mod(u + step, self.period)
            if np.max(np.abs(step)) < 1e-15 * self.period:
                break
        foot = np.asarray(self.spline(u))
        normal = self.outward_normal(u)
        distance = np.einsum("ij,ij->i", q - foot, normal)
        return ClosestPoints(u, foot, normal, distance)
