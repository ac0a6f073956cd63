"""Best-fit registration of measured section points to the nominal curve.

Point-to-curve least squares: the rigid in-plane transform ``p = R(θ)(c - pivot) + pivot + t``
taking the nominal curve onto the measured points minimises the sum of squared signed normal
distances of the measured points to the transformed curve. It is solved by Gauss-Newton with
the closest points recomputed every iteration (point-to-plane ICP iterated to convergence), from
the identity: the measured cloud must already lie in the nominal frame to within a fraction of
the section thickness, as a CMM inspection does after its part alignment.

``t`` gives the axial (x) and circumferential (y) position offsets, ``θ`` the twist angle about
the stacking point ``pivot``, counterclockwise positive (the reference paper counts counterclockwise as
negative: negate for its convention).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal_uncertainty.core.instruments.cmm import as_points
from robocal_uncertainty.errors import ConvergenceError, InputError
from robocal_uncertainty.inspection.nominal_curve import NominalCurve

__all__ = ["Registration", "polygon_centroid", "register_to_nominal", "registration_jacobian", "rotation"]

_MAX_ITERATIONS = 60
_MISMATCH_RMS = 2e-3
"""RMS distance after registration, as a fraction of the section size, that means a wrong nominal."""


def rotation(angle: float) -> NDArray[np.float64]:
    """2x2 rotation matrix of ``angle`` [rad], counterclockwise positive."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def polygon_centroid(points: ArrayLike) -> NDArray[np.float64]:
    """Area centroid of a closed polygon, shape (2,) [m].

    Parameters
    ----------
    points : array_like, shape (n, 2) [m]
        Polygon vertices in order (either orientation).
    """
    p = as_points(points, "points")
    x, y = p[:, 0], p[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = 0.5 * cross.sum()
    if abs(area) < 1e-300:
        msg = "polygon has zero area; cannot take its centroid"
        raise InputError(msg)
    sums = np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()], dtype=np.float64)
    return np.asarray(sums / (6.0 * area), dtype=np.float64)


@dataclass(frozen=True, eq=False)
class Registration:
    """Outcome of :func:`register_to_nominal`.

    Attributes
    ----------
    offset : ndarray, shape (2,) [m]
        Translation t: axial (x) and circumferential (y) position offsets.
    twist : float
        Rotation θ about ``pivot`` [rad], counterclockwise positive.
    pivot : ndarray, shape (2,) [m]
        Stacking point the twist is measured about.
    parameter : ndarray, shape (n,) [m]
        Nominal-curve parameter of each measured point's foot.
    foot : ndarray, shape (n, 2) [m]
        Feet on the nominal curve, in the nominal frame.
    normal : ndarray, shape (n, 2)
        Outward unit normals at the feet, in the measured frame (rotated by θ).
    residual : ndarray, shape (n,) [m]
        Signed normal distances of the measured points to the registered curve (outward +).
    jacobian : ndarray, shape (n, 3) [1, 1, m]
        ∂residual/∂(t_x, t_y, θ) with the sign flipped (the model matrix of the final step).
    iterations : int
        Gauss-Newton iterations run.
    """

    offset: NDArray[np.float64]
    twist: float
    pivot: NDArray[np.float64]
    parameter: NDArray[np.float64]
    foot: NDArray[np.float64]
    normal: NDArray[np.float64]
    residual: NDArray[np.float64]
    jacobian: NDArray[np.float64]
    iterations: int

    @property
    def rms(self) -> float:
        """RMS of the residuals [m]."""
        return float(np.sqrt(np.mean(self.residual**2)))


def registration_jacobian(
    foot: NDArray[np.float64], normal: NDArray[np.float64], twist: float, pivot: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Model matrix A (n, 3) of the linearised residual change ``-A @ (Δt_x, Δt_y, Δθ)``.

    Parameters
    ----------
    foot : ndarray, shape (n, 2) [m]
        Feet in the nominal frame.
    normal : ndarray, shape (n, 2)
        Outward normals in the measured frame.
    twist : float
        Current θ [rad].
    pivot : ndarray, shape (2,) [m]
        Stacking point.
    """
    arm = (foot - pivot) @ rotation(twist).T
    lever = normal[:, 1] * arm[:, 0] - normal[:, 0] * arm[:, 1]
    return np.column_stack([normal, lever])


def register_to_nominal(
    points: ArrayLike,
    curve: NominalCurve,
    *,
    pivot: ArrayLike | None = None,
    tolerance: float = 1e-13,
) -> Registration:
    """Point-to-curve least-squares registration of measured points to the nominal curve.

    Parameters
    ----------
    points : array_like, shape (n, 2) [m]
        Measured points in the section plane, n >= 3.
    curve : NominalCurve
        Nominal section curve.
    pivot : array_like, shape (2,) [m], optional
        Stacking point for the twist; default the nominal section's area centroid.
    tolerance : float
        Convergence threshold on the step [m and rad].

    Returns
    -------
    Registration

    Raises
    ------
    InputError
        Fewer than 3 points, or an RMS distance after registration above 0.2 % of the section
        size (measured and nominal are different sections).
    ConvergenceError
        No convergence in 60 iterations.
    """
    p = as_points(points, "points")
    if p.shape[0] < 3:
        msg = f"registration needs at least 3 points, got {p.shape[0]}"
        raise InputError(msg)
    centre = polygon_centroid(curve.section.points) if pivot is None else np.asarray(pivot, dtype=np.float64)
    if centre.shape != (2,) or not np.isfinite(centre).all():
        msg = f"pivot must be a finite (2,) point [m], got {pivot!r}"
        raise InputError(msg)
    t, theta, u, iteration, last_step = _gauss_newton(p, curve, centre, tolerance)
    r = rotation(theta)
    near = curve.closest((p - centre - t) @ r + centre, start=u)
    normal = near.normal @ r.T
    result = Registration(
        offset=t,
        twist=theta,
        pivot=centre,
        parameter=near.parameter,
        foot=near.foot,
        normal=normal,
        residual=near.distance,
        jacobian=registration_jacobian(near.foot, normal, theta, centre),
        iterations=iteration,
    )
    size = float(np.ptp(curve.section.points, axis=0).max())
    if result.rms > _MISMATCH_RMS * size:
        msg = (
            f"measured points do not match the nominal section: RMS distance {result.rms * 1e3:.3g} mm "
            f"after registration (limit {_MISMATCH_RMS * size * 1e3:.3g} mm)"
        )
        raise InputError(msg)
    if not last_step < tolerance:  # also a NaN step
        msg = f"registration did not converge in {_MAX_ITERATIONS} iterations (last step {last_step:.3g})"
        raise ConvergenceError(msg)
    return result


def _gauss_newton(
    p: NDArray[np.float64], curve: NominalCurve, centre: NDArray[np.float64], tolerance: float
) -> tuple[NDArray[np.float64], float, NDArray[np.float64] | None, int, float]:
    """Gauss-Newton iterations of the registration: ``(offset, twist, feet parameters, iterations,
    largest component of the last step)``; the last step is below ``tolerance`` when converged."""
    t = np.zeros(2)
    theta = 0.0
    u: NDArray[np.float64] | None = None
    last_step = np.inf
    iteration = 0
    for iteration in range(1, _MAX_ITERATIONS + 1):
        r = rotation(theta)
        local = (p - centre - t) @ r + centre  # R(-θ)(p - pivot - t) + pivot
        # Closest points from the global (dense-sample) start every iteration: warm-starting
        # Newton at the previous feet lets feet of a large move (0.3° on a 300 mm blade)
        # stay on a wrong local minimum, and the registration converged silently off.
        near = curve.closest(local)
        u = near.parameter
        normal = near.normal @ r.T
        a = registration_jacobian(near.foot, normal, theta, centre)
        step, *_ = np.linalg.lstsq(a, near.distance, rcond=None)
        t = t + step[:2]
        theta += float(step[2])
        last_step = float(np.max(np.abs(step)))
        if last_step < tolerance:
            break
    return t, theta, u, iteration, last_step
