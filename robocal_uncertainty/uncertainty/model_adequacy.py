"""Model inadequacy: the part of the calibration residuals that the stated noise does not explain.

After calibration the residuals hold the measurement noise (tracker, encoders) plus whatever
the kinematic model cannot represent (compliance, gear errors, thermal drift). The noise
sources of the Monte Carlo already carry the first part; counting the raw residual scatter
again would double it. Here the residuals are compared with the noise the stated models
predict, pose by pose:

* the statistic ``chi2 = sum_i r_i^T Sigma_noise,i^-1 r_i`` with ``d n - p_eff`` degrees of
  freedom (``d`` the equations per pose of the measurement type, 3 for points; ``p_eff`` the
  effective number of parameters of the regularised fit) tests whether the model is
  adequate;
* if the test rejects adequacy at the significance level, the model-error covariance per
  pose is estimated by moments, ``Sigma_m = S - mean_i Sigma_noise,i``, with ``S`` the
  residual covariance corrected for the degrees of freedom the fit used, and negative
  eigenvalues clipped to zero;
* otherwise ``Sigma_m = 0``: the residual source contributes nothing.

The Monte Carlo draws model errors as a residual bootstrap whitened to ``Sigma_m`` (the
shape of the real residual distribution, the covariance of the unexplained part), adds one
to every measured value (the error a pose's model error leaves in the identification) and
one to every prediction (the model error at the test configuration).

Everything is in the residual coordinates of the calibration's measurement type
(:class:`~robocal_uncertainty.core.measurement.MeasurementType`): ``d = dimension`` components
per pose; when the type weighs its components, the test runs on whitened residuals.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.core.measurement import row_weights, stack_jacobian

__all__ = ["MIN_RESIDUAL_DOF_PER_COMPONENT", "ModelAdequacy", "assess_model_adequacy", "pose_noise_covariances"]

Array = NDArray[np.float64]
SIGNIFICANCE = 0.01
"""Level of the chi-square test below which the model is declared inadequate."""
MIN_RESIDUAL_DOF_PER_COMPONENT = 32.0
"""Residual degrees of freedom per measured component below which the statement is flagged
as not trustworthy. A variance estimated from nu degrees of freedom has a relative standard
error sqrt(2 / nu); 95 % intervals keep 95 +- 4 % coverage while the standard uncertainty is
within about -13 %/+22 % of the truth, i.e. the variance within about +-25 %, which needs
sqrt(2 / nu) <= 0.25: nu >= 32 per component (96 for points, 192 for 6-DOF poses). Below
it the residuals can neither estimate the model error nor exclude one (the adequacy test
has no power), whatever the test says."""


@dataclass(frozen=True)
class ModelAdequacy:
    """Outcome of :func:`assess_model_adequacy`; covariances in the measurement frame.

    ``d`` is the measurement type's dimension (3 for points, components x, y, z in metres).

    Attributes
    ----------
    chi2 : float
        ``sum_i r_i^T Sigma_noise,i^-1 r_i`` over the calibration poses.
    dof : float
        Degrees of freedom of the scaled chi-square (``d n - p_eff`` for a noise-free
        statement).
    p_value : float
        Probability of a chi2 at least this large if the model were adequate.
    significance : float
        Test level; below it the model is declared inadequate.
    adequate : bool
        True when the residuals are consistent with the stated noise.
    residual_covariance : ndarray, shape (d, d) [m^2 for points]
        Per-pose covariance of the residuals, corrected for the fitted degrees of freedom.
    noise_covariance : ndarray, shape (d, d) [m^2 for points]
        Mean over the poses of the covariance the stated noise models predict.
    inadequacy_covariance : ndarray, shape (d, d) [m^2 for points]
        Covariance of the model error per pose (zero when adequate).
    draws : ndarray, shape (n_poses, d) [m for points]
        Centred residuals whitened to `inadequacy_covariance`: the values the residual
        source resamples (all zero when adequate).
    residual_dof : float
        ``d n - p_eff``: equations left after the (regularised) fit, each distinct joint
        configuration counted once (a copied or re-measured pose tells nothing new about the
        model error, so copying rows cannot make a small campaign look large).
    repeated_poses : int
        Poses whose joint readings repeat an earlier pose's (within :data:`REPEAT_TOLERANCE`).
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
    residual_dof: float = float("inf")
    repeated_poses: int = 0

    @property
    def min_residual_dof(self) -> float:
        """Residual degrees of freedom a trustworthy statement needs (``d`` x 32)."""
        return MIN_RESIDUAL_DOF_PER_COMPONENT * int(self.draws.shape[1])

    @property
    def trustworthy(self) -> bool:
        """False when the campaign is too small to estimate or exclude a model error.

        See :data:`MIN_RESIDUAL_DOF_PER_COMPONENT`: with fewer residual degrees of freedom,
        held-out poses fall inside the 95 % region far less often than stated.
        """
        return bool(self.residual_dof >= self.min_residual_dof)

    @property
    def trust_note(self) -> str:
        """One line: why the statement is not trustworthy and what makes it so; "" when it is."""
        if self.trustworthy:
            return ""
        d = int(self.draws.shape[1])
        repeated = (
            f", {self.repeated_poses} repeated pose{'s' if self.repeated_poses != 1 else ''} counted once"
            if self.repeated_poses
            else ""
        )
        return (
            f"NOT TRUSTWORTHY: {self.residual_dof:.0f} residual degrees of freedom (d n - p_eff{repeated}), "
            f"fewer than the {self.min_residual_dof:.0f} needed to estimate or exclude a model error; "
            f"measure more poses (about {math.ceil((self.min_residual_dof - self.residual_dof) / d)} more)"
        )

    @property
    def standard_uncertainty(self) -> Array:
        """Model-error standard uncertainty per residual component, shape (d,) [m for points]."""
        return np.sqrt(np.diag(self.inadequacy_covariance))


def pose_noise_covariances(
    calibration: IdentificationResult,
    joint_positions: Array,
    tracker_noise: TrackerNoise,
    encoder_noise: EncoderNoise,
    distances: Array,
) -> Array:
    """Covariance of each measured value that tracker and encoder noise predict.

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
    ndarray, shape (n_poses, d, d) [m^2 for points], in the measurement frame, in the
    residual coordinates of ``calibration.measurement`` (unweighted).
    """
    measurement = calibration.measurement
    jq = measurement.joint_jacobian(calibration.model.layout, calibration.estimate, joint_positions)
    # Variance of the uniform encoder error: half-width^2 / 3 (not a point dimension; rad or m per joint).
    cov: Array = encoder_noise.covariance(jq, calibration.model.prismatic)
    cov += measurement.instrument_covariance(tracker_noise.std(distances))
    return cov


def _fit_gain(calibration: IdentificationResult, joint_positions: Array) -> tuple[Array, Array, Array]:
    """Scaled Jacobian A, the fit's gain (so that H = A gain) and the equations' weights.

    Noise reaches the residuals through the fit, r = (I - H) e: with the encoders' strongly
    anisotropic covariance the residual covariance is (I - H) Sigma (I - H)^T, not Sigma.
    With whitening weights w the fit solves on W A and W b, so H = A (A^T W^2 A + P)^-1 A^T W^2.
    """
    measurement = calibration.measurement
    n, dim = np.shape(calibration.residuals)
    n_eq = dim * n
    layout = calibration.model.layout
    est = np.flatnonzero(calibration.estimated)
    _, jac = measurement.predict_and_jacobian(layout, calibration.estimate, joint_positions)
    a_mat = jac.reshape(n_eq, layout.size)[:, est] / calibration.column_scale[est]
    penalty = calibration.lambda_**2 * np.diag(calibration.penalized[est].astype(np.float64))
    w = row_weights(measurement, n)
    if w is None:
        gain: Array = np.asarray(np.linalg.solve(a_mat.T @ a_mat + penalty, a_mat.T), dtype=np.float64)
        w_eq = np.ones(n_eq)
    else:
        a_w = stack_jacobian(measurement, jac, est) / calibration.column_scale[est]
        gain = np.asarray(np.linalg.solve(a_w.T @ a_w + penalty, a_w.T * w), dtype=np.float64)
        w_eq = w
    return a_mat, gain, w_eq


def _satterthwaite_test(sum_sq: float, tr1: float, tr2: float, residual_dof: float) -> tuple[float, float, float]:
    """chi2, degrees of freedom and p-value of the residual sum of squares under adequacy.

    The sum is a weighted sum of chi2(1); Satterthwaite's scaled chi2 matches its first two
    moments (on the whitened residuals when the type weighs them). Without noise (``tr1 == 0``)
    every residual is model error: chi2 infinite, p 0.
    """
    if tr1 > 0.0:
        scale = tr2 / tr1
        dof = tr1**2 / tr2
        chi2 = sum_sq / scale
        return chi2, dof, float(stats.chi2.sf(chi2, dof))
    return float("inf"), max(residual_dof, 1.0), 0.0


def _model_error(a_mat: Array, gain: Array, residuals: Array, blocks: Array, in_sample: Array) -> tuple[Array, Array]:
    """Covariance of the model error and its draws (the residuals recoloured to it).

    The larger of the in-sample estimate (residuals corrected for the fitted degrees of freedom)
    and the leave-one-out one: with few poses the fit follows the model error and only the
    prediction of a left-out pose shows it.
    """
    n = residuals.shape[0]
    observed_cv, noise_cv = _leave_one_out_moments(a_mat, gain, residuals, blocks)
    cross_validated = observed_cv - noise_cv
    use_cv = np.trace(cross_validated) > np.trace(in_sample)
    evals, evecs = np.linalg.eigh(cross_validated if use_cv else in_sample)
    inadequacy = (evecs * np.clip(evals, 0.0, None)) @ evecs.T
    centred = residuals - residuals.mean(axis=0)
    s_evals, s_evecs = np.linalg.eigh(centred.T @ centred / n)
    s_inv_sqrt = (s_evecs / np.sqrt(np.maximum(s_evals, np.finfo(float).tiny))) @ s_evecs.T
    m_evals, m_evecs = np.linalg.eigh(inadequacy)
    m_sqrt = (m_evecs * np.sqrt(np.clip(m_evals, 0.0, None))) @ m_evecs.T
    return inadequacy, centred @ (m_sqrt @ s_inv_sqrt).T


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
    n, dim = residuals.shape
    n_eq = dim * n
    repeated = repeated_pose_count(joint_positions)
    noise = pose_noise_covariances(calibration, joint_positions, tracker_noise, encoder_noise, distances)
    a_mat, gain, w_eq = _fit_gain(calibration, joint_positions)
    sum_sq = float(np.sum((residuals.reshape(n_eq) * w_eq) ** 2))
    blocks, tr1, tr2 = _residual_noise_moments(a_mat, gain, noise, w_eq)
    chi2, dof, p_value = _satterthwaite_test(sum_sq, tr1, tr2, float(n_eq) - calibration.effective_parameters)
    noise_in_residuals = blocks.mean(axis=0)
    fitted_fraction = max(1.0 - calibration.effective_parameters / float(n_eq), 1.0 / float(n_eq))
    observed = residuals.T @ residuals / n
    adequate = p_value >= significance
    inadequacy = np.zeros((dim, dim))
    draws = np.zeros_like(residuals)
    if not adequate:
        in_sample = (observed - noise_in_residuals) / fitted_fraction
        inadequacy, draws = _model_error(a_mat, gain, residuals, blocks, in_sample)
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
        residual_dof=float(dim * (n - repeated)) - calibration.effective_parameters,
        repeated_poses=repeated,
    )


REPEAT_TOLERANCE = 1e-6
"""Joint readings [rad, m] that agree within this on every joint are one pose (an encoder count
of an industrial arm is 1e-5 to 1e-6 rad; distinct calibration poses differ by degrees)."""


def repeated_pose_count(joint_positions: Array, tolerance: float = REPEAT_TOLERANCE) -> int:
    """Number of poses whose joint readings repeat an earlier pose's (rounded to `tolerance`)."""
    q = np.asarray(joint_positions, dtype=np.float64)
    if q.shape[0] < 2:
        return 0
    keys = np.round(q / tolerance)
    return int(q.shape[0] - np.unique(keys, axis=0).shape[0])


def _leave_one_out_moments(a_mat: Array, gain: Array, residuals: Array, blocks: Array) -> tuple[Array, Array]:
    """Leave-one-out second moments of the residuals and of their noise part, each (d, d).

    For the linear(ised) regularised fit ``y_hat = H y`` with ``H = A C``, deleting pose i's
    d equations gives the prediction error ``e_i = (I - H_ii)^-1 r_i`` (``H_ii`` its d x d
    diagonal block), whose noise part has covariance ``(I - H_ii)^-1 M_i (I - H_ii)^-T``
    (``blocks`` M_i). A pose the fit cannot predict without itself (H_ii near I) gets a
    large error: the cross-validated estimate sees the model error the fit absorbed.
    """
    n, d = residuals.shape
    k = gain.shape[0]
    a_p = a_mat.reshape(n, d, k)
    c_p = gain.reshape(k, n, d).transpose(1, 0, 2)
    lever = np.eye(d) - a_p @ c_p
    inv = np.linalg.pinv(lever)
    e = np.einsum("pij,pj->pi", inv, residuals)
    observed = e.T @ e / n
    noise = np.einsum("pij,pjk,plk->il", inv, blocks, inv) / n
    return observed, noise


def _residual_noise_moments(a_mat: Array, gain: Array, noise: Array, w: Array) -> tuple[Array, float, float]:
    """Per-pose blocks of M = (I - H) Sigma (I - H)^T and trace(Q), trace(Q^2) of Q = W M W.

    The fit's hat matrix is H = A C (`a_mat` (n_eq, k), `gain` C (k, n_eq)) and Sigma is block
    diagonal (`noise`, (n, d, d)), so everything follows from k x k and per-pose products,
    never from an n_eq x n_eq matrix (3 792 rows on a 632-pose 6-DOF campaign: 115 MB and
    seconds of dense products). With U = W A, V^T = C W^-1 and D = W Sigma W:
    Q = D - U E - E^T U^T + U F U^T, E = V^T D, F = E V; writing the low-rank part as
    Y N Y^T with Y = [U, E^T] and N = [[F, -I], [-I, 0]],
    trace(Q^2) = sum_i |D_i|_F^2 + 2 trace(D L) + trace(N G N G), G = Y^T Y.
    """
    n, d, _ = noise.shape
    k = gain.shape[0]
    a_p = a_mat.reshape(n, d, k)
    c_p = gain.reshape(k, n, d).transpose(1, 0, 2)  # (n, k, d): C's columns of each pose
    c_sigma = c_p @ noise  # (n, k, d): C Sigma per pose
    k_mat = np.einsum("ikd,ild->kl", c_sigma, c_p)  # C Sigma C^T
    h_sigma = a_p @ c_sigma  # (n, d, d): diagonal blocks of H Sigma
    blocks = noise - h_sigma - np.swapaxes(h_sigma, 1, 2) + a_p @ k_mat @ np.swapaxes(a_p, 1, 2)
    w_p = w.reshape(n, d)
    outer = w_p[:, :, None] * w_p[:, None, :]
    tr1 = float(np.sum(np.diagonal(blocks, axis1=1, axis2=2) * w_p**2))
    d_p = noise * outer  # blocks of D = W Sigma W
    u = a_mat * w[:, None]  # (n_eq, k)
    v = (gain / w[None, :]).T  # (n_eq, k)
    e_t = np.einsum("ide,iek->idk", d_p, v.reshape(n, d, k)).reshape(n * d, k)  # E^T = D V
    f = v.T @ e_t  # F = V^T D V, symmetric
    y = np.concatenate((u, e_t), axis=1)
    g = y.T @ y
    eye = np.eye(k)
    n_mat = np.block([[f, -eye], [-eye, np.zeros((k, k))]])
    # trace(D L) with L = -U E - E^T U^T + U F U^T: -2 trace(E D U) + trace(F U^T D U).
    d_u = np.einsum("ide,iek->idk", d_p, u.reshape(n, d, k)).reshape(n * d, k)
    trace_dl = -2.0 * float(np.sum(e_t * d_u)) + float(np.sum(f * (u.T @ d_u)))
    ng = n_mat @ g
    tr2 = float(np.sum(d_p * d_p)) + 2.0 * trace_dl + float(np.sum(ng * ng.T))
    return blocks, tr1, tr2
