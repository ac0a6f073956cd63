"""Session records of a calibration, and the between-session reproducibility of a robot.

:func:`session_state` turns a calibration into the
:class:`~robocal_uncertainty.core.session.SessionState` a later session needs: the linearised
covariance of the estimated parameters (stated tracker and encoder noise plus the model error
of :func:`~robocal_uncertainty.uncertainty.model_adequacy.assess_model_adequacy`), the model
error in the robot base frame, and the session's registration with its uncertainty.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.robot_model import rpy_to_matrix
from robocal_uncertainty.core.session import BASE_NAMES, SessionState, parameter_covariance
from robocal_uncertainty.core.simulation import EncoderNoise, TrackerNoise
from robocal_uncertainty.uncertainty.model_adequacy import ModelAdequacy, assess_model_adequacy, pose_noise_covariances

__all__ = ["campaign_distances", "session_state"]

Array = NDArray[np.float64]


def campaign_distances(campaign: Campaign, calibration: IdentificationResult) -> Array:
    """Tracker-to-target distance of every pose [m] (the tracker at the origin of its frame)."""
    positions = campaign.measurement.positions(campaign.points)
    if campaign.frame == "tracker" and positions is not None:
        return np.asarray(np.linalg.norm(positions, axis=1), dtype=np.float64)
    # Base-frame points: the tracker position is unknown; 2 m is the simulation's default reach.
    return np.full(campaign.n_poses, 2.0)


def session_state(
    calibration: IdentificationResult,
    campaign: Campaign,
    tracker_noise: TrackerNoise,
    encoder_noise: EncoderNoise,
    *,
    sources: tuple[str, ...] = ("tracker", "encoder", "residual"),
    adequacy: ModelAdequacy | None = None,
) -> tuple[SessionState, ModelAdequacy]:
    """What a point calibration leaves for verification and for the next session.

    Parameters
    ----------
    calibration : IdentificationResult
        A point calibration of `campaign`.
    campaign : Campaign
        Its campaign (joints reordered to the model's).
    tracker_noise, encoder_noise
        The stated noise models of the session.
    sources : tuple of str
        Sources the statement uses; without ``residual`` no model error is carried.
    adequacy : ModelAdequacy, optional
        Already computed model adequacy (computed here otherwise).
    """
    campaign = campaign.reorder_joints(calibration.model.joint_names)
    q = campaign.joint_positions
    distances = campaign_distances(campaign, calibration)
    if adequacy is None:
        adequacy = assess_model_adequacy(calibration, q, tracker_noise, encoder_noise, distances)
    noise = pose_noise_covariances(calibration, q, tracker_noise, encoder_noise, distances)
    model_error = adequacy.inadequacy_covariance if "residual" in sources else np.zeros((3, 3))
    cov = parameter_covariance(calibration, q, noise + model_error)
    layout = calibration.model.layout
    b0 = layout.base_index
    r_wb = rpy_to_matrix(calibration.estimate[b0 + 3 : b0 + 6])
    names = tuple(n for n, e in zip(calibration.parameter_names, calibration.estimated) if e)
    state = SessionState(
        frame=campaign.frame,
        frame_id=campaign.frame_id,
        n_poses=campaign.n_poses,
        covariance_names=names,
        parameter_covariance=cov,
        model_error_covariance=r_wb.T @ model_error @ r_wb,
        tracker_noise=tracker_noise,
        encoder_noise=encoder_noise,
        registration=calibration.estimate[b0 : b0 + 6].copy() if campaign.frame == "tracker" else np.zeros(6),
        registration_covariance=np.zeros((6, 6)),
        sources=tuple(sources),
    )
    reg_cov = state.covariance_of(BASE_NAMES)
    return SessionState(**{**state.__dict__, "registration_covariance": reg_cov}), adequacy
