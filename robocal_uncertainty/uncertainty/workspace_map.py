"""Uncertainty of the calibrated tool position over the workspace (a map).

One Monte Carlo trial perturbs the campaign, re-identifies the parameters once and
evaluates the tool position at every configuration of the map, so all configurations
share the same trials (and the same trials as :func:`evaluate_uncertainty` with the same
configurations, seed, settings and block size). Each block of trials is reduced where it
runs (see :func:`robocal_uncertainty.montecarlo.engine.reduce_trials`): the driver keeps
a mean and a 3 x 3 covariance per configuration, and model values only for the
configurations that get a JCGM 102 coverage region, so thousands of configurations fit
in memory.

Configurations come from :func:`grid_configurations`, :func:`sample_configurations`
(uniform inside the joint limits) or a file read by the caller.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.field_kriging import KrigingBasis, krige
from robocal_uncertainty.core.identification import IdentificationResult, identify
from robocal_uncertainty.core.joint_limits import check_joint_limits
from robocal_uncertainty.core.kinematics import forward_points
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.errors import ConfigError, ConvergenceError, InputError
from robocal_uncertainty.kernels import BackendInfo, resolve_backend
from robocal_uncertainty.montecarlo.engine import ProgressCallback, ReducedTrials, reduce_trials
from robocal_uncertainty.montecarlo.region import coverage_region
from robocal_uncertainty.montecarlo.streaming import Reduction
from robocal_uncertainty.uncertainty.calibration import (
    OUTPUT_FRAMES,
    CalibrationTrials,
    first_order_standard_uncertainty,
    prepare_calibration_trials,
)
from robocal_uncertainty.uncertainty.field_kriging import (
    calibration_kriging_basis,
    corrected_statement,
    output_rotation,
)
from robocal_uncertainty.uncertainty.memory import check_fits, grid_bytes, grid_size, map_bytes
from robocal_uncertainty.uncertainty.sources import UncertaintySettings
from robocal_uncertainty.uncertainty.statement_check import GUM_DISAGREEMENT_FACTOR, spread_disagreements

__all__ = [
    "DEFAULT_MAP_BLOCK_SIZE",
    "WorkspaceMap",
    "grid_configurations",
    "joint_ranges",
    "map_workspace",
    "sample_configurations",
]

Array = NDArray[np.float64]

POSITION_DIM = 3
"""Columns per configuration in a trial row: the tool position x, y, z [m]."""

GUM_CHECKED_CONFIGURATIONS = 16
"""Map configurations, spread evenly over the map, whose Monte Carlo spread is checked against
the first-order (GUM) statement as `evaluate` checks every test configuration: the trials are
shared by all configurations, so trials that diverged show at any of them."""

DEFAULT_MAP_BLOCK_SIZE = 1_000
"""Trials per block of a map: a block holds n_trials x 3 n_configurations values on a
worker (48 MB for 2 000 configurations), and 10^4 trials give ten blocks to share out."""


@dataclass(frozen=True, eq=False)
class WorkspaceMap:
    """Monte Carlo uncertainty of the calibrated tool position at many configurations.

    Attributes
    ----------
    configurations : ndarray, shape (n, n_joints) [rad]
        Joint positions, columns in ``joint_names`` order.
    joint_names : tuple of str
    positions : ndarray, shape (n, 3) [m]
        Tool position of the calibrated model (the calibration's estimate), output frame.
    mean : ndarray, shape (n, 3) [m]
        Mean of the Monte Carlo tool positions, output frame.
    covariance : ndarray, shape (n, 3, 3) [m^2]
        Covariance (ddof=1) of the Monte Carlo tool positions.
    standard_uncertainty : ndarray, shape (n, 3) [m]
        u(x), u(y), u(z).
    position_uncertainty : ndarray, shape (n,) [m]
        u_pos = sqrt(u(x)² + u(y)² + u(z)²) = sqrt(trace of the covariance).
    reach : ndarray, shape (n,) [m]
        Distance of the tool from the origin of the robot base frame (calibrated model).
    nearest_pose_distance : ndarray, shape (n,) [m]
        Distance of the tool from the nearest calibration pose's tool position (both
        from the calibrated model, output frame): how far the map extrapolates.
    region_configurations : ndarray of int, shape (m,)
        0-based configurations whose Monte Carlo values were kept for a JCGM 102 region.
    region_semi_axes : ndarray, shape (n, 3) [m]
        Semi-axes of the coverage ellipsoid at ``coverage_probability``, largest first;
        NaN where no values were kept or the region is degenerate.
    coverage_probability : float
    frame : {"measurement", "base"}
    frame_id : str
        TF name of the output frame.
    n_trials, n_dropped, seed, block_size : int
    settings : UncertaintySettings
    calibration : IdentificationResult
    warnings : tuple of str
    backend : BackendInfo or None
        The trial kernels that ran the trials (:mod:`robocal_uncertainty.kernels`).
    field_correction : ndarray, shape (n, 3) [m], or None
        With ``field_correction=True``: the model-error field's conditional mean (kriging), added
        to `positions` and `mean`; `covariance` is then the kriging covariance plus what the
        Monte Carlo carries beyond the field's own prior
        (:func:`~robocal_uncertainty.uncertainty.field_kriging.corrected_statement`).
    field_std_ratio : ndarray, shape (n,), or None
        Kriging std over the field's uncorrected std: near 0 next to a calibration pose, 1 far
        from all of them (there the correction knows nothing and the statement is the field's).
    """

    configurations: Array
    joint_names: tuple[str, ...]
    positions: Array
    mean: Array
    covariance: Array
    standard_uncertainty: Array
    position_uncertainty: Array
    reach: Array
    nearest_pose_distance: Array
    region_configurations: NDArray[np.intp]
    region_semi_axes: Array
    coverage_probability: float
    frame: str
    frame_id: str
    n_trials: int
    n_dropped: int
    seed: int
    block_size: int
    settings: UncertaintySettings
    calibration: IdentificationResult
    warnings: tuple[str, ...] = field(default=())
    backend: BackendInfo | None = None
    field_correction: Array | None = None
    field_std_ratio: Array | None = None

    def __len__(self) -> int:
        return int(self.configurations.shape[0])

    @property
    def order(self) -> NDArray[np.intp]:
        """0-based configuration indices by u_pos, largest first (ties by index)."""
        return np.argsort(-self.position_uncertainty, kind="stable")


def joint_ranges(model: RobotModel, limits: ArrayLike | None = None) -> Array:
    """Joint ranges to sample, shape (n_joints, 2) [rad]: ``limits`` checked, or the model's."""
    if limits is None:
        return np.array(model.joint_limits, dtype=np.float64)
    ranges = np.asarray(limits, dtype=np.float64)
    if ranges.shape != (model.n_joints, 2) or not np.isfinite(ranges).all() or (ranges[:, 0] > ranges[:, 1]).any():
        msg = f"joint ranges must be finite (low, high) rows of shape ({model.n_joints}, 2), got {np.shape(limits)}"
        raise ConfigError(msg)
    check_joint_limits(model, ranges.T, what="joint range bound", degrees_hint=None)
    return ranges


def sample_configurations(
    model: RobotModel, n: int, *, rng: np.random.Generator, limits: ArrayLike | None = None
) -> Array:
    """Configurations drawn uniformly inside the joint ranges.

    Parameters
    ----------
    model : RobotModel
    n : int
        Number of configurations (>= 1).
    rng : numpy.random.Generator
    limits : array_like, shape (n_joints, 2) [rad], optional
        Ranges inside the model's joint limits (e.g. the campaign's span); default the limits.

    Returns
    -------
    ndarray, shape (n, n_joints) [rad]
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        msg = f"number of configurations must be an integer >= 1, got {n!r}"
        raise ConfigError(msg)
    ranges = joint_ranges(model, limits)
    return np.asarray(rng.uniform(ranges[:, 0], ranges[:, 1], size=(int(n), model.n_joints)), dtype=np.float64)


def _grouped(n: int) -> str:
    """``15 625 000 000``: thousands grouped with spaces."""
    return f"{n:,}".replace(",", " ")


def grid_configurations(model: RobotModel, steps: int | Sequence[int], *, limits: ArrayLike | None = None) -> Array:
    """A full grid over the joint ranges: ``steps[j]`` evenly spaced values of joint j.

    Parameters
    ----------
    model : RobotModel
    steps : int or sequence of int, length n_joints
        Values per joint (>= 1; 1 takes the middle of the range, e.g. for the last
        joint, which does not move a tool point on its axis).
    limits : array_like, shape (n_joints, 2) [rad], optional
        Ranges inside the model's joint limits; default the limits.

    Returns
    -------
    ndarray, shape (prod(steps), n_joints) [rad]
        The first joint varies slowest.
    """
    counts = [steps] * model.n_joints if isinstance(steps, (int, np.integer)) else list(steps)
    if len(counts) != model.n_joints or any(
        isinstance(c, bool) or not isinstance(c, (int, np.integer)) or c < 1 for c in counts
    ):
        msg = f"grid steps must be {model.n_joints} integers >= 1 (one per joint), got {steps!r}"
        raise ConfigError(msg)
    n = grid_size([int(c) for c in counts])
    check_fits(
        grid_bytes(n, model.n_joints),
        f"a grid of {' x '.join(str(int(c)) for c in counts)} = {_grouped(n)} configurations",
        "use fewer values per joint (--grid), or --configurations N random ones",
    )
    ranges = joint_ranges(model, limits)
    axes = [
        np.linspace(lo, hi, int(c)) if c > 1 else np.array([0.5 * (lo + hi)]) for (lo, hi), c in zip(ranges, counts)
    ]
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.stack([m.ravel() for m in mesh], axis=1)


def _check_configurations(model: RobotModel, configurations: ArrayLike) -> Array:
    q = np.asarray(configurations, dtype=np.float64)
    if q.ndim != 2 or q.shape[0] < 1 or q.shape[1] != model.n_joints:
        msg = (
            f"configurations must have shape (n, {model.n_joints}) "
            f"({', '.join(model.joint_names)}), got {np.shape(configurations)}"
        )
        raise ConfigError(msg)
    if not np.isfinite(q).all():
        raise InputError("configurations contain NaN or inf")
    check_joint_limits(model, q, what="map configuration")
    return q


def _check_regions(regions: Sequence[int], n: int) -> NDArray[np.intp]:
    values = list(regions)
    for value in values:
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 0 <= value < n:
            msg = f"region configuration {value!r} is not a 0-based index in [0, {n})"
            raise ConfigError(msg)
    return np.array(sorted({int(i) for i in values}), dtype=np.intp)


def _calibrated_points(calibration: IdentificationResult, joints: Array, *, in_base: bool) -> Array:
    params = np.array(calibration.estimate, dtype=np.float64)
    if in_base:
        b0 = calibration.model.layout.base_index
        params[b0 : b0 + 6] = 0.0  # the tool in the robot base frame
    return np.asarray(forward_points(calibration.model.layout, params, joints), dtype=np.float64)


def _nearest_distance(points: Array, references: Array) -> Array:
    """Distance of each point (n, 3) to the nearest reference (m, 3), in slices of rows."""
    out = np.empty(points.shape[0])
    for lo in range(0, points.shape[0], 4096):
        diff = points[lo : lo + 4096, None, :] - references[None, :, :]
        out[lo : lo + 4096] = np.sqrt((diff * diff).sum(axis=-1).min(axis=1))
    return out


def _check_against_gum(
    model: RobotModel,
    campaign: Campaign,
    q: Array,
    std: Array,
    settings: UncertaintySettings,
    calibration: IdentificationResult,
    frame: str,
) -> None:
    """Refuse a map whose trials did not re-identify the calibration (see :mod:`.statement_check`)."""
    picked = np.unique(np.linspace(0, q.shape[0] - 1, min(GUM_CHECKED_CONFIGURATIONS, q.shape[0])).round().astype(int))
    gum_std = first_order_standard_uncertainty(model, campaign, q[picked], settings, calibration, frame)
    if gum_std is None:
        return
    problems = spread_disagreements(std[picked], gum_std, [f"map configuration {int(i)}" for i in picked])
    if problems:
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        msg = (
            f"the Monte Carlo did not converge to a map: {problems[0]}{more}; its trials do not re-identify the "
            f"calibration's solution (honest runs stay within a factor {GUM_DISAGREEMENT_FACTOR:g}; causes: a unit "
            "slip, a wrong robot model, or too few poses for the model error)"
        )
        raise ConvergenceError(msg)


def map_workspace(
    model: RobotModel,
    campaign: Campaign,
    configurations: ArrayLike,
    *,
    settings: UncertaintySettings | None = None,
    calibration: IdentificationResult | None = None,
    lambda_: str | float = "auto",
    accept_unconverged: bool = False,
    trials: int = 10_000,
    seed: int = 0,
    frame: str = "measurement",
    coverage: float = 0.95,
    regions: Sequence[int] = (),
    block_size: int = DEFAULT_MAP_BLOCK_SIZE,
    chunk_blocks: int = 1,
    executor: object | None = None,
    workers: int = 1,
    progress: ProgressCallback | None = None,
    backend: str = "numpy",
    field_correction: bool = False,
) -> WorkspaceMap:
    """Monte Carlo uncertainty of the calibrated tool position at many configurations.

    Parameters
    ----------
    model, campaign : RobotModel, Campaign
        Nominal model; calibration data (joint readings [rad], points [m]).
    configurations : array_like, shape (n, n_joints) [rad]
        Where to evaluate, inside the joint limits (:func:`grid_configurations`, :func:`sample_configurations`).
    settings : UncertaintySettings, optional
        Sources and their models; default as :func:`evaluate_uncertainty`.
    calibration : IdentificationResult, optional
        An existing calibration of `campaign`; else identified with `lambda_` and `accept_unconverged`
        (an identification that did not converge is used instead of raising).
    trials, seed : int
        Monte Carlo trials (fixed, >= 2; a region needs more, e.g. 11 at p = 0.95; JCGM 101
        asks for 10^4 or more); root seed, the map is reproducible from it.
    frame : {"measurement", "base"}
        Output frame of the positions (see :func:`evaluate_uncertainty`).
    coverage : float
        Coverage probability of the JCGM 102 regions.
    regions : sequence of int
        0-based configurations whose Monte Carlo values (3 x trials each) are kept for a coverage
        region; the others keep only their mean and covariance.
    block_size, chunk_blocks : int
        Trials per random stream (part of the result's identity, as in
        :func:`evaluate_uncertainty`); blocks per task (never changes the result).
    executor, workers, progress, backend
        ``concurrent.futures`` executor or ``dask.distributed.Client`` for the blocks; local
        processes without one (never change the result); ``progress(done, target)`` after each
        chunk; trial kernels (:attr:`~robocal_uncertainty.uncertainty.EvaluationSettings.backend`,
        the same result to rounding).
    field_correction : bool
        Add the model-error field's conditional mean given the calibration residuals (kriging,
        :mod:`~robocal_uncertainty.uncertainty.field_kriging`) to every position, with its
        covariance in the statement, and record the std ratio per configuration.

    Raises
    ------
    ConfigError, InputError
        Bad settings, frame or region indices; configurations outside the joint limits or not finite.
    ConvergenceError
        The trials' spread disagrees with the first-order (GUM) statement by more than
        :data:`~.statement_check.GUM_DISAGREEMENT_FACTOR` at a checked configuration
        (:data:`GUM_CHECKED_CONFIGURATIONS`): they did not re-identify the calibration.
    """
    settings = settings or UncertaintySettings()
    _check_map_settings(frame, trials, coverage)
    q = _check_configurations(model, configurations)
    kept_configs = _check_regions(regions, q.shape[0])
    campaign = campaign.reorder_joints(model.joint_names)
    _check_map_memory(model, campaign, q.shape[0], trials, kept_configs, (block_size, chunk_blocks, executor, workers))
    if calibration is None:
        calibration = identify(model, campaign, lambda_=lambda_, accept_unconverged=accept_unconverged)
    trial_block = prepare_calibration_trials(
        model, campaign, q, settings=settings, calibration=calibration, frame=frame, backend=backend
    )
    blocks = (block_size, chunk_blocks, workers, executor, progress)
    run = _run_map(trial_block, q.shape[0], kept_configs, seed, trials, blocks)
    record = (frame, coverage, seed, block_size, backend)
    wmap = _assemble_map(model, campaign, q, run, kept_configs, calibration, settings, record)
    if not field_correction:
        return wmap
    basis = calibration_kriging_basis(calibration, campaign, settings.tracker_noise, settings.encoder_noise)
    return _corrected_statement(wmap, basis)


def _corrected_statement(wmap: WorkspaceMap, basis: KrigingBasis) -> WorkspaceMap:
    """The map with the field's correction (:func:`~.field_kriging.corrected_statement`): positions
    and means moved by the kriged mean, the kriging covariance in place of the field's prior."""
    calibration = wmap.calibration
    kriged = krige(basis, calibration.model.layout, calibration.estimate, wmap.configurations)
    shift, covariance = corrected_statement(kriged, wmap.covariance, output_rotation(calibration, wmap.frame))
    std = np.sqrt(np.einsum("nii->ni", covariance))
    for array in (shift, covariance, std):
        array.setflags(write=False)
    return dataclasses.replace(
        wmap,
        positions=wmap.positions + shift,
        mean=wmap.mean + shift,
        covariance=covariance,
        standard_uncertainty=std,
        position_uncertainty=np.sqrt(np.einsum("nii->n", covariance)),
        field_correction=shift,
        field_std_ratio=kriged.std_ratio,
    )


def _run_map(
    trial_block: CalibrationTrials,
    n: int,
    kept_configs: NDArray[np.intp],
    seed: int,
    trials: int,
    blocks: tuple[int, int, int, object | None, ProgressCallback | None],
) -> ReducedTrials:
    """The map's trials reduced where they run: per configuration a mean and 3 x 3 covariance,
    Monte Carlo values of `kept_configs` only (`blocks`: block size, blocks per chunk, workers,
    executor, progress)."""
    block_size, chunk_blocks, workers, executor, progress = blocks
    groups = np.arange(POSITION_DIM * n).reshape(n, POSITION_DIM)
    return reduce_trials(
        trial_block,
        Reduction(groups, keep=groups[kept_configs].ravel()),
        seed=seed,
        n_trials=int(trials),
        block_size=block_size,
        chunk_blocks=chunk_blocks,
        workers=workers,
        executor=executor,
        progress=progress,
    )


def _assemble_map(
    model: RobotModel,
    campaign: Campaign,
    q: Array,
    run: ReducedTrials,
    kept_configs: NDArray[np.intp],
    calibration: IdentificationResult,
    settings: UncertaintySettings,
    record: tuple[str, float, int, int, str],
) -> WorkspaceMap:
    """The map from the reduced trials (checked against the GUM first; `record`: frame, coverage,
    seed, block size, backend as asked)."""
    frame, coverage, seed, block_size, backend = record
    n = q.shape[0]
    mean = run.moments.mean[: POSITION_DIM * n].reshape(n, POSITION_DIM)
    covariance = run.moments.group_covariance
    std = np.sqrt(np.einsum("nii->ni", covariance))
    _check_against_gum(model, campaign, q, std, settings, calibration, frame)
    warns: list[str] = list(calibration.warnings)
    semi = _region_semi_axes(run.kept, kept_configs, n, coverage, warns)
    in_base = frame == "base" or campaign.frame == "base"
    positions = _calibrated_points(calibration, q, in_base=frame == "base")
    poses = _calibrated_points(calibration, campaign.joint_positions, in_base=frame == "base")
    for array in (q, positions, mean, covariance, std, semi):
        array.setflags(write=False)
    return WorkspaceMap(
        configurations=q,
        joint_names=tuple(model.joint_names),
        positions=positions,
        mean=mean,
        covariance=covariance,
        standard_uncertainty=std,
        position_uncertainty=np.sqrt(np.einsum("nii->n", covariance)),
        reach=np.linalg.norm(_calibrated_points(calibration, q, in_base=True), axis=1),
        nearest_pose_distance=_nearest_distance(positions, poses),
        region_configurations=kept_configs,
        region_semi_axes=semi,
        coverage_probability=float(coverage),
        frame=frame,
        frame_id=model.base_frame_id if in_base else campaign.frame_id,
        n_trials=run.n_trials,
        n_dropped=run.n_dropped,
        seed=seed,
        block_size=block_size,
        settings=settings,
        calibration=calibration,
        warnings=tuple(warns),
        backend=resolve_backend(backend),
    )


def _check_map_settings(frame: str, trials: int, coverage: float) -> None:
    """Refuse an output frame, trial count or coverage probability a map cannot have."""
    if frame not in OUTPUT_FRAMES:
        msg = f"output frame must be one of {', '.join(OUTPUT_FRAMES)}, got {frame!r}"
        raise ConfigError(msg)
    if isinstance(trials, bool) or not isinstance(trials, (int, np.integer)) or trials < 2:
        msg = f"trials must be an integer >= 2 for a map, got {trials!r}"
        raise ConfigError(msg)
    if isinstance(coverage, bool) or not isinstance(coverage, (int, float)) or not 0.0 < coverage < 1.0:
        msg = f"coverage probability must be in (0, 1), got {coverage!r}"
        raise ConfigError(msg)


def _check_map_memory(
    model: RobotModel,
    campaign: Campaign,
    n: int,
    trials: int,
    kept_configs: NDArray[np.intp],
    run: tuple[int, int, object | None, int],
) -> None:
    """Refuse a map whose blocks (and kept region values) would not fit in memory (`run`: block
    size, blocks per chunk, executor, workers)."""
    block_size, chunk_blocks, executor, workers = run
    rows = min(int(block_size), int(trials)) * max(1, int(chunk_blocks))
    check_fits(
        map_bytes(
            n,
            model.n_joints,
            campaign.n_poses,
            block_rows=rows,
            workers=1 if executor is not None else int(workers),
            n_trials=int(trials),
            n_regions=int(kept_configs.size),
        ),
        f"a map of {_grouped(n)} configurations x {_grouped(int(trials))} trials ({_grouped(rows)} trials per "
        f"block, {int(workers)} worker{'s' if int(workers) != 1 else ''}"
        f"{f', {kept_configs.size} with a region' if kept_configs.size else ''})",
        "use fewer configurations, a smaller --block-size, fewer --workers"
        + (", or fewer --trials or --regions" if kept_configs.size else ""),
    )


def _region_semi_axes(kept: Array, kept_configs: NDArray[np.intp], n: int, coverage: float, warns: list[str]) -> Array:
    """Semi-axes of the JCGM 102 regions, shape (n, 3) (NaN without a region); a region that
    cannot be formed is a line appended to `warns`."""
    semi = np.full((n, POSITION_DIM), np.nan)
    for slot, i in enumerate(kept_configs):
        values = kept[:, POSITION_DIM * slot : POSITION_DIM * (slot + 1)]
        try:
            region = coverage_region(values, coverage)
        except (InputError, ConfigError) as err:
            warns.append(f"map configuration {int(i)}: no coverage region ({err})")
            continue
        eig = np.clip(np.linalg.eigvalsh(region.covariance), 0.0, None)
        semi[i] = region.coverage_factor * np.sqrt(eig[::-1])
    return semi
