"""Proof of an uncertainty statement on held-out measurements.

A calibration's uncertainty statement says where the tool will be at configurations it was
not calibrated on. That can be checked: calibrate and evaluate on some poses exactly as
``evaluate`` does, predict the others with their coverage intervals, and count how often
the measurements fall inside. For each held-out pose the predictive distribution is the
Monte Carlo distribution of the calibrated prediction (every enabled source, including the
model error at that configuration when the ``residual`` source is on) plus the held-out
measurement's own tracker noise, drawn from the stated tracker model. A statement that
means what it says puts a fraction p of the held-out measurements inside its p-intervals
and has normalised errors of RMS 1.

The check is on positions: the Monte Carlo predicts the tool position, and each held-out
measurement gives its 3-D position through its measurement type
(:meth:`~robocal_uncertainty.core.measurement.MeasurementType.positions`); a type that holds
no position (e.g. a distance) cannot be held out this way.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.frame_check import FrameComparison, compare_frames
from robocal_uncertainty.core.identification import IdentificationResult, identify
from robocal_uncertainty.core.kinematics import forward_points
from robocal_uncertainty.core.measurement import POSITION_AXES
from robocal_uncertainty.core.pose_measurement import PoseMeasurement, split_pose_values
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.rotation import rotation_log
from robocal_uncertainty.errors import ConfigError, ConvergenceError, InputError
from robocal_uncertainty.montecarlo.executor import RunContext
from robocal_uncertainty.uncertainty.calibration import (
    CalibrationUncertainty,
    EvaluationSettings,
    evaluate_uncertainty,
)
from robocal_uncertainty.uncertainty.memory import check_fits, validation_bytes
from robocal_uncertainty.uncertainty.sources import UncertaintySettings, sources_with_role
from robocal_uncertainty.uncertainty.sources.instrument import TRACKER, TRACKER_ORIENTATION

__all__ = [
    "HOLDOUT_POSE_TRIALS",
    "RELIABILITY_LEVELS",
    "AxisValidation",
    "FoldResult",
    "HoldoutSplit",
    "HoldoutValidation",
    "holdout_chunk_size",
    "split_campaign",
    "validate_holdout",
]

Array = NDArray[np.float64]
RELIABILITY_LEVELS: tuple[float, ...] = (0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 0.99)
"""Coverage probabilities of the reliability curve."""
AXES = POSITION_AXES
"""Axes of the predicted position (the output of the Monte Carlo), in its frame."""


@dataclass(frozen=True)
class HoldoutSplit:
    """Indices of the training and held-out poses of one fold."""

    train: NDArray[np.intp]
    held_out: NDArray[np.intp]


def split_campaign(
    n_poses: int,
    *,
    n_train: int | None = None,
    holdout_fraction: float | None = None,
    k_folds: int | None = None,
    seed: int = 0,
) -> tuple[HoldoutSplit, ...]:
    """Random training/held-out splits of a campaign's poses.

    Exactly one of `n_train`, `holdout_fraction`, `k_folds` is given.

    Parameters
    ----------
    n_poses : int
    n_train : int, optional
        Training poses drawn at random; the rest are held out.
    holdout_fraction : float, optional
        Fraction of the poses held out, in (0, 1).
    k_folds : int, optional
        k-fold cross-validation: every pose is held out once.
    seed : int
        Seed of the permutation.
    """
    given = [v is not None for v in (n_train, holdout_fraction, k_folds)]
    if sum(given) != 1:
        raise ConfigError("give exactly one of n_train, holdout_fraction, k_folds")
    perm = np.random.default_rng(np.random.SeedSequence([seed, 0x5EED])).permutation(n_poses)
    if k_folds is not None:
        if isinstance(k_folds, bool) or not isinstance(k_folds, int) or not 2 <= k_folds <= n_poses:
            msg = f"k_folds must be an integer between 2 and the {n_poses} poses, got {k_folds!r}"
            raise ConfigError(msg)
        folds = np.array_split(perm, k_folds)
        return tuple(
            HoldoutSplit(train=np.sort(np.concatenate(folds[:i] + folds[i + 1 :])), held_out=np.sort(f))
            for i, f in enumerate(folds)
        )
    if holdout_fraction is not None:
        if not 0.0 < float(holdout_fraction) < 1.0:
            msg = f"hold-out fraction must lie in (0, 1), got {holdout_fraction}"
            raise ConfigError(msg)
        n_train = n_poses - max(1, round(holdout_fraction * n_poses))
    assert n_train is not None
    if isinstance(n_train, bool) or not isinstance(n_train, int) or not 1 <= n_train < n_poses:
        msg = f"training poses must be between 1 and {n_poses - 1} (the campaign has {n_poses}), got {n_train!r}"
        raise ConfigError(msg)
    return (HoldoutSplit(train=np.sort(perm[:n_train]), held_out=np.sort(perm[n_train:])),)


@dataclass(frozen=True)
class AxisValidation:
    """Held-out statistics of one axis of the output frame.

    Attributes
    ----------
    axis : str
    rms_error : float [m]
        RMS of measured minus predicted (Monte Carlo mean).
    normalized_rms : float
        RMS of the error divided by the predictive standard uncertainty (which includes
        the measurement's own noise); 1 for an honest statement.
    inside_fraction : float
        Fraction of held-out measurements inside their probabilistically symmetric
        p-interval at the run's coverage probability.
    reliability : ndarray, shape (n_levels,)
        The same fraction at every level of :data:`RELIABILITY_LEVELS`.
    """

    axis: str
    rms_error: float
    normalized_rms: float
    inside_fraction: float
    reliability: Array


@dataclass(frozen=True)
class FoldResult:
    """What one fold's calibration and Monte Carlo looked like."""

    n_train: int
    n_held_out: int
    rms_train_after: float
    lambda_: float
    model_adequate: bool
    model_error_std: Array
    n_trials: int
    trustworthy: bool = True
    trust_note: str = ""
    model_error: str = "none"
    """How the residual source drew the model error: ``"field"`` (correlated over the
    configurations), ``"independent"`` (pose by pose: asked for, or the field not identified by
    the training poses) or ``"none"`` (model adequate, or no ``residual`` source)."""


@dataclass(frozen=True)
class HoldoutValidation:
    """Result of :func:`validate_holdout`.

    Attributes
    ----------
    coverage_probability : float
    levels : ndarray, shape (n_levels,)
        Coverage probabilities of the reliability curve.
    axes : tuple of AxisValidation, one per axis of :data:`AXES`
    region_inside_fraction : float
        Fraction of held-out measurements inside the JCGM 102 3-D region at p.
    region_reliability : ndarray, shape (n_levels,)
    errors : ndarray, shape (n_held_out, len(AXES)) [m]
        Measured minus predicted, in `frame_id`.
    standard_uncertainties : ndarray, shape (n_held_out, len(AXES)) [m]
        Predictive standard uncertainty (calibration plus measurement noise).
    folds : tuple of FoldResult
    frame_id : str
    sources : tuple of str
    seed : int
    mode : str
        ``"split"``, ``"k-fold"`` or ``"campaign"`` (a second campaign held out).
    orientation_axes : tuple of AxisValidation
        6-DOF held-out measurements: the same statistics for the rotation about the frame's
        fixed x, y, z axes (``rx, ry, rz``; errors ``log(R_measured R_predicted^T)`` [rad],
        predictive distribution with the ``tracker_orientation`` noise when enabled); empty
        for points.
    frame_comparison : FrameComparison or None
        Mode ``"campaign"``: the validation campaign's frame against the calibration's (a rigid
        fit of predicted to measured positions), within the stated uncertainty.
    """

    coverage_probability: float
    levels: Array
    axes: tuple[AxisValidation, ...]
    region_inside_fraction: float
    region_reliability: Array
    errors: Array
    standard_uncertainties: Array
    folds: tuple[FoldResult, ...]
    frame_id: str
    sources: tuple[str, ...]
    seed: int
    mode: str
    orientation_axes: tuple[AxisValidation, ...] = ()
    frame_comparison: FrameComparison | None = None

    @property
    def n_held_out(self) -> int:
        """Number of held-out measurements."""
        return int(self.errors.shape[0])


def _inside_regions(pred: Array, points: Array, levels: Array) -> NDArray[np.bool_]:
    """Whether each point lies in the JCGM 102 ellipsoidal region of its samples, per level.

    Vectorised over poses; the same definition as
    :func:`robocal_uncertainty.montecarlo.coverage_region`: k_p^2 is the q-th smallest squared
    Mahalanobis distance of the samples, q = floor(p M + 1/2).

    Returns
    -------
    ndarray of bool, shape (n_levels, n_poses)
    """
    m = pred.shape[0]
    centred = pred - pred.mean(axis=0)
    cov = np.einsum("mpi,mpj->pij", centred, centred) / (m - 1)
    chol = np.linalg.cholesky(cov)
    d2 = _squared_whitened(chol, centred)  # (m, n_poses)
    dp2 = _squared_whitened(chol, (points - pred.mean(axis=0))[None])[0]
    q = np.clip(np.floor(levels * m + 0.5).astype(int), 1, m)
    # Only the q-th smallest distances are read: a partition gives them exactly, without a sort.
    ranks = np.unique(q)
    kth = np.partition(d2, ranks - 1, axis=0)[ranks - 1]
    inside: NDArray[np.bool_] = dp2[None, :] <= kth[np.searchsorted(ranks, q)]
    return inside


def _squared_whitened(chol: Array, centred: Array) -> Array:
    """|L^-1 c|^2 per pose and row: `chol` (n, 3, 3) lower, `centred` (m, n, 3); shape (m, n).

    Forward substitution written out for 3 axes (a batched general solve of millions of 3x3
    systems costs ten times more).
    """
    c0, c1, c2 = centred[..., 0], centred[..., 1], centred[..., 2]
    z0 = c0 / chol[:, 0, 0]
    z1 = (c1 - chol[:, 1, 0] * z0) / chol[:, 1, 1]
    z2 = (c2 - chol[:, 2, 0] * z0 - chol[:, 2, 1] * z1) / chol[:, 2, 2]
    d2: Array = z0 * z0 + z1 * z1 + z2 * z2
    return d2


def _held_out_positions(campaign: Campaign) -> Array:
    """3-D positions [m] of the held-out measurements, shape (n_poses, len(AXES))."""
    positions = campaign.measurement.positions(campaign.points)
    if positions is None:
        msg = (
            f"held-out {campaign.measurement.name} measurements hold no 3-D position: "
            "validation compares predicted and measured positions"
        )
        raise InputError(msg)
    return positions


def _tracker_distances(points: Array, campaign: Campaign, settings: UncertaintySettings) -> Array:
    origin = np.zeros(len(AXES)) if campaign.frame == "tracker" else np.asarray(settings.tracker_xyz)
    distances: Array = np.linalg.norm(points - origin, axis=1)
    return distances


def _orientation_fold(
    result: CalibrationUncertainty,
    held: Campaign,
    settings: UncertaintySettings,
    levels: Array,
    rng: np.random.Generator,
) -> tuple[Array, Array, NDArray[np.bool_]]:
    """Held-out rotation errors [rad], predictive std [rad] and inside flags (L, n, 3).

    The Monte Carlo rows end with each held-out configuration's rotation deviation from the
    calibrated rotation; the measured deviation is compared with their distribution (plus the
    instrument's orientation noise when ``tracker_orientation`` is enabled).
    """
    n_held = held.n_poses
    if result.rotation_samples is None:
        raise InputError("the Monte Carlo gave no orientation for the held-out configurations")
    dev = result.rotation_samples.reshape(-1, n_held, 3)
    measurement = held.measurement
    if isinstance(measurement, PoseMeasurement) and TRACKER_ORIENTATION.name in settings.sources:
        dev = dev + rng.normal(0.0, 1.0, dev.shape) * np.asarray(measurement.rotation_std)
    reference = np.stack([pose.orientation.calibrated_rotation for pose in result.poses if pose.orientation])
    if reference.shape[0] != n_held:
        raise InputError("the Monte Carlo gave no orientation for the held-out configurations")
    _, measured_rot = split_pose_values(held.points)
    measured = rotation_log(measured_rot @ np.swapaxes(reference, -1, -2))
    mean = dev.mean(axis=0)
    std = dev.std(axis=0, ddof=1)
    tails = np.concatenate(((1.0 - levels) / 2.0, (1.0 + levels) / 2.0))
    q = np.quantile(dev, tails, axis=0)
    lo, hi = q[: levels.size], q[levels.size :]
    return measured - mean, std, (measured[None] >= lo) & (measured[None] <= hi)


StatementAdjustment = Callable[[CalibrationUncertainty, IdentificationResult, Campaign], CalibrationUncertainty]
"""``adjust(result, calibration, training campaign)`` of :func:`validate_holdout`."""

HOLDOUT_POSE_TRIALS = 3_200_000
"""Held-out poses x Monte Carlo trials evaluated at once (640 poses at 5000 trials): what bounds
the memory of :func:`validate_holdout` whatever the number of held-out poses."""
MIN_HOLDOUT_CHUNK = 16
"""Fewest held-out poses per chunk (with very many trials)."""


def holdout_chunk_size(trials: int) -> int:
    """Held-out poses per Monte Carlo run of :func:`validate_holdout` at `trials` trials.

    A fold with more held-out poses runs one Monte Carlo per chunk (each re-identifying the
    trials of the same calibration): peak memory is set by this chunk, not by the number of
    held-out poses. Up to this many poses the result is the single run's, bit for bit.
    """
    return max(MIN_HOLDOUT_CHUNK, HOLDOUT_POSE_TRIALS // max(int(trials), 1))


def _chunk_seed(seed: int, fold: int, chunk: int) -> int:
    """Root seed of chunk > 0 of a fold: its own stream, distinct from every fold's ``seed + f``."""
    return int(np.random.SeedSequence([seed, fold, chunk, 0xC4A1]).generate_state(1, np.uint64)[0] >> 1)


def _chunk_statistics(
    result: CalibrationUncertainty,
    held: Campaign,
    settings: UncertaintySettings,
    levels: Array,
    seed: int,
    fold: int,
    chunk: int,
) -> tuple[Array, Array, NDArray[np.bool_], NDArray[np.bool_], tuple[Array, Array, NDArray[np.bool_]] | None]:
    """Errors, predictive std, inside flags (L, n, 3), region flags (L, n) and the orientation's
    of one chunk of held-out poses; the Monte Carlo samples are not kept."""
    n_held = held.n_poses
    n_axes = len(AXES)
    held_points = _held_out_positions(held)
    pred = result.samples[:, : n_axes * n_held].reshape(-1, n_held, n_axes)
    # The held-out measurement carries its own tracker noise: the predictive distribution
    # of what the tracker will read is the prediction plus that noise.
    key = [seed, fold, 0xB0B] if chunk == 0 else [seed, fold, 0xB0B, chunk]
    rng = np.random.default_rng(np.random.SeedSequence(key))
    dist = _tracker_distances(held_points, held, settings)
    if TRACKER.name in settings.sources:
        pred = pred + settings.tracker_noise.sample(rng, np.broadcast_to(dist, pred.shape[:2]))
    mean = pred.mean(axis=0)
    std = pred.std(axis=0, ddof=1)
    if not (std > 0).all():
        raise InputError("a held-out prediction has zero spread: enable at least one noise source")
    tails = np.concatenate(((1.0 - levels) / 2.0, (1.0 + levels) / 2.0))
    q = np.quantile(pred, tails, axis=0)  # (2 L, n_held, n_axes)
    lo, hi = q[: levels.size], q[levels.size :]
    inside = (held_points[None] >= lo) & (held_points[None] <= hi)
    region = _inside_regions(pred, held_points, levels)
    rot = _orientation_fold(result, held, settings, levels, rng) if held.measurement.measures_orientation else None
    return held_points - mean, std, inside, region, rot


def _model_error_kind(result: CalibrationUncertainty) -> str:
    """``field``, ``independent`` or ``none``: what the residual source drew in `result`."""
    if not sources_with_role(result.settings.sources, "model_error") or result.model_adequacy.adequate:
        return "none"
    me_field = result.model_error_field
    return "field" if me_field is not None and me_field.identified else "independent"


def _check_frame(calibration: IdentificationResult, held: Campaign, std: Array, coverage: float) -> FrameComparison:
    """Compare the validation campaign's frame with the calibration's; refuse a move.

    The calibrated model predicts every held-out position in the training campaign's frame; a
    rigid fit of those predictions to the measured positions is a moved instrument when it
    displaces the points by more than the statement's p-region radius (sqrt of the chi-square
    3-quantile times the RMS predictive standard uncertainty of the first chunk) or the
    training residual RMS, whichever is larger.

    Raises
    ------
    InputError
        The frame moved beyond that limit (names the move in mm and mrad).
    """
    layout = calibration.model.layout
    predicted = forward_points(layout, calibration.estimate, held.joint_positions)
    u_axis = float(np.sqrt(np.mean(std**2)))
    radius = float(np.sqrt(chi2.ppf(coverage, len(AXES)))) * u_axis
    comparison = compare_frames(predicted, _held_out_positions(held), max(radius, calibration.rms_after))
    if comparison.moved:
        msg = (
            f"the validation campaign was measured in another set-up than the calibration campaign (same frame "
            f"name {held.frame_id!r}): {comparison.describe()}; its errors would be the move, not the "
            "calibration's: validate it with a campaign of the same set-up, or calibrate that set-up's base"
        )
        raise InputError(msg)
    return comparison


def validate_holdout(
    model: RobotModel,
    campaign: Campaign,
    *,
    splits: Sequence[HoldoutSplit] | None = None,
    validation_campaign: Campaign | None = None,
    settings: UncertaintySettings | None = None,
    lambda_: str | float = "auto",
    trials: int = 5000,
    coverage: float = 0.95,
    seed: int = 0,
    workers: int = 1,
    levels: Sequence[float] = RELIABILITY_LEVELS,
    progress: Callable[[str], None] | None = None,
    backend: str = "numpy",
    adjust_statement: StatementAdjustment | None = None,
) -> HoldoutValidation:
    """Calibrate on training poses, predict held-out measurements, count what the intervals hold.

    Parameters
    ----------
    model : RobotModel
        Nominal model.
    campaign : Campaign
        Calibration campaign (joint readings [rad], points [m]).
    splits : sequence of HoldoutSplit, optional
        Folds of `campaign` (:func:`split_campaign`); required unless `validation_campaign`.
    validation_campaign : Campaign, optional
        A second campaign measured in the same frame (same tracker set-up): every pose of
        it is held out and `campaign` is used whole for training.
    settings : UncertaintySettings, optional
        Sources and noise models, as for :func:`evaluate_uncertainty`.
    lambda_ : {"auto", "gcv"} or float
    trials, workers : int
        Monte Carlo trials per fold; worker processes.
    coverage : float
        Coverage probability p of the intervals checked.
    seed : int
        Root seed (Monte Carlo and the held-out measurement noise).
    levels : sequence of float
        Coverage probabilities of the reliability curve.
    progress : callable, optional
        Called with a one-line status per fold.
    backend : str
        Trial kernels (:attr:`~robocal_uncertainty.uncertainty.EvaluationSettings.backend`).
    adjust_statement : callable, optional
        ``adjust_statement(result, calibration, train)``: the statement checked in place of each
        Monte Carlo chunk's `result` (e.g. with the model-error field's correction,
        :func:`~robocal_uncertainty.uncertainty.field_kriging.corrected_uncertainty`).

    Returns
    -------
    HoldoutValidation

    Raises
    ------
    ConfigError
        Neither or both of `splits` and `validation_campaign`; bad levels.
    InputError
        A validation campaign in another frame or with other joints.
    """
    settings = settings or UncertaintySettings()
    levels_arr = _levels(levels, coverage)
    campaign = campaign.reorder_joints(model.joint_names)
    folds, mode = _folds(model, campaign, splits, validation_campaign)
    pooled = _Pooled()
    fold_results = []
    frame_comparison: FrameComparison | None = None
    chunk = _check_memory(model, folds, trials)
    run = _FoldRun(settings, levels_arr, seed, chunk, mode, workers, trials, coverage, backend, adjust_statement)
    for f, (train, held_all) in enumerate(folds):
        calibration = identify(model, train, lambda_=lambda_)
        result, comparison = _run_fold(model, train, held_all, calibration, f, run, pooled)
        frame_comparison = comparison if comparison is not None else frame_comparison
        fold_results.append(_fold_result(result, calibration, train, held_all.n_poses))
        if progress is not None:
            progress(f"fold {f + 1}/{len(folds)}: {_fold_line(train, held_all, calibration)}")
        frame_id = result.frame_id
    record = (tuple(fold_results), frame_id, tuple(settings.sources), seed, mode, frame_comparison)
    return _pooled_validation(pooled, levels_arr, coverage, record)


def _fold_line(train: Campaign, held: Campaign, calibration: IdentificationResult) -> str:
    """A fold's progress line (after its number)."""
    n_train, n_held, rms = train.n_poses, held.n_poses, calibration.rms_after
    return f"{n_train} training poses, {n_held} held out, residual RMS {rms * 1e3:.4f} mm"


def _levels(levels: Sequence[float], coverage: float) -> Array:
    """The reliability curve's coverage levels with `coverage` among them, sorted; all in (0, 1)."""
    levels_arr = np.asarray(sorted({float(v) for v in levels} | {float(coverage)}))
    if not ((levels_arr > 0) & (levels_arr < 1)).all():
        raise ConfigError(f"coverage levels must lie in (0, 1), got {levels_arr.tolist()}")
    return levels_arr


def _pooled_validation(
    pooled: _Pooled,
    levels_arr: Array,
    coverage: float,
    record: tuple[tuple[FoldResult, ...], str, tuple[str, ...], int, str, FrameComparison | None],
) -> HoldoutValidation:
    """The validation pooled over every fold and chunk (`record`: folds, frame id, sources, seed,
    mode and frame comparison, as recorded)."""
    folds, frame_id, sources, seed, mode, frame_comparison = record
    err = np.concatenate(pooled.errors)
    sd = np.concatenate(pooled.stds)
    reg_all = np.concatenate(pooled.region_inside, axis=1)
    at = int(np.flatnonzero(np.isclose(levels_arr, coverage))[0])
    axes = _axis_validations(AXES, err, sd, np.concatenate(pooled.inside, axis=1), at)
    orientation_axes: tuple[AxisValidation, ...] = ()
    if pooled.rot_errors:
        r_ins = np.concatenate(pooled.rot_inside, axis=1)
        r_err, r_sd = np.concatenate(pooled.rot_errors), np.concatenate(pooled.rot_stds)
        orientation_axes = _axis_validations(("rx", "ry", "rz"), r_err, r_sd, r_ins, at)
    return HoldoutValidation(
        orientation_axes=orientation_axes,
        coverage_probability=float(coverage),
        levels=levels_arr,
        axes=axes,
        region_inside_fraction=float(reg_all[at].mean()),
        region_reliability=reg_all.mean(axis=1),
        errors=err,
        standard_uncertainties=sd,
        folds=folds,
        frame_id=frame_id,
        sources=sources,
        seed=seed,
        mode=mode,
        frame_comparison=frame_comparison,
    )


@dataclass
class _Pooled:
    """Per-chunk statistics of every fold, pooled at the end (lists of arrays)."""

    errors: list[Array] = field(default_factory=list)
    stds: list[Array] = field(default_factory=list)
    inside: list[NDArray[np.bool_]] = field(default_factory=list)
    region_inside: list[NDArray[np.bool_]] = field(default_factory=list)
    rot_errors: list[Array] = field(default_factory=list)
    rot_stds: list[Array] = field(default_factory=list)
    rot_inside: list[NDArray[np.bool_]] = field(default_factory=list)


def _folds(
    model: RobotModel,
    campaign: Campaign,
    splits: Sequence[HoldoutSplit] | None,
    validation_campaign: Campaign | None,
) -> tuple[list[tuple[Campaign, Campaign]], str]:
    """The (training, held-out) campaigns and the mode (``campaign``, ``k-fold``, ``split``)."""
    if validation_campaign is not None:
        if splits is not None:
            raise ConfigError("give either splits or a validation campaign, not both")
        held = validation_campaign.reorder_joints(model.joint_names)
        if (held.frame, held.frame_id) != (campaign.frame, campaign.frame_id):
            msg = (
                f"validation campaign points are in frame {held.frame_id!r} ({held.frame}), the calibration "
                f"campaign's in {campaign.frame_id!r} ({campaign.frame}): they must share one tracker set-up"
            )
            raise InputError(msg)
        return [(campaign, held)], "campaign"
    if not splits:
        raise ConfigError("give splits (hold-out fraction, training poses or k folds) or a validation campaign")
    folds = [(campaign.subset(s.train), campaign.subset(s.held_out)) for s in splits]
    return folds, "k-fold" if len(splits) > 1 else "split"


def _check_memory(model: RobotModel, folds: list[tuple[Campaign, Campaign]], trials: int) -> int:
    """Held-out poses per Monte Carlo chunk; refuses a trial count whose largest chunk would not fit in memory."""
    chunk = holdout_chunk_size(trials)
    largest = min(chunk, max(held.n_poses for _, held in folds))
    check_fits(
        validation_bytes(
            int(trials),
            largest,
            model.layout.size,
            n_poses=max(train.n_poses for train, _ in folds),
            n_joints=model.n_joints,
        ),
        f"--trials {int(trials)} with {largest} held-out poses per Monte Carlo",
        "use fewer --trials",
    )
    return chunk


@dataclass(frozen=True)
class _FoldRun:
    """What every fold's Monte Carlo shares (see :func:`validate_holdout`)."""

    settings: UncertaintySettings
    levels: Array
    seed: int
    chunk: int
    mode: str
    workers: int
    trials: int
    coverage: float
    backend: str
    adjust_statement: StatementAdjustment | None = None


def _run_fold(
    model: RobotModel,
    train: Campaign,
    held_all: Campaign,
    calibration: IdentificationResult,
    f: int,
    run: _FoldRun,
    pooled: _Pooled,
) -> tuple[CalibrationUncertainty, FrameComparison | None]:
    """One fold's Monte Carlo, chunk by chunk, its statistics appended to `pooled`."""
    settings, seed, chunk = run.settings, run.seed, run.chunk
    n_held = held_all.n_poses
    result: CalibrationUncertainty | None = None
    frame_comparison: FrameComparison | None = None
    # The held-out poses in chunks of a size fixed by the trial count: peak memory does not
    # grow with their number (the Monte Carlo of a chunk holds trials x poses values).
    for c, lo in enumerate(range(0, n_held, chunk)):
        held = held_all if n_held <= chunk else held_all.subset(np.arange(lo, min(n_held, lo + chunk)))
        result = evaluate_uncertainty(
            model,
            train,
            held.joint_positions,
            EvaluationSettings(
                uncertainty=settings,
                trials=run.trials,
                coverage=run.coverage,
                seed=seed + f if c == 0 else _chunk_seed(seed, f, c),
                orientation=held.measurement.measures_orientation,
                backend=run.backend,
            ),
            calibration=calibration,
            run=RunContext(workers=run.workers),
            per_pose=True,  # each held-out pose is checked alone (_inside_regions draws its regions)
        )
        if run.adjust_statement is not None:
            result = run.adjust_statement(result, calibration, train)
        stats = _chunk_statistics(result, held, settings, run.levels, seed, f, c)
        if run.mode == "campaign" and c == 0:
            frame_comparison = _check_frame(calibration, held_all, stats[1], run.coverage)
        pooled.errors.append(stats[0])
        pooled.stds.append(stats[1])
        pooled.inside.append(stats[2])
        pooled.region_inside.append(stats[3])
        if stats[4] is not None:
            pooled.rot_errors.append(stats[4][0])
            pooled.rot_stds.append(stats[4][1])
            pooled.rot_inside.append(stats[4][2])
    assert result is not None
    if result.not_converged:
        # The trials do not re-identify the calibration: no statement to validate.
        msg = f"fold {f + 1}: the Monte Carlo did not converge to a statement: {result.not_converged[0]}"
        raise ConvergenceError(msg)
    return result, frame_comparison


def _fold_result(
    result: CalibrationUncertainty, calibration: IdentificationResult, train: Campaign, n_held: int
) -> FoldResult:
    """What one fold records (its training, the adequacy and which model error was drawn)."""
    adequacy = result.model_adequacy
    return FoldResult(
        n_train=train.n_poses,
        n_held_out=n_held,
        rms_train_after=calibration.rms_after,
        lambda_=calibration.lambda_,
        model_adequate=adequacy.adequate,
        model_error_std=adequacy.standard_uncertainty,
        n_trials=result.n_trials,
        trustworthy=adequacy.trustworthy,
        trust_note=adequacy.trust_note,
        model_error=_model_error_kind(result),
    )


def _axis_validations(
    names: Sequence[str], err: Array, sd: Array, ins: NDArray[np.bool_], at: int
) -> tuple[AxisValidation, ...]:
    """Pooled per-axis statistics: errors and std (n, k), inside flags (L, n, k), `at` the level checked."""
    return tuple(
        AxisValidation(
            axis=name,
            rms_error=float(np.sqrt(np.mean(err[:, a] ** 2))),
            normalized_rms=float(np.sqrt(np.mean((err[:, a] / sd[:, a]) ** 2))),
            inside_fraction=float(ins[at, :, a].mean()),
            reliability=ins[:, :, a].mean(axis=1),
        )
        for a, name in enumerate(names)
    )
