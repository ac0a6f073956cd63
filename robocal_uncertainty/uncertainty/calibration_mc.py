"""Monte Carlo uncertainty of a calibrated arm's tool pose (JCGM 101).

A trial perturbs the campaign according to the enabled sources, re-identifies the
parameters, and evaluates the tool pose at every requested joint configuration: the tool
point and, unless switched off, the tool orientation.

Orientation (3 extra columns per test configuration): a trial stores the rotation vector
``log(R_trial R_cal^T)`` [rad] of its tool rotation relative to the calibrated one, i.e. a
rotation about the **fixed x, y, z axes of the output frame** (the ROS convention of the
orientation block of ``geometry_msgs/PoseWithCovariance``). After the run the mean
orientation is the chordal L2 mean (SVD projection of the mean rotation matrix) and the
reported deviations are re-expressed about it, ``log(R_trial R_mean^T)``.

Rotation components the campaign cannot determine are found by estimability, not from the
spread of the trials: a parameter the measurements cannot identify (e.g. the joint-6 offset
when only points on joint 6's axis are measured) is held at its nominal value in every trial,
so the trials show *no* spread along its direction although the data say nothing about it.
A rotation about a unit axis ``u`` is determined when ``u^T J_w dp = 0`` for every parameter
change ``dp`` the measurements cannot see (the null space of the candidates' measurement
Jacobian on the structural probe poses of
:func:`~robocal_uncertainty.core.observability.structural_observability`); ``J_w`` is the
angular Jacobian of the tool at the test configuration.
Trials run in blocks with independent seeded streams (see
:mod:`robocal_uncertainty.montecarlo.engine`), so the result is the same whatever the
chunk size or the number of workers.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult, identify
from robocal_uncertainty.core.kinematics import (
    forward_points,
    forward_points_and_jacobian,
    forward_poses,
    forward_poses_and_jacobian,
)
from robocal_uncertainty.core.measurement import POSITION_AXES, joint_columns, row_weights, stack_jacobian
from robocal_uncertainty.core.pose_measurement import PoseMeasurement
from robocal_uncertainty.core.robot_model import RobotModel, rpy_to_matrix
from robocal_uncertainty.core.rotation import chordal_mean, quaternion_from_matrix, rotation_exp, rotation_log
from robocal_uncertainty.core.session import effect_jacobian
from robocal_uncertainty.errors import ConfigError, InputError
from robocal_uncertainty.kernels import Backend, BackendInfo, ToolPredictor, get_backend, resolve_backend
from robocal_uncertainty.montecarlo.distributions import Distribution, IndependentNormal
from robocal_uncertainty.montecarlo.engine import AdaptiveReport, AdaptiveSettings, TrialsResult, run_trials
from robocal_uncertainty.montecarlo.gum import GumResult, propagate_gum
from robocal_uncertainty.montecarlo.region import EllipsoidalRegion, coverage_region
from robocal_uncertainty.montecarlo.summary import OutputSummary, Summary, coverage_window, summarize
from robocal_uncertainty.montecarlo.validation import validate_gum
from robocal_uncertainty.uncertainty.model_adequacy import (
    ModelAdequacy,
    assess_model_adequacy,
    pose_noise_covariances,
)
from robocal_uncertainty.uncertainty.model_error_draws import (
    FieldEstimate,
    FieldNormal,
    estimate_field,
    standardised_innovations,
)
from robocal_uncertainty.uncertainty.reidentification import (
    BatchProblem,
    ChordSolver,
    reidentify_batch,
)
from robocal_uncertainty.uncertainty.sources import (
    Source,
    TrialBatch,
    TrialContext,
    UncertaintySettings,
    build_sources,
    source_rng,
    stream_id,
)
from robocal_uncertainty.uncertainty.statement_check import gum_disagreements, too_few_trials_note

__all__ = [
    "OUTPUT_FRAMES",
    "ROTATION_AXES",
    "CalibrationTrials",
    "CalibrationUncertainty",
    "EvaluationSettings",
    "GumPose",
    "OrientationUncertainty",
    "PoseUncertainty",
    "evaluate_uncertainty",
    "first_order_standard_uncertainty",
    "prepare_calibration_trials",
]

Array = NDArray[np.float64]
_SUB_BATCH = 256
_TEST_ELEMENTS = 16_384
"""Trials x test configurations evaluated at once after the re-identification (memory bound)."""
# The outputs at the test configurations are tool positions (x, y, z), whatever is measured.
_N_AXES = len(POSITION_AXES)
OutputFrame = Literal["measurement", "base"]
OUTPUT_FRAMES: tuple[str, ...] = ("measurement", "base")
ROTATION_AXES: tuple[str, str, str] = ("rx", "ry", "rz")
"""Rotation deviations about the fixed x, y, z axes of the output frame."""
UNDETERMINED_VARIANCE = 1.0e6
"""Variance [rad^2] published for an undetermined rotation direction (ROS "unknown")."""
_ESTIMABLE_RTOL = 1e-6
_NULL_RTOL = 1e-7
"""``measurement``: the frame of the campaign's points (the tracker's, or the base when the
campaign is in the base frame); ``base``: the robot base frame."""


@dataclass(frozen=True)
class GumPose:
    """First-order GUM propagation for one test configuration (where applicable).

    Attributes
    ----------
    applicable : bool
        False when a non-smooth source (lambda, n_poses, pose_choice) is enabled:
        the law of propagation has no derivative to offer for those.
    estimate : ndarray, shape (3,) [m]
    covariance : ndarray, shape (3, 3) [m^2]
    standard_uncertainty : ndarray, shape (3,) [m]
    coverage_factor : float
        From the normal distribution at the coverage probability.
    expanded_uncertainty : ndarray, shape (3,) [m]
    validated : tuple of bool, length 3
        JCGM 101 §8 check against the Monte Carlo symmetric interval, per axis.
    d_low, d_high : ndarray, shape (3,) [m]
        Endpoint differences of §8.
    delta : ndarray, shape (3,) [m]
        Numerical tolerance used for the check.
    """

    applicable: bool
    estimate: Array
    covariance: Array
    standard_uncertainty: Array
    coverage_factor: float
    expanded_uncertainty: Array
    validated: tuple[bool, ...]
    d_low: Array
    d_high: Array
    delta: Array


@dataclass(frozen=True)
class PoseUncertainty:
    """Uncertainty statement of the tool position at one joint configuration.

    Attributes
    ----------
    joint_positions : ndarray, shape (n_joints,) [rad]
    mean : ndarray, shape (3,) [m]
        Mean of the Monte Carlo tool positions, in the result's output frame
        (:attr:`CalibrationUncertainty.frame_id`).
    covariance : ndarray, shape (3, 3) [m^2]
    axes : tuple of OutputSummary, length 3
        Per-axis x, y, z summaries (standard and expanded uncertainty, coverage factor,
        probabilistically symmetric and shortest intervals, histogram) [m].
    region : EllipsoidalRegion or None
        JCGM 102 hyper-ellipsoidal 3-D coverage region (None if degenerate).
    gum : GumPose
    orientation : OrientationUncertainty or None
        The tool orientation; None when the evaluation was asked for positions only.
    """

    joint_positions: Array
    mean: Array
    covariance: Array
    axes: tuple[OutputSummary, ...]
    region: EllipsoidalRegion | None
    gum: GumPose
    orientation: OrientationUncertainty | None = None

    @property
    def pose_covariance(self) -> Array | None:
        """6x6 covariance of (x, y, z, rx, ry, rz) [m^2, m rad, rad^2], or None without orientation."""
        return None if self.orientation is None else self.orientation.pose_covariance


@dataclass(frozen=True)
class OrientationUncertainty:
    """Uncertainty statement of the tool orientation at one joint configuration.

    Deviations are rotation vectors about the fixed x, y, z axes of the output frame
    (``R_trial = exp([delta]x) R_mean``), the ROS convention of
    ``geometry_msgs/PoseWithCovariance``.

    Attributes
    ----------
    mean_rotation : ndarray, shape (3, 3)
        Chordal L2 mean of the trials' tool rotations, ``output_R_tool``.
    mean_quaternion : ndarray, shape (4,)
        The same as a unit quaternion (x, y, z, w), w >= 0.
    calibrated_rotation : ndarray, shape (3, 3)
        Tool rotation of the calibrated model (the GUM estimate).
    covariance : ndarray, shape (3, 3) [rad^2]
        Monte Carlo covariance of the deviations from the mean (ddof=1).
    axes : tuple of OutputSummary, length 3
        Per-axis (rx, ry, rz) summaries of the deviations from the mean [rad]: standard and
        expanded uncertainty, coverage intervals, histogram.
    pose_covariance : ndarray, shape (6, 6) [m^2, m rad, rad^2]
        Covariance of (x, y, z, rx, ry, rz): position, rotation and their correlation. Its
        position block is :attr:`PoseUncertainty.covariance`.
    determined : tuple of bool, length 3
        Per axis: whether the campaign determines the rotation about it. An undetermined
        axis has no uncertainty statement (its Monte Carlo numbers are not reported).
    undetermined_directions : ndarray, shape (n_undetermined, 3)
        Unit axes (output frame) of the rotations the data cannot determine; empty if none.
    gum : GumPose
        First-order propagation of the smooth sources through the angular Jacobian,
        about :attr:`calibrated_rotation` [rad], validated against the Monte Carlo
        deviations from the same rotation.
    """

    mean_rotation: Array
    mean_quaternion: Array
    calibrated_rotation: Array
    covariance: Array
    axes: tuple[OutputSummary, ...]
    pose_covariance: Array
    determined: tuple[bool, ...]
    undetermined_directions: Array
    gum: GumPose

    @property
    def fully_determined(self) -> bool:
        """True when every rotation axis is determined."""
        return all(self.determined)

    def ros_covariance(
        self, position_covariance: Array, *, undetermined_variance: float = UNDETERMINED_VARIANCE
    ) -> Array:
        """6x6 covariance for ``geometry_msgs/PoseWithCovariance`` (row-major x, y, z, rx, ry, rz).

        The determined part of the Monte Carlo covariance is kept; along each undetermined
        direction ``u`` the rotation gets `undetermined_variance` [rad^2] (``+ s u u^T``) and no
        correlation, so only the components that overlap an undetermined direction are huge.

        Parameters
        ----------
        position_covariance : ndarray, shape (3, 3) [m^2]
        undetermined_variance : float [rad^2]

        Returns
        -------
        ndarray, shape (6, 6) [m^2, m rad, rad^2]
        """
        out = np.array(self.pose_covariance, dtype=np.float64, copy=True)
        out[:3, :3] = position_covariance
        u = np.asarray(self.undetermined_directions, dtype=np.float64).reshape(-1, 3)
        if u.shape[0] == 3:
            # No rotation determined: exactly the stated variance, uncorrelated (u^T u is the
            # identity only to rounding, which left 1e-10 rad^2 cross terms and 1e6 + 2e-10).
            out[3:, :] = 0.0
            out[:, 3:] = 0.0
            out[3:, 3:] = undetermined_variance * np.eye(3)
        elif u.shape[0]:
            proj = np.eye(6)
            proj[3:, 3:] -= u.T @ u
            out = proj @ out @ proj.T
            out[3:, 3:] += undetermined_variance * (u.T @ u)
        return out


@dataclass(frozen=True, eq=False)
class CalibrationUncertainty:
    """Result of :func:`evaluate_uncertainty`.

    Attributes
    ----------
    poses : tuple of PoseUncertainty
        One per test configuration.
    parameter_names : tuple of str
        Names of the estimated parameters.
    parameters : tuple of OutputSummary
        Monte Carlo distribution of each estimated parameter [m or rad].
    calibration : IdentificationResult
        The calibration the uncertainty is about.
    settings : UncertaintySettings
    coverage_probability : float
    n_trials : int
    seed : int
    block_size : int
    adaptive : AdaptiveReport or None
    samples : ndarray, shape (n_trials, 3 n_test + k)
        Positions (output frame) then parameters, per trial.
    rotation_samples : ndarray, shape (n_trials, 3 n_test) [rad], or None
        With orientation: per trial and test configuration, the rotation deviation
        ``log(R_trial R_calibrated^T)`` about the output frame's fixed axes.
    lambda_star : float
        Lambda of the calibration (scaled units).
    lambda_range : (float, float) or None
        Range used by the lambda source.
    frame : {"measurement", "base"}
        Output frame of every position.
    frame_id : str
        Its TF name (the campaign's frame_id, or the model's base frame).
    model_adequacy : ModelAdequacy
        Residuals against the stated noise; the residual source draws what is left over.
    warnings : tuple of str
    not_converged : tuple of str
        Why the run is no statement although it ran (its spread disagrees with its own GUM
        statement: :func:`~robocal_uncertainty.uncertainty.statement_check.gum_disagreements`);
        empty for a statement.
    model_error_field : FieldEstimate or None
        The model-error field estimated for the residual source, drawn when it is
        :attr:`~FieldEstimate.identified` (else the independent model error is drawn); None: no
        model error, or ``model_error="independent"``.
    """

    poses: tuple[PoseUncertainty, ...]
    parameter_names: tuple[str, ...]
    parameters: tuple[OutputSummary, ...]
    calibration: IdentificationResult
    settings: UncertaintySettings
    coverage_probability: float
    n_trials: int
    seed: int
    block_size: int
    adaptive: AdaptiveReport | None
    samples: Array
    lambda_star: float
    lambda_range: tuple[float, float] | None
    frame: OutputFrame
    frame_id: str
    model_adequacy: ModelAdequacy
    warnings: tuple[str, ...] = field(default=())
    rotation_samples: Array | None = None
    not_converged: tuple[str, ...] = field(default=())
    backend: BackendInfo | None = None
    model_error_field: FieldEstimate | None = None

    @property
    def converged(self) -> bool:
        """False when a check failed (:attr:`not_converged`, or the adaptive procedure's); else True.

        A fixed number of trials runs no convergence test: see :attr:`convergence_tested`.
        """
        if self.not_converged:
            return False
        return True if self.adaptive is None else self.adaptive.converged

    @property
    def convergence_tested(self) -> bool:
        """True when a convergence test ran (the adaptive JCGM 101 §7.9 procedure)."""
        return self.adaptive is not None


@dataclass(frozen=True, eq=False)
class CalibrationTrials:
    """Picklable trial block: perturb, re-identify, evaluate at the test configurations.

    Every source draws its values for the block from its own stream (see
    :func:`~robocal_uncertainty.uncertainty.sources.source_rng`); the block's values are
    then applied and re-identified in fixed sub-batches.
    """

    problem: BatchProblem
    x_hat: Array
    joint_positions: Array
    points: Array
    test_joints: Array
    drop_base: bool
    output_rotation: Array
    lambda_star: float
    sources: tuple[Source, ...]
    gauss_newton_iterations: int
    solver: ChordSolver | None = None
    reference_rotations: Array | None = None
    test_predictor: ToolPredictor | None = None

    @property
    def orientation(self) -> bool:
        """Whether trial rows end with the rotation deviations of every test configuration."""
        return self.reference_rotations is not None

    @property
    def n_outputs(self) -> int:
        """Columns of a trial row: x, y, z per test configuration, the parameters, then (with
        orientation) rx, ry, rz per test configuration [rad], ``log(R_trial R_ref^T)``."""
        n_rot = _N_AXES * self.test_joints.shape[0] if self.orientation else 0
        return _N_AXES * self.test_joints.shape[0] + self.x_hat.size + n_rot

    def __call__(self, rng: np.random.Generator, n: int) -> Array:
        """Model values of n trials, shape (n, d n_test + k)."""
        # Draw every input of the block first, each source from its own stream, so a
        # source's values depend on the block and the source alone; the sub-batches
        # below only bound memory.
        values = [source.draw(source_rng(rng, stream_id(source.name)), n) for source in self.sources]
        measurement = self.problem.measurement
        dim = _N_AXES
        n_test = self.test_joints.shape[0]
        k = self.x_hat.size
        out = np.empty((n, self.n_outputs))
        params = np.empty((n, self.problem.start.size))
        test_deviations: list[Array] = []
        predictions: list[Array] = []
        # A fixed sub-batch: BLAS rounding may depend on the number of rows, so the split of
        # a block must never depend on a user setting.
        for lo_i in range(0, n, _SUB_BATCH):
            sl = slice(lo_i, min(n, lo_i + _SUB_BATCH))
            t = sl.stop - sl.start
            batch = TrialBatch(n_trials=t)
            for source, value in zip(self.sources, values):
                source.apply(value[sl], batch)
            # Every source perturbs the measured points with zero-mean errors, so the trials
            # stay centred on the calibration.
            # Source deviations are in the residual coordinates of the measurement type.
            pts = (
                measurement.perturb(self.points[None], batch.points)
                if batch.points is not None
                else np.broadcast_to(self.points, (t, *self.points.shape))
            )
            q = self.joint_positions[None] + batch.joints if batch.joints is not None else self.joint_positions
            lambdas = batch.lambdas if batch.lambdas is not None else np.full(t, self.lambda_star)
            if self.solver is not None:
                x, _ = self.solver.solve(q, pts, batch.weights, lambdas, self.x_hat)
            else:
                x, _ = reidentify_batch(
                    self.problem,
                    q,
                    np.ascontiguousarray(pts),
                    batch.weights,
                    lambdas,
                    self.x_hat,
                    iterations=self.gauss_newton_iterations,
                )
            params[sl] = self.problem.parameters(x)
            if batch.test_joints is not None:
                test_deviations.append(batch.test_joints)
            if batch.predictions is not None:
                predictions.append(batch.predictions)
        out[:, dim * n_test : dim * n_test + k] = params[:, self.problem.estimated]
        if self.drop_base:
            # Positions in the robot base frame: the identified base does not enter.
            b0 = self.problem.layout.base_index
            params[:, b0 : b0 + 6] = 0.0
        # The test configurations of the whole block at once, in slices of a bounded size:
        # every operation there is per trial (elementwise, or a 3x3 product per trial), so
        # the values do not depend on the slices, and the per-call overhead is paid once per
        # slice instead of once per sub-batch.
        qt_dev = np.concatenate(test_deviations) if test_deviations else None
        pred = np.concatenate(predictions) if predictions else None
        step = max(_SUB_BATCH, _TEST_ELEMENTS // n_test)
        for lo_i in range(0, n, step):
            sl = slice(lo_i, min(n, lo_i + step))
            t = sl.stop - sl.start
            qt = self.test_joints[None] + qt_dev[sl] if qt_dev is not None else self.test_joints
            if self.reference_rotations is None:
                if self.test_predictor is not None:
                    pos = self.test_predictor(params[sl], qt)
                else:
                    pos = forward_points(self.problem.layout, params[sl], qt)
            else:
                if self.test_predictor is not None:
                    values = self.test_predictor.poses(params[sl], qt)
                    pos, rot = values[..., :dim], values[..., dim:].reshape(*values.shape[:-1], dim, dim)
                else:
                    pos, rot = forward_poses(self.problem.layout, params[sl], qt)
                # Deviation about the fixed axes of the output frame: exp([d]x) = R R_ref^T.
                dev = rotation_log(rot @ np.swapaxes(self.reference_rotations, -1, -2))
                if pred is not None and pred.shape[-1] == 2 * dim:
                    # 6-DOF model errors: their rotation part (small) moves the orientation.
                    dev = dev + pred[sl, :, dim:] @ self.output_rotation.T
                out[sl, dim * n_test + k :] = dev.reshape(t, dim * n_test)
            if pred is not None:
                # Row-vector form of R_out e: model errors live in the measurement frame
                # (their position part for 6-DOF measurements).
                pos = pos + pred[sl, :, :dim] @ self.output_rotation.T
            out[sl, : dim * n_test] = pos.reshape(t, dim * n_test)
        return out


def _validate_inputs(
    model: RobotModel, test_joint_positions: object, coverage: float, trials: object
) -> tuple[Array, int | None]:
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
class _Prepared:
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


def _field_sensitivities(prep: _Prepared, *, angular: bool = False) -> tuple[dict[str, Array], Array]:
    """First-order sensitivity of the outputs to each additive batch field, and y = f(E[X]).

    Outputs are the tool position (x, y, z) at every test configuration or, with `angular`,
    the rotation deviation (rx, ry, rz) about the calibrated tool rotation (then y = 0),
    through the angular Jacobian of the tool; the identification is linearised at the
    calibration (x = H b). Model errors (the predictions field) move positions only.
    """
    problem = prep.problem
    layout = problem.layout
    est = problem.estimated
    calibration = prep.calibration
    trials = prep.trials
    q = prep.campaign.joint_positions
    measurement = problem.measurement
    n_poses = trials.points.shape[0]
    dim = _N_AXES
    n_test, n_joints = prep.test_joints.shape
    _, jac = measurement.predict_and_jacobian(layout, calibration.estimate, q)
    weights = row_weights(measurement, n_poses)
    # stack_jacobian already whitens the rows (W A): the weights must not enter twice.
    a_mat = stack_jacobian(measurement, jac, est) / problem.scale
    lam = calibration.lambda_
    # x = H b: the linearised (weighted) Tikhonov solution for the stacked residual b,
    # H = (A^T W^2 A + lam^2 P)^-1 A^T W^2.
    h = np.linalg.solve(a_mat.T @ a_mat + lam**2 * np.diag(problem.penalty_mask), a_mat.T)
    if weights is not None:
        h = h * weights[None, :]
    p_out = calibration.estimate.copy()
    b0 = layout.base_index
    if trials.drop_base:
        p_out[b0 : b0 + 6] = 0.0
    if angular:
        _, _, g6 = forward_poses_and_jacobian(layout, p_out, prep.test_joints)
        gy = np.ascontiguousarray(g6[:, 3:, :])
        y = np.zeros((n_test, dim))
    else:
        y, gy = forward_points_and_jacobian(layout, p_out, prep.test_joints)
    if trials.drop_base:
        gy[:, :, b0 : b0 + 6] = 0.0
    n_out = dim * n_test
    s_points = gy[:, :, est].reshape(n_out, est.size) @ (h / problem.scale[:, None])
    theta_cols = joint_columns(layout)
    # A reading error dq shifts the prediction by J_q dq: for the fit, the measurement moved by -J_q dq.
    m_dim = measurement.dimension
    s_joints = -np.einsum("opc,pcj->opj", s_points.reshape(n_out, n_poses, m_dim), jac[..., theta_cols])
    s_test = np.zeros((n_test, dim, n_test, n_joints))
    # Model errors (the residual source) have the measurement's components: positions move
    # positions and, for 6-DOF measurements, rotations move rotations.
    s_pred = np.zeros((n_test, dim, n_test, m_dim))
    for i in range(n_test):
        s_test[i, :, i, :] = gy[i][:, theta_cols]
        if not angular:
            s_pred[i, :, i, :dim] = trials.output_rotation
        elif m_dim == 2 * dim:
            s_pred[i, :, i, dim:] = trials.output_rotation
    fields = {
        "points": s_points,
        "joints": s_joints.reshape(n_out, n_poses * n_joints),
        "test_joints": s_test.reshape(n_out, n_test * n_joints),
        "predictions": s_pred.reshape(n_out, n_test * m_dim),
    }
    return fields, y.reshape(n_out)


def _gum(prep: _Prepared, coverage: float, *, angular: bool = False) -> GumResult | None:
    """GUM (JCGM 100) propagation of the smooth sources' distributions; None if there is none."""
    smooth = [src for src in prep.trials.sources if src.smooth and src.distribution is not None]
    if not smooth:
        return None
    fields, y0 = _field_sensitivities(prep, angular=angular)
    inputs: dict[str, Distribution] = {}
    columns = []
    for src in smooth:
        block = np.hstack([fields[name] for name, _ in src.segments])
        if isinstance(src.distribution, FieldNormal):
            # The field's draws are F z with z standard normal: propagate z through S F, the
            # same factor the Monte Carlo draws with, never the dense covariance of the draws.
            inputs[src.name] = IndependentNormal(np.ones(src.distribution.size))
            block = src.distribution.whitened_sensitivities(block)
        elif src.distribution is not None:
            inputs[src.name] = src.distribution
        columns.append(block)
    sensitivities = np.hstack(columns)

    def estimate(x: Array) -> Array:
        # Zero-mean deviations: the GUM estimate is the calibrated model's prediction.
        return np.broadcast_to(y0, (x.shape[0], y0.size))

    return propagate_gum(estimate, inputs, coverage=coverage, sensitivities=sensitivities)


def first_order_standard_uncertainty(
    model: RobotModel,
    campaign: Campaign,
    test_q: Array,
    settings: UncertaintySettings,
    calibration: IdentificationResult,
    frame: str = "measurement",
) -> Array | None:
    """GUM (first-order) standard uncertainty of the tool position at `test_q`, as `evaluate` states it.

    The same propagation as the ``gum`` part of :func:`evaluate_uncertainty`'s statement, for
    callers that run their own trials (the workspace map) and check them against it.

    Parameters
    ----------
    model : RobotModel
        Nominal model.
    campaign : Campaign
        Calibration data (joint readings [rad], points [m]).
    test_q : ndarray, shape (n, n_joints) [rad]
        Configurations.
    settings : UncertaintySettings
        Sources and their models.
    calibration : IdentificationResult
        The calibration of `campaign`.
    frame : {"measurement", "base"}
        Output frame.

    Returns
    -------
    ndarray, shape (n, 3) [m], or None
        Per configuration and axis; None when no source is smooth (nothing to propagate).
    """
    prep = _prepare(
        model, campaign, np.atleast_2d(np.asarray(test_q, dtype=np.float64)), settings, calibration, "auto", frame
    )
    gum = _gum(prep, 0.95)
    if gum is None:
        return None
    variance = np.clip(np.diag(np.asarray(gum.covariance)), 0.0, None)
    return np.asarray(np.sqrt(variance).reshape(-1, _N_AXES), dtype=np.float64)


def _regularisation_bias(prep: _Prepared) -> Array:
    """First-order Tikhonov shrinkage of the tool position at each test configuration [m].

    For b = A x + e the regularised estimate has E[x_hat] - x = -(A^T A + lam^2 P)^-1 lam^2 P x:
    a bias the Monte Carlo cannot see, because every trial is centred on the calibration.
    Evaluated with x_hat in place of the unknown x, it is a lower estimate (x_hat is itself
    shrunk). Shape (n_test, 3), in the output frame.
    """
    problem = prep.problem
    calibration = prep.calibration
    lam = calibration.lambda_
    n_test = prep.test_joints.shape[0]
    if lam <= 0.0 or not problem.penalty_mask.any():
        return np.zeros((n_test, _N_AXES))
    layout = problem.layout
    est = problem.estimated
    measurement = problem.measurement
    _, jac = measurement.predict_and_jacobian(layout, calibration.estimate, prep.campaign.joint_positions)
    a_mat = stack_jacobian(measurement, jac, est) / problem.scale
    penalty = lam**2 * problem.penalty_mask
    x_hat = prep.trials.x_hat
    shift = -np.linalg.solve(a_mat.T @ a_mat + np.diag(penalty), penalty * x_hat) / problem.scale
    p_out = calibration.estimate.copy()
    b0 = layout.base_index
    if prep.trials.drop_base:
        p_out[b0 : b0 + 6] = 0.0
    _, gy = forward_points_and_jacobian(layout, p_out, prep.test_joints)
    if prep.trials.drop_base:
        gy[:, :, b0 : b0 + 6] = 0.0
    return np.asarray(gy[:, :, est] @ shift, dtype=np.float64)


# A bias beyond half the standard uncertainty lowers a 95 % interval's coverage below ~92 %.
_BIAS_WARN_RATIO = 0.5


def _gum_poses(
    prep: _Prepared, summary: Summary, coverage: float, n_dig: int, *, angular: bool = False
) -> list[GumPose]:
    """Per test configuration: the GUM statement and its JCGM 101 §8 validation.

    With `angular`, `summary` holds the rotation deviations about the calibrated rotation.
    """
    dim = _N_AXES
    n_test = prep.test_joints.shape[0]
    n_out = dim * n_test
    applicable = all(src.smooth for src in prep.trials.sources)
    gum = _gum(prep, coverage, angular=angular)
    k_norm = float(stats.norm.ppf(0.5 + coverage / 2.0))
    if gum is None:
        _, y_all = _field_sensitivities(prep, angular=angular)
        cov_all = np.zeros((n_out, n_out))
    else:
        y_all = np.array([o.estimate for o in gum.outputs])
        cov_all = np.asarray(gum.covariance)
    positions = Summary(
        outputs=summary.outputs[:n_out],
        covariance=summary.covariance[:n_out, :n_out],
        coverage_probability=summary.coverage_probability,
        n_trials=summary.n_trials,
    )
    out = []
    for i in range(n_test):
        cols = slice(dim * i, dim * (i + 1))
        y = y_all[cols]
        cov_y = cov_all[cols, cols]
        u = np.sqrt(np.clip(np.diag(cov_y), 0.0, None))
        big_u = k_norm * u
        if gum is None:
            mc = [a.probabilistically_symmetric for a in positions.outputs[cols]]
            d_low = np.array([abs(y[j] - mc[j].low) for j in range(dim)])
            d_high = np.array([abs(y[j] - mc[j].high) for j in range(dim)])
            delta = np.zeros(dim)
            validated: tuple[bool, ...] = (False,) * dim
        else:
            checks = [validate_gum(gum, positions, output=dim * i + j, n_dig=n_dig) for j in range(dim)]
            d_low = np.array([c.d_low for c in checks])
            d_high = np.array([c.d_high for c in checks])
            delta = np.array([c.delta for c in checks])
            validated = tuple(bool(applicable and c.validated) for c in checks)
        out.append(
            GumPose(
                applicable=applicable,
                estimate=y,
                covariance=cov_y,
                standard_uncertainty=u,
                coverage_factor=k_norm,
                expanded_uncertainty=big_u,
                validated=validated,
                d_low=d_low,
                d_high=d_high,
                delta=delta,
            )
        )
    return out


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


def undetermined_rotations(prep: _Prepared) -> list[Array]:
    """Per test configuration, the unit axes (output frame) of rotations the data cannot fix.

    See the module docstring: the null space ``N`` of the candidates' whitened measurement
    Jacobian on the structural probe poses (columns normalised, singular values below
    1e-7 of the largest) holds the parameter changes the measurements cannot see; the
    directions ``u`` with ``u^T J_w N != 0`` (left singular vectors of ``J_w N`` above 1e-6
    of the norm of ``J_w``) are undetermined.

    Returns
    -------
    list of ndarray, each shape (n_undetermined, 3)
    """
    calibration = prep.calibration
    model = calibration.model
    layout = model.layout
    measurement = calibration.measurement
    cand = np.flatnonzero(calibration.candidates)
    if prep.trials.drop_base:
        # In the robot base frame the identified base is dropped: that frame is defined by the
        # nominal joint-1 parameters the base absorbs (joint1.alpha = base.roll, ...), so those
        # combinations are a choice of frame, not unseen errors of the tool's orientation.
        b0 = layout.base_index
        cand = cand[(cand < b0) | (cand >= b0 + 6)]
    rng = np.random.default_rng(20231101)  # the probe poses of structural_observability
    lo, hi = model.joint_limits[:, 0], model.joint_limits[:, 1]
    probe = rng.uniform(lo, hi, size=(200, model.n_joints))
    # Linearised at the nominal parameters, where identify decided what to estimate: a
    # parameter it held at nominal there (e.g. joint6.a for points on joint 6's axis) has an
    # unseen error even though at the estimate its column is no longer exactly dependent. The
    # rotation Jacobian below is taken at the same point, so that exact dependencies (joint6.theta
    # and tool.rz) cancel there as they do in the measurements; the directions found are then
    # carried with the tool (body-fixed, e.g. "about the tool axis") to the calibrated rotation.
    _, jac = measurement.predict_and_jacobian(layout, calibration.nominal, probe)
    a_mat = stack_jacobian(measurement, jac)[:, cand]
    norms = np.linalg.norm(a_mat, axis=0)
    scale = np.where(norms > 1e-9 * norms.max(), norms, 1.0)
    a_mat = np.where(norms > 1e-9 * norms.max(), a_mat / scale, 0.0)
    # With more rows than columns (always: 200 probe poses) the reduced SVD's V is the full
    # one, without the 600 x 600 left factor (ten times the work).
    _, sv, vt = np.linalg.svd(a_mat, full_matrices=a_mat.shape[0] < a_mat.shape[1])
    rank = int(np.sum(sv > _NULL_RTOL * sv[0]))
    null = vt[rank:].T  # (n_cand, n_null), normalised parameter coordinates
    p_out = calibration.nominal.copy()
    p_cal = calibration.estimate.copy()
    b0 = layout.base_index
    if prep.trials.drop_base:
        p_out[b0 : b0 + 6] = 0.0
        p_cal[b0 : b0 + 6] = 0.0
    _, r_nominal, g6 = forward_poses_and_jacobian(layout, p_out, prep.test_joints)
    _, r_calibrated = forward_poses(layout, p_cal, prep.test_joints)
    transport = r_calibrated @ np.swapaxes(r_nominal, -1, -2)
    j_w = g6[:, 3:, :]
    if prep.trials.drop_base:
        j_w[:, :, b0 : b0 + 6] = 0.0
    j_w = j_w[:, :, cand] / scale
    out = []
    for i in range(prep.test_joints.shape[0]):
        if null.shape[1] == 0:
            out.append(np.zeros((0, 3)))
            continue
        m_mat = j_w[i] @ null
        u, sm, _ = np.linalg.svd(m_mat, full_matrices=False)
        ref = max(float(np.linalg.norm(j_w[i], 2)), np.finfo(float).tiny)
        out.append(u[:, sm > _ESTIMABLE_RTOL * ref].T @ transport[i].T)
    return out


def _orientation_uncertainty(
    prep: _Prepared,
    samples: Array,
    pos_summaries: Summary,
    coverage: float,
    n_dig: int,
) -> list[OrientationUncertainty]:
    """Orientation statements from the rotation columns (deviations from the calibrated rotations)."""
    dim = _N_AXES
    n_test = prep.test_joints.shape[0]
    k = prep.trials.x_hat.size
    raw = samples[:, dim * n_test + k :]
    ref = prep.trials.reference_rotations
    assert ref is not None
    # The GUM is about the calibrated rotation: validate it against deviations from it.
    raw_summary = summarize(raw, coverage)
    gums = _gum_poses(prep, raw_summary, coverage, n_dig, angular=True)
    undetermined = undetermined_rotations(prep)
    out = []
    for i in range(n_test):
        dev_ref = raw[:, dim * i : dim * (i + 1)]
        # Chordal mean: R_mean = proj(mean_t exp(d_t)) R_ref; deviations about it.
        rot_ref = rotation_exp(dev_ref)
        mean_dev = chordal_mean(rot_ref)
        mean_rot = mean_dev @ ref[i]
        dev = rotation_log(rot_ref @ mean_dev.T)
        rot_summary = summarize(dev, coverage)
        pos = samples[:, dim * i : dim * (i + 1)]
        pose_cov = np.cov(np.hstack((pos, dev)), rowvar=False, ddof=1)
        pose_cov[:3, :3] = pos_summaries.covariance[dim * i : dim * (i + 1), dim * i : dim * (i + 1)]
        pose_cov[3:, 3:] = rot_summary.covariance
        dirs = undetermined[i]
        determined = tuple(bool(np.linalg.norm(dirs[:, a]) <= _ESTIMABLE_RTOL) for a in range(dim))
        out.append(
            OrientationUncertainty(
                mean_rotation=mean_rot,
                mean_quaternion=quaternion_from_matrix(mean_rot),
                calibrated_rotation=ref[i],
                covariance=rot_summary.covariance,
                axes=rot_summary.outputs,
                pose_covariance=pose_cov,
                determined=determined,
                undetermined_directions=dirs,
                gum=gums[i],
            )
        )
    return out


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


def _prepare(
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
) -> _Prepared:
    kernels = get_backend(backend)
    if frame not in OUTPUT_FRAMES:
        msg = f"output frame must be one of {', '.join(OUTPUT_FRAMES)}, got {frame!r}"
        raise ConfigError(msg)
    campaign = campaign.reorder_joints(model.joint_names)
    if calibration is None:
        calibration = identify(model, campaign, lambda_=lambda_)
    model = calibration.model  # its layout (a tool rotation when the data hold orientations)
    layout = model.layout
    problem = BatchProblem.from_calibration(calibration)
    x_hat = problem.scaled_deviation(calibration.estimate)
    measurement = campaign.measurement
    n_poses = campaign.n_poses
    dim = measurement.dimension
    k = problem.estimated.size

    lam_star = calibration.lambda_
    lambda_range: tuple[float, float] | None = None
    if "lambda" in settings.sources:
        if settings.lambda_range is None:
            lambda_range = (lam_star / 5.0, lam_star * 5.0)
        else:
            lambda_range = (float(settings.lambda_range[0]), float(settings.lambda_range[1]))
            if not lambda_range[0] <= lam_star <= lambda_range[1]:
                msg = (
                    f"lambda range [{lambda_range[0]:.4g}, {lambda_range[1]:.4g}] excludes the "
                    f"calibration's optimum lambda {lam_star:.4g} ({calibration.lambda_method})"
                )
                raise ConfigError(msg)
    min_identifiable = math.ceil(k / dim)
    min_poses = settings.min_poses or max(math.ceil(40 / dim), math.ceil(1.5 * k / dim))
    subset_size = settings.subset_size or round(33 / 53 * n_poses)
    for name, value in (("min_poses", min_poses), ("subset_size", subset_size)):
        if "n_poses" in settings.sources or "pose_choice" in settings.sources:
            if value < min_identifiable or value > n_poses:
                msg = (
                    f"{name} = {value} must lie between {min_identifiable} (identifiable "
                    f"parameters / {dim}) and the campaign's {n_poses} poses"
                )
                raise ConfigError(msg)

    b0 = layout.base_index
    positions = measurement.positions(campaign.points)
    if positions is None:
        msg = f"{measurement.quantity} measurements hold no position: no tracker distance for the noise model"
        raise InputError(msg)
    origin = np.zeros(3) if campaign.frame == "tracker" else np.asarray(settings.tracker_xyz)
    distances = np.linalg.norm(positions - origin, axis=1)
    drop_base = frame == "base" and campaign.frame == "tracker"
    # Model errors live in the measurement frame; R^T takes them into the base frame.
    output_rotation = rpy_to_matrix(calibration.estimate[b0 + 3 : b0 + 6]).T if drop_base else np.eye(_N_AXES)
    frame_id = model.base_frame_id if frame == "base" or campaign.frame == "base" else campaign.frame_id
    adequacy = assess_model_adequacy(
        calibration, campaign.joint_positions, settings.tracker_noise, settings.encoder_noise, distances
    )
    field_estimate = None
    field_draw = None
    if "residual" in settings.sources and not adequacy.adequate and settings.model_error == "field":
        noise = pose_noise_covariances(
            calibration, campaign.joint_positions, settings.tracker_noise, settings.encoder_noise, distances
        )
        # The shape of the residuals' own covariance: the model error dominates it, and unlike the
        # moment estimate (clipped to be PSD) it has variance in every direction the data have.
        field_estimate = estimate_field(calibration, campaign.joint_positions, noise, adequacy.residual_covariance)
        if field_estimate.identified:
            field_draw = FieldNormal(
                campaign.joint_positions,
                test_q,
                field_estimate,
                innovations=standardised_innovations(np.asarray(calibration.residuals, dtype=np.float64)),
            )
    context = TrialContext(
        n_poses=n_poses,
        n_joints=model.n_joints,
        n_test=test_q.shape[0],
        measurement_dimension=dim,
        distances=distances,
        model_errors=adequacy.draws,
        lambda_star=lam_star,
        lambda_range=lambda_range,
        min_poses=min_poses,
        subset_size=subset_size,
        rotation_std=np.asarray(measurement.rotation_std) if isinstance(measurement, PoseMeasurement) else None,
        test_effect_jacobian=test_effect_jacobian(calibration, test_q, settings),
        prismatic=model.prismatic if any(model.prismatic) else (),
        model_error_field=field_draw,
    )
    trials = CalibrationTrials(
        problem=problem,
        x_hat=x_hat,
        joint_positions=campaign.joint_positions,
        points=campaign.points,
        test_joints=test_q,
        drop_base=drop_base,
        output_rotation=output_rotation,
        lambda_star=lam_star,
        sources=build_sources(settings, context),
        gauss_newton_iterations=settings.gauss_newton_iterations,
        solver=None
        if settings.jacobian == "exact"
        else _chord_solver(problem, calibration.estimate, campaign.joint_positions, kernels),
        reference_rotations=_calibrated_rotations(calibration, test_q, drop_base=drop_base) if orientation else None,
        test_predictor=_test_predictor(calibration, test_q, drop_base=drop_base, backend=kernels),
    )
    return _Prepared(
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
    test_q, _ = _validate_inputs(model, test_joint_positions, 0.95, "auto")
    return _prepare(model, campaign, test_q, settings, calibration, lambda_, frame, backend=backend).trials


@dataclass(frozen=True)
class EvaluationSettings:
    """Everything that determines the result of :func:`evaluate_uncertainty` besides its data.

    The data are the model, the campaign, the test configurations and (optionally) an existing
    calibration; how the trials are run (workers, chunks, an executor, a progress callback)
    never changes the result and is given to :func:`evaluate_uncertainty` separately.

    Attributes
    ----------
    uncertainty : UncertaintySettings
        Sources and their models; default tracker and encoder noise at the seed's levels.
    lambda_ : {"auto", "gcv"} or float
        Lambda method of the calibration (when it is computed here).
    trials : int or "auto"
        Fixed number of trials, or the JCGM 101 §7.9 adaptive procedure.
    coverage : float
        Coverage probability p in (0, 1).
    seed : int
        Root seed; the result is reproducible from it.
    n_dig : int
        Significant digits of the adaptive procedure and the GUM validation.
    max_trials : int
        Cap of the adaptive procedure.
    block_size : int
        Trials per independent random stream (part of the result's identity).
    frame : {"measurement", "base"}
        Frame of the output positions. ``measurement``: the frame of the campaign's points, so
        results compare directly with measurements; for a tracker-frame campaign the
        uncertainty of the identified base enters. ``base``: the robot base frame (the
        identified base does not enter).
    orientation : bool
        Also evaluate the tool orientation (3 more columns per test configuration, see the
        module docstring); positions and parameters are the same either way, bit for bit.
        The adaptive procedure monitors the positions only.
    backend : {"numpy", "numba", "cupy", "auto"}
        Which trial kernels walk the chain (:mod:`robocal_uncertainty.kernels`): the same
        draws, the same result to rounding (1e-12 relative, tested), recorded in the result.
    """

    uncertainty: UncertaintySettings = field(default_factory=UncertaintySettings)
    lambda_: str | float = "auto"
    trials: int | str = 10_000
    coverage: float = 0.95
    seed: int = 0
    n_dig: int = 2
    max_trials: int = 2_000_000
    block_size: int = 10_000
    frame: str = "measurement"
    orientation: bool = True
    backend: str = "numpy"

    def replace(self, **keywords: Any) -> EvaluationSettings:
        """A copy with fields replaced; also takes the keyword names :func:`evaluate_uncertainty`
        had before this object (``settings`` for :attr:`uncertainty`, None meaning the default).

        Raises
        ------
        TypeError
            An unknown keyword.
        """
        changes: dict[str, Any] = {}
        for given, value in keywords.items():
            name = "uncertainty" if given == "settings" else given
            if name not in _EVALUATION_FIELDS:
                msg = f"evaluate_uncertainty() got an unexpected keyword argument {given!r}"
                raise TypeError(msg)
            changes[name] = UncertaintySettings() if given == "settings" and value is None else value
        return dataclasses.replace(self, **changes) if changes else self


_EVALUATION_FIELDS = frozenset(f.name for f in dataclasses.fields(EvaluationSettings))


def evaluate_uncertainty(
    model: RobotModel,
    campaign: Campaign,
    test_joint_positions: Array,
    evaluation: EvaluationSettings | None = None,
    *,
    calibration: IdentificationResult | None = None,
    workers: int = 1,
    chunk_blocks: int = 1,
    progress: Callable[[int, int | None], None] | None = None,
    executor: object | None = None,
    **fields: Any,
) -> CalibrationUncertainty:
    """Monte Carlo uncertainty of the calibrated tool pose at test configurations.

    Parameters
    ----------
    model : RobotModel
        Nominal model.
    campaign : Campaign
        Calibration data (joint readings [rad], points [m]).
    test_joint_positions : ndarray, shape (n_test, n_joints) or (n_joints,) [rad]
        Configurations at which the tool position is evaluated.
    evaluation : EvaluationSettings, optional
        What determines the result (sources, lambda method, trials, coverage, seed, ...);
        the defaults when omitted.
    calibration : IdentificationResult, optional
        An existing calibration of `campaign`; computed with ``evaluation.lambda_`` when
        omitted.
    workers : int
        Local processes (never changes the result).
    chunk_blocks : int
        Blocks evaluated per task (never changes the result). Memory is bounded by a
        fixed sub-batch of trials re-identified at once.
    progress : callable, optional
        ``progress(done, target_or_None)``.
    executor : Executor-like, optional
        Runs the trial blocks instead of local processes: anything with a
        ``concurrent.futures``-style ``submit`` (a process pool, a ``dask.distributed``
        Client). Never changes the result.
    **fields
        Fields of :class:`EvaluationSettings` replaced in `evaluation` (the keyword call of
        before: ``settings=``, ``trials=``, ``seed=``, ``frame=``, ...), see
        :meth:`EvaluationSettings.replace`.

    Returns
    -------
    CalibrationUncertainty

    Raises
    ------
    ConfigError
        Bad settings (trials, coverage, test joints, lambda range, pose counts).
    """
    ev = (evaluation or EvaluationSettings()).replace(**fields)
    if ev.frame not in OUTPUT_FRAMES:
        msg = f"output frame must be one of {', '.join(OUTPUT_FRAMES)}, got {ev.frame!r}"
        raise ConfigError(msg)
    test_q, n_trials = _validate_inputs(model, test_joint_positions, ev.coverage, ev.trials)
    prep = _prepare(
        model,
        campaign,
        test_q,
        ev.uncertainty,
        calibration,
        ev.lambda_,
        ev.frame,
        orientation=ev.orientation,
        backend=ev.backend,
    )
    adaptive = None
    if n_trials is None:
        # The measurand is the tool position: its components decide convergence; the
        # parameter columns ride along and report the tolerance they reached.
        adaptive = AdaptiveSettings(
            n_dig=ev.n_dig,
            coverage=ev.coverage,
            max_trials=ev.max_trials,
            monitored=tuple(range(_N_AXES * test_q.shape[0])),
        )
    result = run_trials(
        prep.trials,
        seed=ev.seed,
        n_trials=n_trials,
        adaptive=adaptive,
        block_size=ev.block_size,
        chunk_blocks=chunk_blocks,
        workers=workers,
        executor=executor,
        progress=progress,
    )
    return _statement(prep, ev, result)


def _statement(prep: _Prepared, ev: EvaluationSettings, result: TrialsResult) -> CalibrationUncertainty:
    """The uncertainty statement of the trials `result` (a ``run_trials`` result)."""
    calibration = prep.calibration
    model = calibration.model
    test_q = prep.test_joints
    dim = _N_AXES
    n_test = test_q.shape[0]
    k = prep.problem.estimated.size
    # Positions and parameters: the same columns (and numbers) with or without orientation.
    samples = result.samples[:, : dim * n_test + k]
    summary = summarize(samples, ev.coverage)
    gum = _gum_poses(prep, summary, ev.coverage, ev.n_dig)
    orientations = (
        _orientation_uncertainty(prep, result.samples, summary, ev.coverage, ev.n_dig)
        if ev.orientation
        else [None] * n_test
    )
    poses = []
    warns: list[str] = list(calibration.warnings)
    for i in range(n_test):
        cols = slice(dim * i, dim * (i + 1))
        axes = summary.outputs[cols]
        try:
            region: EllipsoidalRegion | None = coverage_region(result.samples[:, cols], ev.coverage)
        except (InputError, ConfigError) as err:
            region = None
            warns.append(f"test configuration {i}: no coverage region ({err})")
        poses.append(
            PoseUncertainty(
                joint_positions=test_q[i],
                mean=np.array([a.estimate for a in axes]),
                covariance=summary.covariance[cols, cols],
                axes=tuple(axes),
                region=region,
                gum=gum[i],
                orientation=orientations[i],
            )
        )
    warns += _bias_warnings(prep, poses)
    few = None if result.adaptive is not None else too_few_trials_note(result.n_trials, ev.coverage)
    if few is not None:
        warns.append(few)
    if result.adaptive is not None and not result.adaptive.converged:
        warns.append(
            f"adaptive Monte Carlo stopped at max_trials={ev.max_trials} before reaching "
            f"the numerical tolerance of {ev.n_dig} significant digits"
        )
    return CalibrationUncertainty(
        poses=tuple(poses),
        parameter_names=tuple(model.layout.names[j] for j in prep.problem.estimated),
        parameters=tuple(summary.outputs[dim * n_test :]),
        calibration=calibration,
        settings=ev.uncertainty,
        coverage_probability=ev.coverage,
        n_trials=result.n_trials,
        seed=ev.seed,
        block_size=ev.block_size,
        adaptive=result.adaptive,
        samples=samples,
        lambda_star=calibration.lambda_,
        lambda_range=prep.lambda_range,
        frame=ev.frame,  # type: ignore[arg-type]
        frame_id=prep.frame_id,
        model_adequacy=prep.adequacy,
        warnings=tuple(warns),
        rotation_samples=result.samples[:, dim * n_test + k :] if ev.orientation else None,
        not_converged=gum_disagreements(poses),
        backend=resolve_backend(ev.backend),
        model_error_field=prep.model_error_field,
    )


def _bias_warnings(prep: _Prepared, poses: list[PoseUncertainty]) -> list[str]:
    """Warnings for test configurations whose regularisation bias the interval does not cover."""
    warns = []
    bias = _regularisation_bias(prep)
    for i, pose in enumerate(poses):
        u = np.array([a.standard_uncertainty for a in pose.axes])
        ratio = np.where(u > 0, np.abs(bias[i]) / np.where(u > 0, u, 1.0), 0.0)
        j = int(np.argmax(ratio))
        if ratio[j] > _BIAS_WARN_RATIO:
            warns.append(
                f"test configuration {i}: regularisation (lambda = {prep.calibration.lambda_:.3g}) shifts the "
                f"calibrated position by about {bias[i, j] * 1e6:.3g} um along {'xyz'[j]}, "
                f"{ratio[j]:.2g} times its standard uncertainty, and the interval does not contain "
                "this bias: measure more poses, or use a smaller --lambda"
            )
    return warns
