"""Model inadequacy: the part of the calibration residuals that the stated noise does not explain.

After calibration the residuals hold the measurement noise (tracker, encoders) plus whatever
the kinematic model cannot represent (compliance, gear errors, thermal drift). The noise
sources of the Monte Carlo already carry the first part; counting the raw residual scatter
again would double it. Here the residuals are compared with the noise the stated models
predict, pose by pose:

* the statistic ``chi2 = sum_i r_i^T Sigma_noise,i^-1 r_i`` with ``3 n - p_eff`` degrees of
  freedom (``p_eff`` the effective number of parameters of the regularised fit) tests
  whether the model is adequate;
* if the test rejects adequacy at the significance level, the model-error covariance per
  pose is estimated by moments, ``Sigma_m = S - mean_i Sigma_noise,i``, with ``S`` the
  residual covariance corrected for the degrees of freedom the fit used, and negative
  eigenvalues clipped to zero;
* otherwise ``Sigma_m = 0``: the residual source contributes nothing.

The Monte Carlo draws model errors as a residual bootstrap whitened to ``Sigma_m`` (the
shape of the real residual distribution, the covariance of the unexplained part), adds one
to every measured point (the error a pose's model error leaves in the identification) and
one to every prediction (the model error at the test configuration).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.kinematics import forward_points_and_jacobian
from robocal_uncertainty.core.simulation import EncoderNoise, TrackerNoise

__all__ = ["ModelAdequacy", "assess_model_adequacy", "pose_noise_covariances"]

Array = NDArray[np.float64]
SIGNIFICANCE = 0.01
"""Level of the chi-square test below which the model is declared inadequate."""


@dataclass(frozen=True)
class ModelAdequacy:
    """Outcome of :func:`assess_model_adequacy`; covariances in the measurement frame.

    Attributes
    ----------
    chi2 : float
        ``sum_i r_i^T Sigma_noise,i^-1 r_i`` over the calibration poses.
    dof : float
        ``3 n - p_eff``.
    p_value : float
        Probability of a chi2 at least this large if the model were adequate.
    significance : float
        Test level; below it the model is declared inadequate.
    adequate : bool
        True when the residuals are consistent with the stated noise.
    residual_covariance : ndarray, shape (3, 3) [m^2]
        Per-pose covariance of the residuals, corrected for the fitted degrees of freedom.
    noise_covariance : ndarray, shape (3, 3) [m^2]
        Mean over the poses of the covariance the stated noise models predict.
    inadequacy_covariance : ndarray, shape (3, 3) [m^2]
        Covariance of the model error per pose (zero when adequate).
    draws : ndarray, shape (n_poses, 3) [m]
        Centred residuals whitened to `inadequacy_covariance`: the values the residual
        source resamples (all zero when adequate).
    """

    chi2: float
    dof: float
    p_value: float
    significance: float
    adequate: bool
    residual_covariance: Array
    noise_covariance: Array
    inadequacy_covariance: Array
    draws: Array

    @property
    def standard_uncertainty(self) -> Array:
        """Model-error standard uncertainty per measurement-frame axis, shape (3,) [m]."""
        return np.sqrt(np.diag(self.inadequacy_covariance))


def pose_noise_covariances(
    calibration: IdentificationResult,
    joint_positions: Array,
    tracker_noise: TrackerNoise,
    encoder_noise: EncoderNoise,
    distances: Array,
) -> Array:
    """Covariance of each measured point that tracker and encoder noise predict.

    Parameters
    ----------
    calibration : IdentificationResult
    joint_positions : ndarray, shape (n_poses, n_joints) [rad]
    tracker_noise, encoder_noise
        The stated noise models.
    distances : ndarray, shape (n_poses,) [m]
        Tracker-to-target distances (for a distance-dependent MPE).

    Returns
    -------
    ndarray, shape (n_poses, 3, 3) [m^2], in the measurement frame.
    """
    layout = calibration.model.layout
    _, jac = forward_points_and_jacobian(layout, calibration.estimate, joint_positions)
    theta_cols = [idx["theta"] for idx in layout.joint_slices()]
    jq = jac[:, :, theta_cols]  # a joint reading enters exactly like its offset theta
    cov = (encoder_noise.half_width**2 / 3.0) * np.einsum("pij,pkj->pik", jq, jq)
    cov += np.eye(3) * (tracker_noise.std(distances) ** 2)[:, None, None]
    return cov


def assess_model_adequacy(
    calibration: IdentificationResult,
    joint_positions: Array,
    tracker_noise: TrackerNoise,
    encoder_noise: EncoderNoise,
    distances: Array,
    *,
    significance: float = SIGNIFICANCE,
) -> ModelAdequacy:
    """Test the calibrated model against the stated noise and estimate what is left over.

    Parameters
    ----------
    calibration : IdentificationResult
        Its residuals [m] are in the measurement frame of the campaign.
    joint_positions : ndarray, shape (n_poses, n_joints) [rad]
    tracker_noise : TrackerNoise
    encoder_noise : EncoderNoise
    distances : ndarray, shape (n_poses,) [m]
    significance : float
        Level of the test (default 1 %).

    Returns
    -------
    ModelAdequacy
    """
    residuals = np.asarray(calibration.residuals, dtype=np.float64)
    n = residuals.shape[0]
    noise = pose_noise_covariances(calibration, joint_positions, tracker_noise, encoder_noise, distances)
    # Noise reaches the residuals through the fit, r = (I - H) e: with the encoders' strongly
    # anisotropic covariance the residual covariance is (I - H) Sigma (I - H)^T, not Sigma.
    layout = calibration.model.layout
    est = np.flatnonzero(calibration.estimated)
    _, jac = forward_points_and_jacobian(layout, calibration.estimate, joint_positions)
    a_mat = jac.reshape(3 * n, layout.size)[:, est] / calibration.column_scale[est]
    penalty = calibration.lambda_**2 * np.diag(calibration.penalized[est].astype(np.float64))
    hat = a_mat @ np.linalg.solve(a_mat.T @ a_mat + penalty, a_mat.T)
    proj = np.eye(3 * n) - hat
    sigma = np.zeros((3 * n, 3 * n))
    for i in range(n):
        sigma[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = noise[i]
    m_cov = proj @ sigma @ proj.T
    # Sum of squares under adequacy: a weighted sum of chi2(1); Satterthwaite's scaled chi2
    # matches its first two moments.
    sum_sq = float(np.sum(residuals**2))
    tr1 = float(np.trace(m_cov))
    tr2 = float(np.sum(m_cov * m_cov))
    if tr1 > 0.0:
        scale = tr2 / tr1
        dof = tr1**2 / tr2
        chi2 = sum_sq / scale
        p_value = float(stats.chi2.sf(chi2, dof))
    else:  # a noise-free statement: every residual is model error
        dof = max(3.0 * n - calibration.effective_parameters, 1.0)
        chi2 = float("inf")
        p_value = 0.0
    blocks = np.stack([m_cov[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] for i in range(n)])
    noise_in_residuals = blocks.mean(axis=0)
    fitted_fraction = max(1.0 - calibration.effective_parameters / (3.0 * n), 1.0 / (3.0 * n))
    observed = residuals.T @ residuals / n
    adequate = p_value >= significance
    inadequacy = np.zeros((3, 3))
    draws = np.zeros_like(residuals)
    if not adequate:
        evals, evecs = np.linalg.eigh((observed - noise_in_residuals) / fitted_fraction)
        inadequacy = (evecs * np.clip(evals, 0.0, None)) @ evecs.T
        centred = residuals - residuals.mean(axis=0)
        s_evals, s_evecs = np.linalg.eigh(centred.T @ centred / n)
        s_inv_sqrt = (s_evecs / np.sqrt(np.maximum(s_evals, np.finfo(float).tiny))) @ s_evecs.T
        m_evals, m_evecs = np.linalg.eigh(inadequacy)
        m_sqrt = (m_evecs * np.sqrt(np.clip(m_evals, 0.0, None))) @ m_evecs.T
        draws = centred @ (m_sqrt @ s_inv_sqrt).T
    return ModelAdequacy(
        chi2=chi2,
        dof=dof,
        p_value=p_value,
        significance=significance,
        adequate=adequate,
        residual_covariance=observed / fitted_fraction,
        noise_covariance=noise.mean(axis=0),
        inadequacy_covariance=inadequacy,
        draws=draws,
    )
