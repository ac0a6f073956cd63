"""The session services: calibrate with a session record, and verify a calibration in a new session.

:func:`calibrate_session` identifies the parameters of a campaign (as ``calibrate``) and adds
what a later session needs: the parameter covariance, the model error, the noise models and
the session's registration (:class:`~robocal_uncertainty.core.session.SessionState`), written
by :func:`~robocal_uncertainty.core.calibration_file.write_calibration`.

:func:`verify` reads such a calibration file and a short check campaign measured in a new
session, re-registers the new measurement frame (and the tool point when asked), and tests
whether the robot still agrees with its calibration within the stated uncertainty
(:func:`~robocal_uncertainty.uncertainty.sessions.verification.verify_session`).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from robocal_uncertainty.core.calibration_file import apply_calibration, read_calibration, read_session_state
from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult, identify
from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.core.measurement import POINT
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.session import DEFAULT_NULL_TRIALS, DEFAULT_SIGNIFICANCE, SessionState, Verification
from robocal_uncertainty.errors import CalibError, ConfigError
from robocal_uncertainty.uncertainty.model_adequacy import ModelAdequacy
from robocal_uncertainty.uncertainty.sessions.between import (
    estimate_between_sessions,
    identifiable_effects,
    with_between_sessions,
)
from robocal_uncertainty.uncertainty.sessions.class_prior import ClassPrior, pooled_with_prior, prior_between_sessions
from robocal_uncertainty.uncertainty.sessions.cross_validation import cross_validated_model_error
from robocal_uncertainty.uncertainty.sessions.orientation import orientation_check, orientation_validated_level
from robocal_uncertainty.uncertainty.sessions.state import MODEL_ERROR_SOURCE, session_state
from robocal_uncertainty.uncertainty.sessions.validated_level import validated_level
from robocal_uncertainty.uncertainty.sessions.verification import verify_session
from robocal_uncertainty.uncertainty.sources.registry import default_sources

__all__ = [
    "SessionCalibration",
    "VerificationRun",
    "calibrate_session",
    "load_session_calibration",
    "scope_text",
    "verify",
    "with_orientation",
]


@dataclass(frozen=True, eq=False)
class SessionCalibration:
    """A calibration and its session record (None for orientation data, with a warning)."""

    result: IdentificationResult
    state: SessionState | None
    adequacy: ModelAdequacy | None
    warnings: tuple[str, ...]


def calibrate_session(
    model: RobotModel,
    campaign: Campaign,
    *,
    tracker_noise: TrackerNoise,
    encoder_noise: EncoderNoise,
    lambda_: str | float = "auto",
    accept_unconverged: bool = False,
    sources: tuple[str, ...] = default_sources(),
    campaign_name: str | None = None,
    cross_validation_folds: int = 5,
    later_sessions: Sequence[Campaign] = (),
    retool: bool = True,
    correlated_model_error: bool = True,
    validate_level: bool = True,
    class_prior: ClassPrior | None = None,
) -> SessionCalibration:
    """Identify `campaign` and record the session for verification and later sessions.

    Parameters
    ----------
    model : RobotModel
        Nominal model.
    campaign : Campaign
    tracker_noise, encoder_noise
        The session's stated instruments (the model error is what they do not explain).
    lambda_, accept_unconverged
        As :func:`~robocal_uncertainty.core.identification.identify`.
    sources : tuple of str
        Sources of the statement; ``residual`` carries the model error.
    campaign_name : str, optional
        Recorded in the file.
    cross_validation_folds : int
        With `correlated_model_error` off and an inadequate model, take the model error from
        this many folds of held-out poses
        (:func:`~robocal_uncertainty.uncertainty.sessions.cross_validation.cross_validated_model_error`); 0 keeps
        the one from the calibration's own residuals.
    later_sessions : sequence of Campaign
        Campaigns of the same robot from other sessions (their own tracker set-ups): the
        between-session component is estimated from them and the statement then holds for a
        future session (:mod:`~robocal_uncertainty.uncertainty.sessions.between`).
    retool : bool
        The probe was remounted between sessions (re-register the tool point on each).
    correlated_model_error : bool
        When the model is inadequate, state the model error as a field correlated over the
        joint configurations, estimated from the calibration's residuals by restricted maximum
        likelihood (:func:`~robocal_uncertainty.uncertainty.sessions.field.estimate_model_error_field`;
        default). Off: independent from pose to pose (held-out folds as above).
    validate_level : bool
        Measure the calibration's error level on its own held-out poses, re-registered as a
        check (:func:`~robocal_uncertainty.uncertainty.sessions.validated_level.validated_level`,
        four splits into five folds):
        ``verify`` tests a check against it and states the check's error ratio.
    class_prior : ClassPrior, optional
        The stated between-session spread of the robot class
        (:mod:`~robocal_uncertainty.uncertainty.sessions.class_prior`): with one session the
        statement for a future session uses it; with `later_sessions` it is pooled with their
        estimate. None (default): one session's statement is for that session only.
    """
    result = identify(model, campaign, lambda_=lambda_, accept_unconverged=accept_unconverged)
    point = _point_calibration(model, campaign, result, lambda_)
    if point is None:
        warning = "no session record: verify and between-session statements need measured positions"
        return SessionCalibration(result=result, state=None, adequacy=None, warnings=(warning,))
    options = _RecordOptions(
        tracker_noise, encoder_noise, lambda_, sources, campaign_name, cross_validation_folds, retool,
        correlated_model_error, validate_level,
    )  # fmt: skip
    state, adequacy, warnings = _session_record(*point, options)
    if validate_level and campaign.measurement.measures_orientation and point[2] is not result:
        weights = getattr(result.measurement, "weight_std", None)
        state = _with_orientation_level(model, campaign, state, lambda_, retool, weights, warnings)
    if later_sessions:
        between = estimate_between_sessions(
            point[2].model, state, list(later_sessions), retool=retool, reference_campaign=point[1]
        )
        if class_prior is not None:
            between = pooled_with_prior(between, class_prior)
        state = with_between_sessions(state, between)
    elif class_prior is not None:
        state = with_between_sessions(
            state, prior_between_sessions(point[2].model, point[1], class_prior, retool=retool)
        )
    if point[2] is not result and state.frame == "tracker":
        # Tracker move and tool change are reported against the parameters the file holds.
        b0 = result.model.layout.base_index
        extra = dict(state.extra)
        extra["tool_point_m"] = [float(v) for v in result.model.tool_point]
        state = dataclasses.replace(state, registration=result.estimate[b0 : b0 + 6].copy(), extra=extra)
    return SessionCalibration(result=result, state=state, adequacy=adequacy, warnings=tuple(warnings))


@dataclass(frozen=True)
class _RecordOptions:
    """How :func:`calibrate_session` makes the session record (its keyword arguments)."""

    tracker_noise: TrackerNoise
    encoder_noise: EncoderNoise
    lambda_: str | float
    sources: tuple[str, ...]
    campaign_name: str | None
    cross_validation_folds: int
    retool: bool
    correlated_model_error: bool
    validate_level: bool


def _point_calibration(
    model: RobotModel, campaign: Campaign, result: IdentificationResult, lambda_: str | float
) -> tuple[RobotModel, Campaign, IdentificationResult, list[str]] | None:
    """The point calibration the session record is made of (None: the campaign has no positions)."""
    if result.measurement.dimension == 3 and result.measurement.weights is None:
        return model, campaign, result, []
    # A 6-DOF (or weighted) calibration: verify checks tool points, so the session record is
    # the point calibration of the same poses (positions only, the tool point's part); the
    # file keeps the 6-DOF parameters.
    positions = campaign.measurement.positions(campaign.points)
    if positions is None:
        return None
    campaign = dataclasses.replace(campaign, points=np.asarray(positions), measurement=POINT, point_std=None)
    model = dataclasses.replace(model, tool_rotation=False)
    result = identify(model, campaign, lambda_=lambda_, accept_unconverged=True)
    warning = (
        "session record from the positions of the same poses (a point calibration of them): verify checks "
        "tool points against it with this calibration's parameters"
    )
    return model, campaign, result, [warning]


def _with_orientation_level(
    model: RobotModel,
    campaign: Campaign,
    state: SessionState,
    lambda_: str | float,
    retool: bool,
    weight_std: tuple[float, ...] | None,
    warnings: list[str],
) -> SessionState:
    """The session record with a 6-DOF calibration's validated orientation level (``verify``'s
    reference for the orientations of a 6-DOF check)."""
    try:
        level = orientation_validated_level(
            model.with_tool_rotation(), campaign, lambda_=lambda_, retool=retool, weight_std=weight_std
        )
    except CalibError as err:
        warnings.append(f"no validated orientation level (verify then checks the positions alone): {err}")
        return state
    extra = dict(state.extra)
    extra["orientation_level"] = level.to_dict()
    return dataclasses.replace(state, extra=extra)


def _session_record(
    model: RobotModel, campaign: Campaign, result: IdentificationResult, warnings: list[str], o: _RecordOptions
) -> tuple[SessionState, ModelAdequacy, list[str]]:
    """The session record of a point calibration: model error (field or folds), validated level."""
    settings: dict[str, object] = {
        "lambda": str(o.lambda_),
        "lambda_method": result.lambda_method,
        "cross_validation_folds": o.cross_validation_folds,
        "retool": o.retool,
        "correlated_model_error": o.correlated_model_error,
    }
    noise = (o.tracker_noise, o.encoder_noise)
    record = functools.partial(session_state, sources=o.sources, campaign_name=o.campaign_name, settings=settings)
    state, adequacy = record(result, campaign, *noise, correlated=o.correlated_model_error)
    folds = o.cross_validation_folds
    if not o.correlated_model_error and folds and not adequacy.adequate and MODEL_ERROR_SOURCE in o.sources:
        try:
            cv = cross_validated_model_error(model, campaign, *noise, folds=folds, lambda_=o.lambda_)
        except CalibError as err:
            warnings.append(f"model error from the calibration's own residuals: {folds}-fold {err}")
        else:
            state, adequacy = record(result, campaign, *noise, adequacy=adequacy, cross_validated=cv, correlated=False)
    if o.validate_level:
        try:
            level = validated_level(
                model, campaign, *noise, lambda_=o.lambda_, retool=o.retool, sources=o.sources,
                correlated=o.correlated_model_error, reference=state,
            )  # fmt: skip
        except CalibError as err:
            warnings.append(f"no validated error level (verify then tests against the statement alone): {err}")
        else:
            state = dataclasses.replace(state, validated_level=level)
    return state, adequacy, warnings


def load_session_calibration(model: RobotModel, path: str | Path) -> tuple[RobotModel, SessionState, dict[str, Any]]:
    """The calibrated model, its session record and the raw file of a calibration.

    Raises
    ------
    ConfigError
        Not a calibration of this robot, or one without a session record (version 1 files,
        orientation calibrations): the message says to re-run ``calibrate --json``.
    """
    where = f"calibration {path}"
    data = read_calibration(path)
    calibrated = apply_calibration(model, data, where=where)
    state = read_session_state(data, where=where)
    if state is None:
        msg = (
            f"{where} has no session record (parameter covariance, model error, registration): "
            "written by an older version or from orientation data; re-run calibrate --json on its campaign"
        )
        raise ConfigError(msg)
    return calibrated, state, data


@dataclass(frozen=True, eq=False)
class VerificationRun:
    """What :func:`verify` did: the check's result and what it was run with."""

    verification: Any  # robocal_uncertainty.core.session.Verification
    calibration_path: Path
    check_campaign: str
    state: SessionState
    robot: str
    scope: Literal["session", "future sessions"] | str

    @property
    def scope_text(self) -> str:
        """Whom the statement holds for, in words (:func:`scope_text`)."""
        return scope_text(self.scope)


def scope_text(scope: str) -> str:
    """The words ``verify`` prints for a calibration's scope."""
    return "this calibration's session set-up only" if scope == "session" else "a future session"


def verify(
    model: RobotModel,
    calibration_path: str | Path,
    check: Campaign,
    *,
    check_name: str = "",
    retool: bool = False,
    significance: float = DEFAULT_SIGNIFICANCE,
    tracker_noise: TrackerNoise | None = None,
    encoder_noise: EncoderNoise | None = None,
    null_trials: int = DEFAULT_NULL_TRIALS,
    seed: int = 0,
    effects: bool = False,
) -> VerificationRun:
    """Verify a calibration on a check campaign of a new session.

    The call ``robocal-uncertainty verify`` and the calibration node's ``~/verify`` make.

    Parameters
    ----------
    model : RobotModel
        Nominal model of the robot (the calibration is applied to it).
    calibration_path : str or Path
        A calibration file with a session record.
    check : Campaign
        The check campaign (5-20 poses spread over the workspace).
    check_name : str
        Names the check campaign in the result.
    retool : bool
        Re-register the tool point (probe remounted).
    significance, tracker_noise, encoder_noise, null_trials, seed
        See :func:`~robocal_uncertainty.uncertainty.sessions.verification.verify_session`.
    effects : bool
        Also estimate what changed since the calibration (joint offsets, length scale) on
        the check (:func:`~robocal_uncertainty.uncertainty.sessions.between.identifiable_effects`).

    Raises
    ------
    CalibError
        The calibration cannot be read or has no session record, or the check cannot
        re-register (too few poses, degenerate): the message says which.
    """
    calibrated, state, _ = load_session_calibration(model, calibration_path)
    names = identifiable_effects(calibrated, check, retool=retool) if effects else ()
    # A 6-DOF calibration on a 6-DOF check: positions and orientations, each half at half the
    # significance (Bonferroni), so the check's false-alarm rate stays at `significance`.
    six_dof = state.orientation_level is not None and calibrated.tool_rotation
    six_dof = six_dof and check.measurement.measures_orientation
    half = significance / 2.0 if six_dof else significance
    result = verify_session(
        calibrated,
        state,
        check,
        retool=retool,
        significance=half,
        tracker_noise=tracker_noise,
        encoder_noise=encoder_noise,
        null_trials=null_trials,
        seed=seed,
        effects=names,
    )
    if six_dof:
        result = with_orientation(result, calibrated, state, check, retool=retool, significance=significance)
    return VerificationRun(
        verification=result,
        calibration_path=Path(calibration_path),
        check_campaign=check_name,
        state=state,
        robot=model.name,
        scope=state.scope,
    )


def with_orientation(
    result: Verification, calibrated: RobotModel, state: SessionState, check: Campaign, *, retool: bool,
    significance: float,
) -> Verification:  # fmt: skip
    """`result` (the positions, tested at half `significance`) with the orientation half added.

    The check is consistent when both halves are; the verdict line names the half that drifted.
    """
    reference = state.orientation_level
    if reference is None:
        return result
    half = significance / 2.0
    orient = orientation_check(calibrated, reference, check, retool=retool, significance=half)
    t = orient.level_test
    i0, i1 = t.ratio_interval
    words = (
        f"orientation errors {t.ratio:.2f}x the calibration session's (95 % interval {i0:.2f}-{i1:.2f}; "
        f"F test on {t.check_dof:.0f} and {t.reference_dof:.0f} degrees of freedom, p = {t.p_value:.3g} "
        f"{'>=' if orient.consistent else '<'} {half:g})"
    )
    consistent = result.consistent and orient.consistent
    if orient.consistent:
        verdict = f"{result.verdict}; {words}"
    elif result.consistent:
        excess = float(np.sqrt(max(orient.level - reference.level, 0.0)))
        verdict = (
            f"drifted: the tool orientations deviate from the calibration by about {excess * 1e3:.3g} mrad per "
            f"axis beyond its validated level: {words}; positions within theirs: {result.verdict.split(': ', 2)[-1]}"
            "; re-calibrate"
        )
    else:
        verdict = f"{result.verdict}; {words}"
    note = f"6-DOF check: positions and orientations each tested at {half:g} (together {significance:g}, Bonferroni)"
    return dataclasses.replace(
        result, consistent=consistent, verdict=verdict, orientation=orient, warnings=(*result.warnings, note)
    )
