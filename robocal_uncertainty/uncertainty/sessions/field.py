"""The model error a calibration leaves: its size per pose, its degrees of freedom, its field.

When the model is inadequate the model error is, by default, a field correlated over the joint
configurations (:func:`estimate_model_error_field`: restricted maximum likelihood on the
calibration's residuals; :mod:`~robocal_uncertainty.core.model_error_field`): a real robot's
error is smooth, and one independent from pose to pose makes a check of a few poses too narrow
(UR10 series, 10-pose checks against 53-pose calibrations: 91.3 % consistent at the 5 % level
with the independent model error, 96.1 % of 1 600 with the field). Without the field it comes
from held-out folds (:class:`CrossValidatedModelError`, :mod:`.cross_validation`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.model_error_field import ModelErrorField
from robocal_uncertainty.core.robot_model import rpy_to_matrix
from robocal_uncertainty.uncertainty.model_error_draws import estimate_field

__all__ = [
    "FIELD_MAX_POSES",
    "CrossValidatedModelError",
    "campaign_distances",
    "estimate_model_error_field",
    "model_error_dof",
]

Array = NDArray[np.float64]


def campaign_distances(campaign: Campaign, calibration: IdentificationResult) -> Array:
    """Tracker-to-target distance of every pose [m] (the tracker at the origin of its frame)."""
    positions = campaign.measurement.positions(campaign.points)
    if campaign.frame == "tracker" and positions is not None:
        return np.asarray(np.linalg.norm(positions, axis=1), dtype=np.float64)
    # Base-frame points: the tracker position is unknown; 2 m is the simulation's default reach.
    return np.full(campaign.n_poses, 2.0)


def model_error_dof(draws: Array, covariance: Array) -> float:
    """Effective degrees of freedom of a model-error covariance estimated from `draws`.

    With ``m_i = d_i^T Sigma^-1 d_i / 3`` (mean 1), the estimate's relative variance is
    ``var(m_i) / n``; a chi-square variance estimate with ``nu`` degrees of freedom has
    relative variance ``2 / nu``, so ``nu = 2 n / var(m_i)`` (``3 n`` for normal draws, fewer
    for heavy-tailed ones).
    """
    inv = np.linalg.pinv(covariance)
    m = np.einsum("pi,ij,pj->p", draws, inv, draws) / float(np.linalg.matrix_rank(covariance) or 1)
    var = float(np.var(m, ddof=1)) if m.size > 1 else float("inf")
    return float(2.0 * m.size / var) if var > 0 else float("inf")


@dataclass(frozen=True, eq=False)
class CrossValidatedModelError:
    """The model error as held-out poses of the calibration campaign show it (k-fold).

    Attributes
    ----------
    covariance : ndarray, shape (3, 3) [m^2]
        Per-pose model-error covariance, robot base frame: the held-out residual covariance
        less the stated noise and the folds' own parameter uncertainty (clipped to be PSD).
    draws : ndarray, shape (n_poses, 3) [m]
        The held-out residuals (centred) whitened to `covariance`, robot base frame.
    fitted_covariance : ndarray, shape (3, 3) [m^2]
        The first-order estimate from the calibration's own residuals, for comparison.
    folds : int
    parameter_factor : float
        Factor (>= 1) on the calibration's parameter covariance with which the held-out folds,
        tested as a check is (tracker pose re-registered), give a statistic equal to its degrees
        of freedom: the first-order covariance treats the model error as independent from pose
        to pose, a smooth real one moves the parameters more.
    """

    covariance: Array
    draws: Array
    fitted_covariance: Array
    folds: int
    parameter_factor: float = 1.0

    def to_dict(self) -> dict[str, object]:
        """JSON-ready (the draws are written with the session's model error)."""
        return {
            "folds": self.folds,
            "parameter_factor": self.parameter_factor,
            "covariance_base_m2": self.covariance.tolist(),
            "fitted_covariance_base_m2": self.fitted_covariance.tolist(),
        }


FIELD_MAX_POSES = 200
"""Most poses the field's hyperparameters are estimated from (a seeded subset of larger campaigns)."""


def estimate_model_error_field(
    calibration: IdentificationResult,
    joint_positions: Array,
    noise: Array,
    shape_base: Array,
    *,
    max_poses: int = FIELD_MAX_POSES,
    seed: int = 0,
) -> tuple[ModelErrorField, float]:
    """The correlated model error of a point calibration by restricted maximum likelihood.

    The estimator every statement uses (:func:`~robocal_uncertainty.uncertainty.model_error_draws.estimate_field`:
    the likelihood of the residuals' contrasts orthogonal to the fit, ``V = [c rho(d / l) +
    (1 - c) I] (x) s S``, see :mod:`~robocal_uncertainty.core.model_error_field`), here with the
    likelihood's scale ``s``: a check re-registers and is tested against the validated level,
    and the session records the field with what a check needs to use it.

    Parameters
    ----------
    calibration : IdentificationResult
        A point calibration (unweighted).
    joint_positions : ndarray, shape (n, n_joints) [rad]
    noise : ndarray, shape (n, 3, 3) [m^2]
        Stated noise covariance per pose, measurement frame.
    shape_base : ndarray, shape (3, 3)
        Shape ``S`` of the per-pose model-error covariance, robot base frame (its trace is
        normalised to 3; the identity when the residuals gave none).
    max_poses : int
        Campaigns with more poses estimate the hyperparameters on a seeded subset of this many.
    seed : int
        Seed of that subset.

    Returns
    -------
    (ModelErrorField, float)
        The field (without its gain: :func:`session_state` adds it) and ``s`` [m^2]: the
        per-pose model-error covariance is ``s S``.
    """
    q_all = np.asarray(joint_positions, dtype=np.float64)
    b0 = calibration.model.layout.base_index
    r_wb = rpy_to_matrix(calibration.estimate[b0 + 3 : b0 + 6])
    shape = np.asarray(shape_base, dtype=np.float64)
    shape = 3.0 * shape / np.trace(shape) if np.trace(shape) > 0 else np.eye(3)
    estimate = estimate_field(
        calibration, q_all, noise, r_wb @ shape @ r_wb.T, max_equations=3 * max_poses, seed=seed, leave_one_out=False
    )
    field = ModelErrorField(
        correlated_fraction=estimate.correlated_fraction,
        length_scale=estimate.length_scale,
        joint_positions=q_all.copy(),
        gain_names=(),
        gain=np.zeros((0, 3 * q_all.shape[0])),
        dof=estimate.dof,
        log_likelihood=estimate.log_likelihood,
        independent_log_likelihood=estimate.independent_log_likelihood,
        hyper_covariance=estimate.hyper_covariance,
        extra={"poses_used": estimate.poses_used, "contrasts": estimate.contrasts},
    )
    return field, float(np.trace(estimate.per_pose_covariance)) / 3.0
