"""What a point calibration leaves for verification and for the next session.

:func:`session_state` turns a calibration into the
:class:`~robocal_uncertainty.core.session.SessionState` a later session needs: the linearised
covariance of the estimated parameters (stated tracker and encoder noise plus the model error
of :func:`~robocal_uncertainty.uncertainty.model_adequacy.assess_model_adequacy`), the model
error in the robot base frame (:mod:`.field`), and the session's registration with its
uncertainty.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.core.model_error_field import ModelErrorField
from robocal_uncertainty.core.robot_model import rpy_to_matrix
from robocal_uncertainty.core.session import BASE_NAMES, SessionState, parameter_covariance, parameter_gain
from robocal_uncertainty.uncertainty.model_adequacy import ModelAdequacy, assess_model_adequacy, pose_noise_covariances
from robocal_uncertainty.uncertainty.sessions.check_campaign import block_diagonal
from robocal_uncertainty.uncertainty.sessions.field import (
    CrossValidatedModelError,
    campaign_distances,
    estimate_model_error_field,
    model_error_dof,
)
from robocal_uncertainty.uncertainty.sources.registry import default_sources, source_with_role

MODEL_ERROR_SOURCE = source_with_role("model_error")
"""The registry's model-error source: in a record's sources, its model error is stated."""

__all__ = ["MODEL_ERROR_SOURCE", "session_state"]

Array = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class _ModelError:
    """The model error a session states (measurement frame) and the parameter covariance it drives."""

    covariance: Array
    draws: Array | None
    field: ModelErrorField | None
    field_dof: float | None
    parameter_covariance: Array


def session_state(
    calibration: IdentificationResult,
    campaign: Campaign,
    tracker_noise: TrackerNoise,
    encoder_noise: EncoderNoise,
    *,
    sources: tuple[str, ...] = default_sources(),
    adequacy: ModelAdequacy | None = None,
    campaign_name: str | None = None,
    settings: dict[str, object] | None = None,
    cross_validated: CrossValidatedModelError | None = None,
    correlated: bool = True,
    model_error_from: SessionState | None = None,
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
    campaign_name : str, optional
        The campaign file, recorded.
    settings : dict, optional
        Settings to record (lambda method, weighting, ...).
    cross_validated : CrossValidatedModelError, optional
        The model error from held-out poses (:func:`~.cross_validation.cross_validated_model_error`): used in
        place of the one from the calibration's own residuals when the model is inadequate.
    correlated : bool
        When the model is inadequate (and no `cross_validated` is given), estimate the model
        error as a field correlated over the configurations (:func:`~.field.estimate_model_error_field`,
        shape from the residuals' moments): the per-pose covariance, the parameter covariance
        (``G (N + V) G^T`` with the correlated ``V``) and what a check needs to use it.
    """
    campaign = campaign.reorder_joints(calibration.model.joint_names)
    q = campaign.joint_positions
    distances = campaign_distances(campaign, calibration)
    if adequacy is None:
        adequacy = assess_model_adequacy(calibration, q, tracker_noise, encoder_noise, distances)
    noise = pose_noise_covariances(calibration, q, tracker_noise, encoder_noise, distances)
    b0 = calibration.model.layout.base_index
    r_wb = rpy_to_matrix(calibration.estimate[b0 + 3 : b0 + 6])
    use_residual = MODEL_ERROR_SOURCE in sources and not adequacy.adequate
    if model_error_from is not None:
        use_residual = MODEL_ERROR_SOURCE in sources and bool(np.any(model_error_from.model_error_covariance))
    error = _model_error(
        calibration,
        q,
        noise,
        r_wb,
        adequacy,
        use_residual=use_residual,
        cross_validated=cross_validated,
        correlated=correlated,
        model_error_from=model_error_from,
    )
    model_error, draws, me_field = error.covariance, error.draws, error.field
    names = tuple(n for n, e in zip(calibration.parameter_names, calibration.estimated) if e)
    model_error_cov_base = r_wb.T @ model_error @ r_wb
    state = SessionState(
        frame=campaign.frame,
        frame_id=campaign.frame_id,
        n_poses=campaign.n_poses,
        covariance_names=names,
        parameter_covariance=error.parameter_covariance,
        model_error_covariance=r_wb.T @ model_error @ r_wb,
        model_error_draws=draws,
        model_error_dof=error.field_dof
        if me_field is not None
        else (None if draws is None else model_error_dof(draws, model_error_cov_base)),
        model_error_field=me_field,
        tracker_noise=tracker_noise,
        encoder_noise=encoder_noise,
        registration=calibration.estimate[b0 : b0 + 6].copy() if campaign.frame == "tracker" else np.zeros(6),
        registration_covariance=np.zeros((6, 6)),
        sources=tuple(sources),
        extra=_extra(calibration, adequacy, sources, campaign_name, settings, cross_validated),
    )
    return dataclasses.replace(state, registration_covariance=state.covariance_of(BASE_NAMES)), adequacy


def _model_error(
    calibration: IdentificationResult,
    q: Array,
    noise: Array,
    r_wb: Array,
    adequacy: ModelAdequacy,
    *,
    use_residual: bool,
    cross_validated: CrossValidatedModelError | None,
    correlated: bool,
    model_error_from: SessionState | None,
) -> _ModelError:
    """The stated model error (from the residuals, held-out folds, another record or a field)."""
    model_error = adequacy.inadequacy_covariance if use_residual else np.zeros((3, 3))
    draws = adequacy.draws @ r_wb if use_residual else None
    if use_residual and cross_validated is not None:
        model_error = r_wb @ cross_validated.covariance @ r_wb.T
        draws = cross_validated.draws
    if use_residual and model_error_from is not None and model_error_from.model_error_field is None:
        model_error = r_wb @ model_error_from.model_error_covariance @ r_wb.T
        draws = model_error_from.model_error_draws
    me_field = None
    field_dof = None
    if use_residual and cross_validated is None and correlated:
        if model_error_from is not None and model_error_from.model_error_field is not None:
            # Another calibration's model error (same session, other poses): its field as stated.
            me_field = dataclasses.replace(model_error_from.model_error_field, joint_positions=q)
            model_error = r_wb @ model_error_from.model_error_covariance @ r_wb.T
        else:
            shape = r_wb.T @ adequacy.inadequacy_covariance @ r_wb
            me_field, scale = estimate_model_error_field(calibration, q, noise, shape)
            shape = 3.0 * shape / np.trace(shape) if np.trace(shape) > 0 else np.eye(3)
            model_error = r_wb @ (scale * shape) @ r_wb.T
        total = block_diagonal(noise) + me_field.covariance(q, model_error)
        cov = parameter_covariance(calibration, q, total)
        # The gain times blockdiag(r_wb, ..., r_wb), pose by pose (the dense block-diagonal
        # product cost a quarter of a fold's record in the validated level; the same sums).
        gain = parameter_gain(calibration, q)
        gain = (gain.reshape(gain.shape[0], q.shape[0], 3) @ r_wb).reshape(gain.shape)
        me_field = dataclasses.replace(
            me_field,
            gain_names=tuple(n for n, e in zip(calibration.parameter_names, calibration.estimated) if e),
            gain=gain,
        )
        field_dof = me_field.dof
    else:
        cov = parameter_covariance(calibration, q, noise + model_error)
    if use_residual and cross_validated is not None:
        cov = cov * cross_validated.parameter_factor
    return _ModelError(model_error, draws, me_field, field_dof, cov)


def _extra(
    calibration: IdentificationResult,
    adequacy: ModelAdequacy,
    sources: tuple[str, ...],
    campaign_name: str | None,
    settings: dict[str, object] | None,
    cross_validated: CrossValidatedModelError | None,
) -> dict[str, object]:
    """What the session record keeps beside the numbers: campaign, settings, tool, adequacy."""
    return {
        "campaign": campaign_name,
        "settings": dict(settings or {}),
        "tool_point_m": [float(v) for v in calibration.model.tool_point],
        "model_adequacy": {
            "adequate": bool(adequacy.adequate),
            "chi2": float(adequacy.chi2),
            "dof": float(adequacy.dof),
            "p_value": float(adequacy.p_value),
            "significance": float(adequacy.significance),
            "included": MODEL_ERROR_SOURCE in sources,
            "cross_validated": None if cross_validated is None else cross_validated.to_dict(),
        },
    }
