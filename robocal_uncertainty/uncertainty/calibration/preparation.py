"""What an evaluation derives from its inputs before any trial runs.

The calibration (computed here when not given), the batched problem of the
re-identification, the model-adequacy assessment and the model-error field, the context
the sources are built from, and the picklable trial block; inputs are checked first, so a
bad setting stops with one line before the work.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult, identify
from robocal_uncertainty.core.kinematics import forward_poses
from robocal_uncertainty.core.pose_measurement import PoseMeasurement
from robocal_uncertainty.core.robot_model import RobotModel, rpy_to_matrix
from robocal_uncertainty.core.session import effect_jacobian
from robocal_uncertainty.errors import ConfigError, InputError
from robocal_uncertainty.kernels import Backend, ToolPredictor, get_backend
from robocal_uncertainty.montecarlo.summary import coverage_window
from robocal_uncertainty.uncertainty.calibration.results import N_AXES, OUTPUT_FRAMES
from robocal_uncertainty.uncertainty.calibration.trials import CalibrationTrials
from robocal_uncertainty.uncertainty.model_adequacy import (
    ModelAdequacy,
    assess_model_adequacy,
    pose_noise_covariances,
)
from robocal_uncertainty.uncertainty.model_error_draws import (
    FieldEstimate,
    FieldNormal,
    estimate_field,
    rescaled_field,
    standardised_innovations,
)
from robocal_uncertainty.uncertainty.reidentification import BatchProblem, ChordSolver
from robocal_uncertainty.uncertainty.sources import TrialContext, UncertaintySettings, build_sources, sources_with_role

__all__ = [
    "Prepared",
    "held_field_correlation",
    "prepare",
    "prepare_calibration_trials",
    "test_effect_jacobian",
    "validate_inputs",
]

Array = NDArray[np.float64]


def validate_inputs(
    model: RobotModel, test_joint_positions: ArrayLike, coverage: float, trials: object
) -> tuple[Array, int | None]:
    """The test configurations as (n_test, n_joints) [rad] and the fixed trial count (None: adaptive).

    Raises
    ------
    ConfigError, InputError
        Test joints of the wrong shape or not finite, a coverage outside (0, 1), a trial
        count that is not a positive integer or ``"auto"``, or too small for the coverage.
    """
    q = np.asarray(test_joint_positions, dtype=np.float64)
    if q.ndim == 1:
        q = q[None, :]
    if q.ndim != 2 or q.shape[1] != model.n_joints or q.shape[0] == 0:
        msg = (
            f"test joints must have {model.n_joints} values per configuration "
            f"({', '.join(model.joint_names)}) and at least one configuration, "
            f"got shape {np.shape(test_joint_positions)}"
        )
        raise ConfigError(msg)
    if not np.isfinite(q).all():
        raise InputError("test joints contain NaN or inf")
    if isinstance(coverage, bool) or not isinstance(coverage, (int, float)) or not 0.0 < coverage < 1.0:
        msg = f"coverage probability must be in (0, 1), got {coverage!r}"
        raise ConfigError(msg)
    if trials == "auto":
        return q, None
    if isinstance(trials, bool) or not isinstance(trials, (int, np.integer)) or trials <= 0:
        msg = f"trials must be a positive integer or 'auto', got {trials!r}"
        raise ConfigError(msg)
    try:
        # Refuse before the work: the summary would refuse the same count after every trial ran.
        coverage_window(int(trials), float(coverage))
    except InputError as err:
        raise ConfigError(f"trials: {err}") from None
    return q, int(trials)


@dataclass(frozen=True, eq=False)
class Prepared:
    """Everything an evaluation derives from its inputs before the trials run."""

    trials: CalibrationTrials
    calibration: IdentificationResult
    campaign: Campaign
    problem: BatchProblem
    test_joints: Array
    context: TrialContext
    adequacy: ModelAdequacy
    lambda_range: tuple[float, float] | None
    frame_id: str
    model_error_field: FieldEstimate | None = None


def _test_predictor(
    calibration: IdentificationResult, test_q: Array, *, drop_base: bool, backend: Backend
) -> ToolPredictor | None:
    """The tool at the test configurations near the calibration, by the backend's walk (the
    numpy one: series instead of a sine and a cosine per joint, to a few ulps of
    :func:`forward_points`), or None where the backend has none (numpy: prismatic joints, a
    mount, or a large set, see ``NEARBY_TEST_CONFIGURATIONS``)."""
    layout = calibration.model.layout
    p_out = calibration.estimate.copy()
    if drop_base:
        p_out[layout.base_index : layout.base_index + 6] = 0.0
    return backend.tool_predictor(layout, p_out, test_q)


def _chord_solver(problem: BatchProblem, params: Array, joints: Array, backend: Backend) -> ChordSolver:
    """The chord solver at the calibration, predicting with the backend's walk."""
    solver = ChordSolver.at(problem, params, joints)
    if backend.name == "numpy":
        return solver  # the measurement type's own nearby predictor, as ChordSolver.at gives it
    predictor = backend.measurement_predictor(problem.measurement, problem.layout, params, joints)
    return dataclasses.replace(solver, predictor=predictor)


def _calibrated_rotations(calibration: IdentificationResult, test_q: Array, *, drop_base: bool) -> Array:
    """Tool rotations of the calibrated model at the test configurations, shape (n_test, 3, 3)."""
    layout = calibration.model.layout
    p_out = calibration.estimate.copy()
    if drop_base:
        p_out[layout.base_index : layout.base_index + 6] = 0.0
    _, rot = forward_poses(layout, p_out, test_q)
    return rot


def test_effect_jacobian(
    calibration: IdentificationResult, test_q: Array, settings: UncertaintySettings
) -> Array | None:
    """Derivative of the tool point at the test configurations w.r.t. the session effects.

    Shape (n_test, 3, k), in the measurement frame as every ``predictions`` offset (the output
    rotation takes them into the base frame); None without a between-session component.
    """
    between = settings.between_session
    if between is None:
        return None
    return effect_jacobian(calibration.model.layout, calibration.estimate, test_q, tuple(between.names))


def _lambda_range(settings: UncertaintySettings, calibration: IdentificationResult) -> tuple[float, float] | None:
    """Range of the ``lambda`` source (None when it is off): [lambda*/5, 5 lambda*] by default."""
    lam_star = calibration.lambda_
    if not sources_with_role(settings.sources, "lambda"):
        return None
    if settings.lambda_range is None:
        return (lam_star / 5.0, lam_star * 5.0)
    lambda_range = (float(settings.lambda_range[0]), float(settings.lambda_range[1]))
    if not lambda_range[0] <= lam_star <= lambda_range[1]:
        msg = (
            f"lambda range [{lambda_range[0]:.4g}, {lambda_range[1]:.4g}] excludes the "
            f"calibration's optimum lambda {lam_star:.4g} ({calibration.lambda_method})"
        )
        raise ConfigError(msg)
    return lambda_range


def _pose_counts(settings: UncertaintySettings, n_poses: int, dim: int, k: int) -> tuple[int, int]:
    """``min_poses`` and ``subset_size`` of the pose sources, checked when one of them is on."""
    min_identifiable = math.ceil(k / dim)
    min_poses = settings.min_poses or max(math.ceil(40 / dim), math.ceil(1.5 * k / dim))
    subset_size = settings.subset_size or round(33 / 53 * n_poses)
    for name, value in (("min_poses", min_poses), ("subset_size", subset_size)):
        if sources_with_role(settings.sources, "pose_count", "pose_subset"):
            if value < min_identifiable or value > n_poses:
                msg = (
                    f"{name} = {value} must lie between {min_identifiable} (identifiable "
                    f"parameters / {dim}) and the campaign's {n_poses} poses"
                )
                raise ConfigError(msg)
    return min_poses, subset_size


def _model_error_field(
    settings: UncertaintySettings,
    calibration: IdentificationResult,
    campaign: Campaign,
    test_q: Array,
    adequacy: ModelAdequacy,
    distances: Array,
) -> tuple[FieldEstimate | None, FieldNormal | None]:
    """The model-error field of the ``residual`` source and its draws (None, None: not asked or adequate)."""
    drawn = bool(sources_with_role(settings.sources, "model_error"))
    if not (drawn and not adequacy.adequate and settings.model_error == "field"):
        return None, None
    noise = pose_noise_covariances(
        calibration, campaign.joint_positions, settings.tracker_noise, settings.encoder_noise, distances
    )
    # The shape of the residuals' own covariance: the model error dominates it, and unlike the
    # moment estimate (clipped to be PSD) it has variance in every direction the data have.
    field_estimate = _field_estimate(settings, calibration, campaign, noise, adequacy.residual_covariance, distances)
    if not field_estimate.identified:
        return field_estimate, None
    return field_estimate, _field_draw(field_estimate, campaign.joint_positions, test_q, calibration)


_DRAW_CACHE: list[tuple[FieldEstimate, Array, Array, IdentificationResult, FieldNormal]] = []


def _field_draw(
    estimate: FieldEstimate, joint_positions: Array, test_q: Array, calibration: IdentificationResult
) -> FieldNormal:
    """The draws of `estimate` (their factors cost a few factorisations of the calibration poses'
    correlation): the same object for the same estimate, poses and test configurations (the
    budget's and the equations sweep's runs; it holds no state between draws)."""
    q = np.asarray(joint_positions, dtype=np.float64)
    for est, q_c, test_c, cal, draw in _DRAW_CACHE:
        if est is estimate and cal is calibration and np.array_equal(q_c, q) and np.array_equal(test_c, test_q):
            return draw
    draw = FieldNormal(
        q,
        test_q,
        estimate,
        innovations=standardised_innovations(np.asarray(calibration.residuals, dtype=np.float64)),
    )
    _DRAW_CACHE.insert(0, (estimate, q.copy(), np.array(test_q, dtype=np.float64), calibration, draw))
    del _DRAW_CACHE[_FIELD_CACHE_SIZE:]
    return draw


@dataclass(frozen=True, eq=False)
class _FieldEntry:
    """One estimate of :func:`_field_estimate`'s cache, with everything it was computed from."""

    calibration: IdentificationResult
    joint_positions: Array
    noise: Array
    shape: Array
    estimate: FieldEstimate

    def matches(self, calibration: IdentificationResult, joint_positions: Array, noise: Array, shape: Array) -> bool:
        return (
            self.calibration is calibration
            and np.array_equal(self.joint_positions, joint_positions)
            and np.array_equal(self.noise, noise)
            and np.array_equal(self.shape, shape)
        )


_FIELD_CACHE: list[_FieldEntry] = []
_FIELD_CACHE_SIZE = 4
_HELD_CORRELATION: contextvars.ContextVar[IdentificationResult | None] = contextvars.ContextVar(
    "held_field_correlation", default=None
)


@contextlib.contextmanager
def held_field_correlation(reference: IdentificationResult | None) -> Iterator[None]:
    """Within it, the model-error field of every calibration other than `reference` keeps the
    correlation and shape hyperparameters of `reference`'s field and re-estimates only its scale
    from its own residuals (:func:`~robocal_uncertainty.uncertainty.model_error_draws.rescaled_field`):
    a sensitivity sweep shows the effect of its setting, not a re-sampling of the hyperparameters.
    None: every calibration's field estimated in full."""
    token = _HELD_CORRELATION.set(reference)
    try:
        yield
    finally:
        _HELD_CORRELATION.reset(token)


def _cached(
    calibration: IdentificationResult, joint_positions: Array, noise: Array, shape: Array
) -> FieldEstimate | None:
    for entry in _FIELD_CACHE:
        if entry.matches(calibration, joint_positions, noise, shape):
            return entry.estimate
    return None


def _remember(
    calibration: IdentificationResult, joint_positions: Array, noise: Array, shape: Array, estimate: FieldEstimate
) -> FieldEstimate:
    _FIELD_CACHE.insert(0, _FieldEntry(calibration, joint_positions.copy(), noise.copy(), shape.copy(), estimate))
    del _FIELD_CACHE[_FIELD_CACHE_SIZE:]
    return estimate


def _full_estimate(
    calibration: IdentificationResult, joint_positions: Array, noise: Array, shape: Array
) -> FieldEstimate:
    """The field of `calibration` estimated in full, once per calibration and inputs: the budget's
    and the sweeps' runs of the same calibration take the statement's estimate (a deterministic
    function of these inputs) instead of repeating it."""
    cached = _cached(calibration, joint_positions, noise, shape)
    if cached is not None:
        return cached
    return _remember(
        calibration, joint_positions, noise, shape, estimate_field(calibration, joint_positions, noise, shape)
    )


def _field_estimate(
    settings: UncertaintySettings,
    calibration: IdentificationResult,
    campaign: Campaign,
    noise: Array,
    shape: Array,
    distances: Array,
) -> FieldEstimate:
    """The field of `calibration`: in full, or under :func:`held_field_correlation` with the
    reference calibration's correlation and shape held (its per-pose covariance re-estimated)."""
    q = np.asarray(campaign.joint_positions, dtype=np.float64)
    noise = np.asarray(noise, dtype=np.float64)
    shape = np.asarray(shape, dtype=np.float64)
    reference = _HELD_CORRELATION.get()
    if reference is None or reference is calibration:
        return _full_estimate(calibration, q, noise, shape)
    ref_noise = pose_noise_covariances(reference, q, settings.tracker_noise, settings.encoder_noise, distances)
    held = next(
        (
            e.estimate
            for e in _FIELD_CACHE
            if e.calibration is reference
            and np.array_equal(e.joint_positions, q)
            and np.array_equal(e.noise, ref_noise)
        ),
        None,
    )
    if held is None:
        ref_shape = assess_model_adequacy(
            reference, q, settings.tracker_noise, settings.encoder_noise, distances
        ).residual_covariance
        held = _full_estimate(reference, q, ref_noise, np.asarray(ref_shape, dtype=np.float64))
    # Not remembered: a sweep point's calibration is its own (the cache keeps the full estimates).
    return rescaled_field(held, calibration, q, noise, shape)


def _tracker_distances(settings: UncertaintySettings, campaign: Campaign) -> Array:
    """Distance of every measured point from the tracker [m] (for the MPE a + b L)."""
    measurement = campaign.measurement
    positions = measurement.positions(campaign.points)
    if positions is None:
        msg = f"{measurement.quantity} measurements hold no position: no tracker distance for the noise model"
        raise InputError(msg)
    origin = np.zeros(3) if campaign.frame == "tracker" else np.asarray(settings.tracker_xyz)
    return np.asarray(np.linalg.norm(positions - origin, axis=1), dtype=np.float64)


def _trial_block(
    settings: UncertaintySettings,
    calibration: IdentificationResult,
    campaign: Campaign,
    problem: BatchProblem,
    test_q: Array,
    context: TrialContext,
    kernels: Backend,
    *,
    drop_base: bool,
    orientation: bool,
) -> CalibrationTrials:
    """The picklable trial block of one evaluation, its sources built from `context`."""
    b0 = calibration.model.layout.base_index
    # Model errors live in the measurement frame; R^T takes them into the base frame.
    output_rotation = rpy_to_matrix(calibration.estimate[b0 + 3 : b0 + 6]).T if drop_base else np.eye(N_AXES)
    return CalibrationTrials(
        problem=problem,
        x_hat=problem.scaled_deviation(calibration.estimate),
        joint_positions=campaign.joint_positions,
        points=campaign.points,
        test_joints=test_q,
        drop_base=drop_base,
        output_rotation=output_rotation,
        lambda_star=calibration.lambda_,
        sources=build_sources(settings, context),
        gauss_newton_iterations=settings.gauss_newton_iterations,
        solver=None
        if settings.jacobian == "exact"
        else _chord_solver(problem, calibration.estimate, campaign.joint_positions, kernels),
        reference_rotations=_calibrated_rotations(calibration, test_q, drop_base=drop_base) if orientation else None,
        test_predictor=_test_predictor(calibration, test_q, drop_base=drop_base, backend=kernels),
    )


def prepare(
    model: RobotModel,
    campaign: Campaign,
    test_q: Array,
    settings: UncertaintySettings,
    calibration: IdentificationResult | None,
    lambda_: str | float,
    frame: str,
    *,
    orientation: bool = False,
    backend: str = "numpy",
) -> Prepared:
    """Everything the trials of one evaluation need (see the module docstring).

    Raises
    ------
    ConfigError, InputError
        An unknown output frame, a lambda range without the calibration's lambda, pose
        counts that cannot identify the model, measurements without a position.
    """
    kernels = get_backend(backend)
    if frame not in OUTPUT_FRAMES:
        msg = f"output frame must be one of {', '.join(OUTPUT_FRAMES)}, got {frame!r}"
        raise ConfigError(msg)
    campaign = campaign.reorder_joints(model.joint_names)
    if calibration is None:
        calibration = identify(model, campaign, lambda_=lambda_)
    model = calibration.model  # its layout (a tool rotation when the data hold orientations)
    problem = BatchProblem.from_calibration(calibration)
    measurement = campaign.measurement
    lambda_range = _lambda_range(settings, calibration)
    min_poses, subset_size = _pose_counts(settings, campaign.n_poses, measurement.dimension, problem.estimated.size)
    distances = _tracker_distances(settings, campaign)
    drop_base = frame == "base" and campaign.frame == "tracker"
    frame_id = model.base_frame_id if frame == "base" or campaign.frame == "base" else campaign.frame_id
    adequacy = assess_model_adequacy(
        calibration, campaign.joint_positions, settings.tracker_noise, settings.encoder_noise, distances
    )
    field_estimate, field_draw = _model_error_field(settings, calibration, campaign, test_q, adequacy, distances)
    context = TrialContext(
        n_poses=campaign.n_poses,
        n_joints=model.n_joints,
        n_test=test_q.shape[0],
        measurement_dimension=measurement.dimension,
        distances=distances,
        model_errors=adequacy.draws,
        lambda_star=calibration.lambda_,
        lambda_range=lambda_range,
        min_poses=min_poses,
        subset_size=subset_size,
        rotation_std=np.asarray(measurement.rotation_std) if isinstance(measurement, PoseMeasurement) else None,
        test_effect_jacobian=test_effect_jacobian(calibration, test_q, settings),
        prismatic=model.prismatic if any(model.prismatic) else (),
        model_error_field=field_draw,
    )
    trials = _trial_block(
        settings, calibration, campaign, problem, test_q, context, kernels, drop_base=drop_base, orientation=orientation
    )
    return Prepared(
        trials=trials,
        calibration=calibration,
        campaign=campaign,
        problem=problem,
        test_joints=test_q,
        context=context,
        adequacy=adequacy,
        lambda_range=lambda_range,
        frame_id=frame_id,
        model_error_field=field_estimate,
    )


def prepare_calibration_trials(
    model: RobotModel,
    campaign: Campaign,
    test_joint_positions: Array,
    *,
    settings: UncertaintySettings | None = None,
    calibration: IdentificationResult | None = None,
    lambda_: str | float = "auto",
    frame: str = "measurement",
    backend: str = "numpy",
) -> CalibrationTrials:
    """The picklable trial function of :func:`evaluate_uncertainty`, for other drivers.

    ``trials(rng, n)`` returns (n, d n_test + k): the predicted measurement (x, y, z for a
    point) at every test configuration in the output frame, then the k estimated
    parameters. Run it with :func:`~robocal_uncertainty.montecarlo.engine.run_trials`
    (e.g. for a workspace map); the same seed gives the same trials as
    :func:`evaluate_uncertainty`.

    Parameters
    ----------
    model, campaign, test_joint_positions, settings, calibration, lambda_, frame
        As for :func:`evaluate_uncertainty`.
    backend : str
        Trial kernels (see :attr:`EvaluationSettings.backend`).
    """
    settings = settings or UncertaintySettings()
    test_q, _ = validate_inputs(model, test_joint_positions, 0.95, "auto")
    return prepare(model, campaign, test_q, settings, calibration, lambda_, frame, backend=backend).trials
