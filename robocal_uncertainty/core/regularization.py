"""Tikhonov regularisation of a linear least-squares step and choice of its parameter.

For ``min ||b - A x||^2 + lambda^2 ||x||^2`` (the reference paper's ``Gamma = lambda I``), the SVD
``A = U S V^T`` gives every quantity in closed form through the filter factors
``f_i = s_i^2 / (s_i^2 + lambda^2)``: the solution, its norm, the residual norm, the L-curve
and its curvature (Hansen, "The L-curve and its use...", 2000) and the GCV function.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["LCurve", "lcurve", "tikhonov_solve"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class LCurve:
    """The L-curve and GCV function of one linear Tikhonov problem.

    Attributes
    ----------
    lambdas : ndarray, shape (n,) [-]
        Regularisation parameters (in the scaled parameter units), decreasing.
    residual_norms : ndarray, shape (n,) [m]
        ``||b - A x_lambda||``.
    solution_norms : ndarray, shape (n,) [-]
        ``||x_lambda||`` in scaled units.
    curvature : ndarray, shape (n,)
        Signed curvature of ``(log residual, log solution)``; the corner is its maximum.
    gcv : ndarray, shape (n,)
        Generalised cross-validation function ``||r||^2 / (m - sum f_i)^2``.
    corner_index : int
        Index of the maximum curvature.
    gcv_index : int
        Index of the GCV minimum.
    """

    lambdas: Array
    residual_norms: Array
    solution_norms: Array
    curvature: Array
    gcv: Array
    corner_index: int
    gcv_index: int

    @property
    def corner_lambda(self) -> float:
        """Lambda at the L-curve corner."""
        return float(self.lambdas[self.corner_index])

    @property
    def gcv_lambda(self) -> float:
        """Lambda at the GCV minimum."""
        return float(self.lambdas[self.gcv_index])


def tikhonov_solve(u: Array, s: Array, vt: Array, b: Array, lam: float) -> Array:
    """Solve ``min ||b - A x||^2 + lam^2 ||x||^2`` from the thin SVD of ``A``.

    Parameters
    ----------
    u, s, vt : ndarray, shapes (m, k), (k,), (k, n)
        Thin SVD of ``A``.
    b : ndarray, shape (m,)
        Right-hand side.
    lam : float
        Regularisation parameter, >= 0.

    Returns
    -------
    ndarray, shape (n,)
    """
    beta = u.T @ b
    return vt.T @ (s * beta / (s**2 + lam**2))


def _corner_index(kappa: Array) -> int:
    """Largest lambda whose curvature reaches 99 % of the maximum.

    For an L-curve with a true corner this is the corner. For a well-posed problem the
    curve has no corner: the curvature climbs to a plateau as the residual reaches the
    noise floor and the curve shrinks to a point; the onset of that plateau is the
    smallest regularisation that still acts, rather than an arbitrary point on it.
    """
    peak = float(np.max(kappa))
    if not np.isfinite(peak) or peak <= 0.0:
        # No convex part at all: Hansen's rule, the leftmost point (smallest lambda).
        return int(kappa.size - 1)
    return int(np.flatnonzero(kappa >= 0.99 * peak)[0])


def lcurve(u: Array, s: Array, b: Array, *, n_points: int = 200) -> LCurve:
    """Evaluate the L-curve, its curvature and GCV on a log grid of lambdas.

    Parameters
    ----------
    u, s : ndarray, shapes (m, k), (k,)
        Left singular vectors and singular values of the (column-scaled) Jacobian.
    b : ndarray, shape (m,)
        Right-hand side (residual of the linearisation).
    n_points : int
        Grid size; the grid spans ``[s_min * 1e-3, s_max]``.
    """
    m = u.shape[0]
    beta = u.T @ b
    perp2 = max(float(b @ b - beta @ beta), 0.0)
    s_pos = s[s > 0]
    # Below s_min * 1e-3 nothing changes any more; above s_max * 1e-10 round-off stays out.
    lo = max(float(s_pos.min()) * 1e-3, float(s_pos.max()) * 1e-10)
    lambdas = np.logspace(np.log10(float(s_pos.max())), np.log10(lo), n_points)
    lam2 = lambdas[:, None] ** 2
    f = s**2 / (s**2 + lam2)
    coef = np.divide(beta, s, out=np.zeros_like(beta), where=s > 0)
    eta = np.sum((f * coef) ** 2, axis=1)
    rho = np.sum(((1.0 - f) * beta) ** 2, axis=1) + perp2
    # Curvature of the curve (X, Y) = (log rho, log eta) parametrised by t = log lambda,
    # from exact derivatives of the filter factors: df/dt = -2 f (1 - f).
    b2 = beta**2
    c2 = coef**2
    one_f = 1.0 - f
    drho = 4.0 * np.sum(f * one_f**2 * b2, axis=1)
    ddrho = -8.0 * np.sum(f * one_f**2 * (1.0 - 3.0 * f) * b2, axis=1)
    deta = -4.0 * np.sum(f**2 * one_f * c2, axis=1)
    ddeta = 8.0 * np.sum(f**2 * one_f * (2.0 - 3.0 * f) * c2, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        dx = 0.5 * drho / rho
        dy = 0.5 * deta / eta
        ddx = 0.5 * (ddrho / rho - (drho / rho) ** 2)
        ddy = 0.5 * (ddeta / eta - (deta / eta) ** 2)
        kappa = (dx * ddy - ddx * dy) / (dx**2 + dy**2) ** 1.5
        gcv = rho / (m - np.sum(f, axis=1)) ** 2
    kappa = np.where(np.isfinite(kappa), kappa, -np.inf)
    gcv = np.where(np.isfinite(gcv), gcv, np.inf)
    return LCurve(
        lambdas=lambdas,
        residual_norms=np.sqrt(rho),
        solution_norms=np.sqrt(eta),
        curvature=kappa,
        gcv=gcv,
        corner_index=_corner_index(kappa),
        gcv_index=int(np.argmin(gcv)),
    )
