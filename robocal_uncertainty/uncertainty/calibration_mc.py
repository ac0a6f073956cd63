"""Monte Carlo uncertainty of a calibrated arm's tool position (JCGM 101).

A trial perturbs the campaign according to the enabled sources, re-identifies the
parameters, and evaluates the tool point at every requested joint configuration.
Trials run in blocks with independent seeded streams (see
:mod:`robocal_uncertainty.montecarlo.engine`), so the result is the same whatever the
chunk size or the number of workers.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult, identify
from robocal_uncertainty.core.kinematics import forward_points, forward_points_and_jacobian
from robocal_uncertainty.core.robot_model import RobotModel, rpy_to_matrix
from robocal_uncertainty.errors import ConfigError, InputError
from robocal_uncertainty.montecarlo import (
    AdaptiveReport,
    AdaptiveSettings,
    EllipsoidalRegion,
    OutputSummary,
    coverage_region,
    numerical_tolerance,
    run_trials,
)
from robocal_uncertainty.uncertainty.model_adequacy import ModelAdequacy, assess_model_adequacy
from robocal_uncertainty.uncertainty.reidentification import (
    BatchProblem,
    ChordSolver,
    reidentify_batch,
)
from robocal_uncertainty.uncertainty.sources import UncertaintySettings

__all__ = [
    "OUTPUT_FRAMES",
    "CalibrationTrials",
    "CalibrationUncertainty",
    "GumPose",
    "PoseUncertainty",
    "evaluate_uncertainty",
]

Array = NDArray[np.float64]
_GUM_SOURCES = frozenset(("tracker", "encoder", "residual"))
_SUB_BATCH = 256
OutputFrame = Literal["measurement", "base"]
OUTPUT_FRAMES: tuple[str, ...] = ("measurement", "base")
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
    """

    joint_positions: Array
    mean: Array
    covariance: Array
    axes: tuple[OutputSummary, ...]
    region: EllipsoidalRegion | None
    gum: GumPose


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

    @property
    def converged(self) -> bool:
        """True for a fixed number of trials, the adaptive verdict otherwise."""
        return True if self.adaptive is None else self.adaptive.converged


@dataclass(frozen=True, eq=False)
class CalibrationTrials:
    """Picklable trial block: perturb, re-identify, evaluate at the test configurations."""

    problem: BatchProblem
    x_hat: Array
    joint_positions: Array
    points: Array
    fitted: Array
    model_errors: Array
    distances: Array
    test_joints: Array
    drop_base: bool
    output_rotation: Array
    lambda_star: float
    lambda_range: tuple[float, float] | None
    min_poses: int
    subset_size: int
    settings: UncertaintySettings
    solver: ChordSolver | None = None

    def __call__(self, rng: np.random.Generator, n: int) -> Array:
        """Model values of n trials, shape (n, 3 n_test + k)."""
        sources = self.settings.sources
        n_poses, n_joints = self.joint_positions.shape
        n_test = self.test_joints.shape[0]
        # Draw every input of the block first, in a fixed order, so the stream depends on
        # the block alone; chunking below only bounds memory.
        tracker = (
            self.settings.tracker_noise.sample(rng, np.broadcast_to(self.distances, (n, n_poses)))
            if "tracker" in sources
            else None
        )
        if "encoder" in sources:
            enc = self.settings.encoder_noise
            q_noise = enc.sample(rng, (n, n_poses, n_joints))
            test_noise = enc.sample(rng, (n, n_test, n_joints))
        else:
            q_noise = test_noise = None
        if "residual" in sources:
            boot = rng.integers(0, n_poses, size=(n, n_poses))
            pred_boot = rng.integers(0, n_poses, size=(n, n_test))
        else:
            boot = pred_boot = None
        if "lambda" in sources:
            lo, hi = self.lambda_range if self.lambda_range is not None else (self.lambda_star,) * 2
            lambdas = rng.uniform(lo, hi, size=n)
        else:
            lambdas = np.full(n, self.lambda_star)
        weights = None
        if "n_poses" in sources:
            counts = rng.integers(self.min_poses, n_poses + 1, size=n)
            ranks = np.argsort(np.argsort(rng.random((n, n_poses)), axis=1), axis=1)
            weights = (ranks < counts[:, None]).astype(np.float64)
        if "pose_choice" in sources:
            ranks = np.argsort(np.argsort(rng.random((n, n_poses)), axis=1), axis=1)
            chosen = (ranks < self.subset_size).astype(np.float64)
            weights = chosen if weights is None else weights * chosen
            # Both sources on: the subset of the subset must still identify the model.
            short = weights.sum(axis=1) < self.min_poses
            weights[short] = chosen[short]

        k = self.x_hat.size
        out = np.empty((n, 3 * n_test + k))
        # A fixed sub-batch: BLAS rounding may depend on the number of rows, so the split of
        # a block must never depend on a user setting.
        for lo_i in range(0, n, _SUB_BATCH):
            sl = slice(lo_i, min(n, lo_i + _SUB_BATCH))
            t = sl.stop - sl.start
            # Every source perturbs the measured points with zero-mean errors, so the trials
            # stay centred on the calibration.
            pts = np.array(np.broadcast_to(self.points, (t, n_poses, 3)))
            if boot is not None:
                pts += self.model_errors[boot[sl]]
            if tracker is not None:
                pts += tracker[sl]
            q = self.joint_positions[None] + q_noise[sl] if q_noise is not None else self.joint_positions
            w = None if weights is None else weights[sl]
            if self.solver is not None:
                x, _ = self.solver.solve(
                    q,
                    pts,
                    w,
                    lambdas[sl],
                    self.x_hat,
                    initial_prediction=self.fitted if q_noise is None else None,
                )
            else:
                x, _ = reidentify_batch(
                    self.problem,
                    q,
                    pts,
                    w,
                    lambdas[sl],
                    self.x_hat,
                    iterations=self.settings.gauss_newton_iterations,
                )
            params = self.problem.parameters(x)
            out[sl, 3 * n_test :] = params[:, self.problem.estimated]
            if self.drop_base:
                # Positions in the robot base frame: the identified base does not enter.
                b0 = self.problem.layout.base_index
                params[:, b0 : b0 + 6] = 0.0
            qt = self.test_joints[None] + test_noise[sl] if test_noise is not None else self.test_joints
            pos = forward_points(self.problem.layout, params, qt)
            if pred_boot is not None:
                # Row-vector form of R_out e: model errors live in the measurement frame.
                pos = pos + self.model_errors[pred_boot[sl]] @ self.output_rotation.T
            out[sl, : 3 * n_test] = pos.reshape(t, 3 * n_test)
        return out


def _validate_inputs(
    model: RobotModel, test_joint_positions: object, coverage: float, trials: object
) -> tuple[Array, int | None]:
    q = np.asarray(test_joint_positions, dtype=np.float64)
    if q.ndim == 1:
        q = q[None, :]
    if q.ndim != 2 or q.shape[1] != model.n_joints:
        msg = (
            f"test joints must have {model.n_joints} values per configuration "
            f"({', '.join(model.joint_names)}), got shape {np.shape(test_joint_positions)}"
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
    return q, int(trials)


def _gum_pose(
    calibration: IdentificationResult,
    problem: BatchProblem,
    campaign: Campaign,
    settings: UncertaintySettings,
    distances: Array,
    adequacy: ModelAdequacy,
    test_joints: Array,
    drop_base: bool,
    output_rotation: Array,
) -> list[tuple[Array, Array, bool]]:
    """First-order covariance of the tool position at each test configuration (output frame)."""
    layout = problem.layout
    est = problem.estimated
    sources = set(settings.sources)
    applicable = sources <= _GUM_SOURCES
    p_hat = calibration.estimate
    q = campaign.joint_positions
    n = campaign.n_poses
    _, jac = forward_points_and_jacobian(layout, p_hat, q)
    a_mat = jac.reshape(3 * n, layout.size)[:, est] / problem.scale
    lam = calibration.lambda_
    h = np.linalg.solve(a_mat.T @ a_mat + lam**2 * np.diag(problem.penalty_mask), a_mat.T)  # x = H b
    cov_b = np.zeros((3 * n, 3 * n))
    if "tracker" in sources:
        cov_b += np.diag(np.repeat(settings.tracker_noise.std(distances) ** 2, 3))
    var_q = settings.encoder_noise.half_width**2 / 3.0
    theta_cols = [idx["theta"] for idx in layout.joint_slices()]
    if "encoder" in sources:
        jq = jac[:, :, theta_cols]  # d point / d joint reading, per pose (n, 3, n_joints)
        blocks = var_q * np.einsum("pij,pkj->pik", jq, jq)
        for i in range(n):
            cov_b[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] += blocks[i]
    model_cov = adequacy.inadequacy_covariance
    if "residual" in sources:
        for i in range(n):
            cov_b[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] += model_cov
    cov_x = h @ cov_b @ h.T
    cov_p = cov_x / np.outer(problem.scale, problem.scale)
    p_out = p_hat.copy()
    b0 = layout.base_index
    if drop_base:
        p_out[b0 : b0 + 6] = 0.0
    y, gy = forward_points_and_jacobian(layout, p_out, test_joints)
    if drop_base:
        gy[:, :, b0 : b0 + 6] = 0.0
    out = []
    for i in range(test_joints.shape[0]):
        g = gy[i][:, est]
        cov_y = g @ cov_p @ g.T
        if "encoder" in sources:
            gq = gy[i][:, theta_cols]
            cov_y = cov_y + var_q * gq @ gq.T
        if "residual" in sources:
            cov_y = cov_y + output_rotation @ model_cov @ output_rotation.T
        out.append((y[i], cov_y, applicable))
    return out


def evaluate_uncertainty(
    model: RobotModel,
    campaign: Campaign,
    test_joint_positions: Array,
    *,
    settings: UncertaintySettings | None = None,
    calibration: IdentificationResult | None = None,
    lambda_: str | float = "auto",
    trials: int | str = 10_000,
    coverage: float = 0.95,
    seed: int = 0,
    n_dig: int = 2,
    max_trials: int = 2_000_000,
    block_size: int = 10_000,
    chunk_blocks: int = 1,
    workers: int = 1,
    progress: Callable[[int, int | None], None] | None = None,
    frame: str = "measurement",
) -> CalibrationUncertainty:
    """Monte Carlo uncertainty of the calibrated tool position at test configurations.

    Parameters
    ----------
    model : RobotModel
        Nominal model.
    campaign : Campaign
        Calibration data (joint readings [rad], points [m]).
    test_joint_positions : ndarray, shape (n_test, n_joints) or (n_joints,) [rad]
        Configurations at which the tool position is evaluated.
    settings : UncertaintySettings, optional
        Sources and their models; default tracker and encoder noise at the seed's levels.
    calibration : IdentificationResult, optional
        An existing calibration of `campaign`; computed with `lambda_` when omitted.
    lambda_ : {"auto", "gcv"} or float
        Lambda method of the calibration.
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
    chunk_blocks : int
        Blocks evaluated per task (never changes the result). Memory is bounded by a
        fixed sub-batch of trials re-identified at once.
    workers : int
        Processes (never changes the result).
    progress : callable, optional
        ``progress(done, target_or_None)``.
    frame : {"measurement", "base"}
        Frame of the output positions. ``measurement`` (default): the frame of the
        campaign's points, so results compare directly with measurements; for a
        tracker-frame campaign the uncertainty of the identified base enters. ``base``: the
        robot base frame (the identified base does not enter).

    Returns
    -------
    CalibrationUncertainty

    Raises
    ------
    ConfigError
        Bad settings (trials, coverage, test joints, lambda range, pose counts).
    """
    settings = settings or UncertaintySettings()
    if frame not in OUTPUT_FRAMES:
        msg = f"output frame must be one of {', '.join(OUTPUT_FRAMES)}, got {frame!r}"
        raise ConfigError(msg)
    test_q, n_trials = _validate_inputs(model, test_joint_positions, coverage, trials)
    campaign = campaign.reorder_joints(model.joint_names)
    if calibration is None:
        calibration = identify(model, campaign, lambda_=lambda_)
    layout = model.layout
    est = np.flatnonzero(calibration.estimated)
    scale = calibration.column_scale[est]
    problem = BatchProblem(
        layout=layout,
        start=calibration.nominal,
        estimated=est,
        scale=scale,
        penalized=calibration.penalized[est],
    )
    x_hat = (calibration.estimate[est] - calibration.nominal[est]) * scale
    n_poses = campaign.n_poses
    k = est.size

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
    min_identifiable = math.ceil(k / 3)
    min_poses = settings.min_poses or max(math.ceil(40 / 3), math.ceil(1.5 * k / 3))
    subset_size = settings.subset_size or round(33 / 53 * n_poses)
    for name, value in (("min_poses", min_poses), ("subset_size", subset_size)):
        if "n_poses" in settings.sources or "pose_choice" in settings.sources:
            if value < min_identifiable or value > n_poses:
                msg = (
                    f"{name} = {value} must lie between {min_identifiable} (identifiable "
                    f"parameters / 3) and the campaign's {n_poses} poses"
                )
                raise ConfigError(msg)

    b0 = layout.base_index
    if campaign.frame == "tracker":
        distances = np.linalg.norm(campaign.points, axis=1)
    else:
        distances = np.linalg.norm(campaign.points - np.asarray(settings.tracker_xyz), axis=1)
    drop_base = frame == "base" and campaign.frame == "tracker"
    # Model errors live in the measurement frame; R^T takes them into the base frame.
    output_rotation = rpy_to_matrix(calibration.estimate[b0 + 3 : b0 + 6]).T if drop_base else np.eye(3)
    frame_id = model.base_frame_id if frame == "base" or campaign.frame == "base" else campaign.frame_id
    adequacy = assess_model_adequacy(
        calibration, campaign.joint_positions, settings.tracker_noise, settings.encoder_noise, distances
    )
    fitted = campaign.points - calibration.residuals
    trial_block = CalibrationTrials(
        problem=problem,
        x_hat=x_hat,
        joint_positions=campaign.joint_positions,
        points=campaign.points,
        fitted=fitted,
        model_errors=adequacy.draws,
        distances=distances,
        test_joints=test_q,
        drop_base=drop_base,
        output_rotation=output_rotation,
        lambda_star=lam_star,
        lambda_range=lambda_range,
        min_poses=min_poses,
        subset_size=subset_size,
        settings=settings,
        solver=None
        if settings.jacobian == "exact"
        else ChordSolver.at(problem, calibration.estimate, campaign.joint_positions),
    )
    adaptive = None
    if n_trials is None:
        # The measurand is the tool position: its components decide convergence; the
        # parameter columns ride along and report the tolerance they reached.
        adaptive = AdaptiveSettings(
            n_dig=n_dig, coverage=coverage, max_trials=max_trials, monitored=tuple(range(3 * test_q.shape[0]))
        )
    result = run_trials(
        trial_block,
        seed=seed,
        n_trials=n_trials,
        adaptive=adaptive,
        block_size=block_size,
        chunk_blocks=chunk_blocks,
        workers=workers,
        progress=progress,
    )
    summary = result.summary(coverage)
    n_test = test_q.shape[0]
    gum = _gum_pose(calibration, problem, campaign, settings, distances, adequacy, test_q, drop_base, output_rotation)
    k_norm = float(stats.norm.ppf(0.5 + coverage / 2.0))
    poses = []
    warns: list[str] = list(calibration.warnings)
    for i in range(n_test):
        cols = slice(3 * i, 3 * i + 3)
        axes = summary.outputs[cols]
        samples = result.samples[:, cols]
        try:
            region: EllipsoidalRegion | None = coverage_region(samples, coverage)
        except (InputError, ConfigError) as err:
            region = None
            warns.append(f"test configuration {i}: no coverage region ({err})")
        y, cov_y, applicable = gum[i]
        u = np.sqrt(np.diag(cov_y))
        big_u = k_norm * u
        d_low = np.array([abs(y[j] - big_u[j] - axes[j].probabilistically_symmetric.low) for j in range(3)])
        d_high = np.array([abs(y[j] + big_u[j] - axes[j].probabilistically_symmetric.high) for j in range(3)])
        delta = np.array([numerical_tolerance(float(u[j]), n_dig) if u[j] > 0 else 0.0 for j in range(3)])
        validated = tuple(bool(applicable and d_low[j] <= delta[j] and d_high[j] <= delta[j]) for j in range(3))
        poses.append(
            PoseUncertainty(
                joint_positions=test_q[i],
                mean=np.array([a.estimate for a in axes]),
                covariance=summary.covariance[cols, cols],
                axes=tuple(axes),
                region=region,
                gum=GumPose(
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
                ),
            )
        )
    if result.adaptive is not None and not result.adaptive.converged:
        warns.append(
            f"adaptive Monte Carlo stopped at max_trials={max_trials} before reaching "
            f"the numerical tolerance of {n_dig} significant digits"
        )
    return CalibrationUncertainty(
        poses=tuple(poses),
        parameter_names=tuple(layout.names[j] for j in est),
        parameters=tuple(summary.outputs[3 * n_test :]),
        calibration=calibration,
        settings=settings,
        coverage_probability=coverage,
        n_trials=result.n_trials,
        seed=seed,
        block_size=block_size,
        adaptive=result.adaptive,
        samples=result.samples,
        lambda_star=lam_star,
        lambda_range=lambda_range,
        frame=frame,  # type: ignore[arg-type]
        frame_id=frame_id,
        model_adequacy=adequacy,
        warnings=tuple(warns),
    )
