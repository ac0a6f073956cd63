"""The model error as a field over the robot's configurations: correlated between nearby poses.

What the kinematic model cannot represent (gear errors, compliance, thermal gradients) is a
smooth function of the joint configuration: two poses a few degrees apart see nearly the same
error, two far apart independent ones. Treating it as independent from pose to pose makes a
check of a few poses too narrow (its errors do not average out as independent ones would) and
the parameter covariance too small (the fit follows the smooth error). Here the model error
``e(q)`` (robot base frame, 3 components) is a zero-mean Gaussian field

``Cov(e(q), e(q')) = [c rho(d(q, q') / l) + (1 - c) [q = q']] Sigma_m``

with ``Sigma_m`` the per-pose model-error covariance (3 x 3), ``c`` the correlated fraction
(the rest is independent from pose to pose), ``rho(t) = exp(-t)`` (exponential kernel) and
``d`` the chordal joint distance ``sqrt(sum_j (2 sin((q_j - q'_j) / 2))^2)`` [rad] (periodic in
every joint, so ``q`` and ``q + 2 pi`` are the same configuration; for small differences the
Euclidean joint distance). ``c``, ``l`` and the scale of ``Sigma_m`` are estimated from the
calibration's own residuals by restricted maximum likelihood
(:func:`~robocal_uncertainty.uncertainty.sessions.field.estimate_model_error_field`).

A calibration's estimate follows the field at its poses: ``delta_theta = G (e_t + eps_t)`` with
``G`` the regularised least-squares gain. At new poses ``q_c`` the prediction error is
``e_c - J_c G e_t`` (plus noise), whose covariance

``K_cc + J_c G K_tt G^T J_c^T - J_c G K_tc - K_ct G^T J_c^T``

needs the calibration poses and the gain: the field carries both (:attr:`ModelErrorField.gain`
maps base-frame point errors at the calibration poses to the estimated parameters).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = ["FIELD_KERNEL", "FIELD_METRIC", "ModelErrorField", "chordal_distance", "kernel_correlation"]

Array = NDArray[np.float64]
FIELD_KERNEL = "exponential"
"""Correlation function of the field: ``rho(t) = exp(-t)`` (Matern 1/2)."""
FIELD_METRIC = "joint_chordal"
"""Distance between configurations: ``sqrt(sum_j (2 sin(dq_j / 2))^2)`` [rad]."""


def chordal_distance(q_a: Array, q_b: Array) -> Array:
    """Chordal joint distance between every configuration of `q_a` and of `q_b`, shape (n_a, n_b) [rad].

    Parameters
    ----------
    q_a : ndarray, shape (n_a, n_joints) [rad]
    q_b : ndarray, shape (n_b, n_joints) [rad]
    """
    a = np.concatenate((np.cos(q_a), np.sin(q_a)), axis=1)
    b = np.concatenate((np.cos(q_b), np.sin(q_b)), axis=1)
    sq = np.sum(a * a, axis=1)[:, None] + np.sum(b * b, axis=1)[None, :] - 2.0 * a @ b.T
    return np.asarray(np.sqrt(np.clip(sq, 0.0, None)), dtype=np.float64)


def kernel_correlation(distance: Array, length_scale: float) -> Array:
    """``rho(d / l)`` of :data:`FIELD_KERNEL` (1 at zero distance)."""
    return np.asarray(np.exp(-distance / max(float(length_scale), 1e-12)), dtype=np.float64)


@dataclass(frozen=True, eq=False)
class ModelErrorField:
    """A correlated model error (robot base frame) with what a later check needs to use it.

    Attributes
    ----------
    correlated_fraction : float
        ``c`` in [0, 1]: share of the per-pose model-error variance that is correlated
        between configurations (the rest is independent from pose to pose).
    length_scale : float [rad]
        ``l`` of the exponential kernel over the chordal joint distance.
    joint_positions : ndarray, shape (n_t, n_joints) [rad]
        The calibration poses (model joint order).
    gain_names : tuple of str, length k
        Estimated parameters the gain maps to (order of the parameter covariance).
    gain : ndarray, shape (k, 3 n_t) [m/m, rad/m]
        First-order change of those estimates per base-frame point error at the calibration
        poses (pose-major, x y z per pose).
    dof : float
        Effective degrees of freedom of the model-error variance estimate (``2 / var(log s)``
        from the restricted likelihood's curvature): far fewer than ``3 n_t`` when the error is
        correlated.
    log_likelihood : float
        Restricted log-likelihood at the estimate.
    independent_log_likelihood : float
        Restricted log-likelihood of the best model with ``c = 0`` (independent model error).
    hyper_covariance : ndarray, shape (3, 3)
        Covariance of the estimates of ``(log s, c, log l)`` (``s`` the scale of the per-pose
        covariance), the inverse curvature of the restricted likelihood; zero rows for those
        at a bound (recorded; `dof` is ``2 / var(log s)`` from it).
    kernel, metric : str
        :data:`FIELD_KERNEL`, :data:`FIELD_METRIC`.
    """

    correlated_fraction: float
    length_scale: float
    joint_positions: Array
    gain_names: tuple[str, ...]
    gain: Array
    dof: float = float("inf")
    log_likelihood: float = float("nan")
    independent_log_likelihood: float = float("nan")
    hyper_covariance: Array = field(default_factory=lambda: np.zeros((3, 3)))
    kernel: str = FIELD_KERNEL
    metric: str = FIELD_METRIC
    extra: dict[str, object] = field(default_factory=dict)

    def correlation(self, q_a: Array, q_b: Array) -> Array:
        """Correlation of the correlated part between configurations, shape (n_a, n_b)."""
        return kernel_correlation(chordal_distance(q_a, q_b), self.length_scale)

    def covariance(self, q: Array, per_pose: Array) -> Array:
        """Model-error covariance over the poses `q`, shape (3 n, 3 n) [m^2], pose-major.

        Parameters
        ----------
        q : ndarray, shape (n, n_joints) [rad]
        per_pose : ndarray, shape (3, 3) [m^2]
            Per-pose covariance (``Sigma_m``) in the frame wanted.
        """
        c = self.correlated_fraction
        corr = c * self.correlation(q, q) + (1.0 - c) * np.eye(q.shape[0])
        return np.asarray(np.kron(corr, per_pose), dtype=np.float64)

    def cross_covariance(self, q: Array, per_pose: Array) -> Array:
        """Covariance between the model error at the calibration poses and at `q`, shape (3 n_t, 3 n).

        Only the correlated part: the independent part of a calibration pose is not the one
        of a new pose.
        """
        corr = self.correlated_fraction * self.correlation(self.joint_positions, q)
        return np.asarray(np.kron(corr, per_pose), dtype=np.float64)

    def prediction_covariance(
        self, q: Array, per_pose_base: Array, rotation: Array, jacobian: Array, names: tuple[str, ...]
    ) -> Array:
        """Covariance of the model error at `q` less what the calibration absorbed, measurement frame.

        ``K_cc - J_c G K_tc - (J_c G K_tc)^T`` (the ``J_c G K_tt G^T J_c^T`` term is the parameter
        covariance's part, added by the caller with the rest of it), shape (3 n, 3 n) [m^2].

        Parameters
        ----------
        q : ndarray, shape (n, n_joints) [rad]
        per_pose_base : ndarray, shape (3, 3) [m^2]
            ``Sigma_m``, robot base frame.
        rotation : ndarray, shape (3, 3)
            Robot base frame to the measurement frame.
        jacobian : ndarray, shape (3 n, k)
            Derivative of the predicted points (measurement frame) by the parameters `names`.
        names : tuple of str, length k
            Parameters the calibration estimated and the check does not re-register.
        """
        n = q.shape[0]
        per_pose = rotation @ per_pose_base @ rotation.T
        k_cc = self.covariance(q, per_pose)
        rows = [self.gain_names.index(nm) for nm in names if nm in self.gain_names]
        cols = [c for c, nm in enumerate(names) if nm in self.gain_names]
        if not rows:
            return k_cc
        k_tc = self.cross_covariance(q, per_pose_base @ rotation.T)  # base (t) x measurement (c)
        cross = jacobian[:, cols] @ (self.gain[rows] @ k_tc)
        out = k_cc - cross - cross.T
        return np.asarray(0.5 * (out + out.T), dtype=np.float64).reshape(3 * n, 3 * n)

    def to_dict(self) -> dict[str, object]:
        """JSON-ready (the calibration file's ``model_error.field``)."""
        return {
            "kernel": self.kernel,
            "metric": self.metric,
            "correlated_fraction": self.correlated_fraction,
            "length_scale_rad": self.length_scale,
            "dof": self.dof,
            "log_likelihood": self.log_likelihood,
            "independent_log_likelihood": self.independent_log_likelihood,
            "hyper_covariance": self.hyper_covariance.tolist(),
            "joint_positions_rad": self.joint_positions.tolist(),
            "gain": {"names": list(self.gain_names), "matrix": self.gain.tolist()},
            **self.extra,
        }
