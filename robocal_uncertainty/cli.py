"""Command line: ``robocal-uncertainty <command>`` (also ``python -m robocal_uncertainty``).

Every command is a thin shell over the library: it parses arguments, calls the same
functions the tests and the ROS nodes call, and prints. A :class:`CalibError` ends the
command with its one-line message on stderr and exit status 1.
"""

from __future__ import annotations

import os

# Trials are batched into many small matrix products; BLAS threads only add synchronisation
# there (measured 2.7x slower on 2 cores). Parallelism comes from --workers processes.
# Must be set before numpy loads its BLAS; a user's explicit setting wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import json
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.errors import CalibError, ConfigError, InputError

__all__ = ["PAPER_TEST_JOINTS_DEG", "main"]

PAPER_TEST_JOINTS_DEG = (-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451)
"""The robot seed's test configuration (Table 2), degrees."""

DEMO_SOURCES = ("tracker", "encoder", "lambda", "n_poses", "pose_choice")


def _load_robot(name: str, *, base_known: bool | None = None) -> Any:
    from robocal_uncertainty.core.robot_config import load_robot_model, resolve_robot_config

    model = load_robot_model(resolve_robot_config(name))
    if base_known is not None:
        model = replace(model, base_known=base_known)
    return model


def _parse_joint_values(values: Sequence[str], n_joints: int, *, degrees: bool, what: str) -> NDArray[np.float64]:
    try:
        numbers = [float(v) for item in values for v in item.replace(",", " ").split()]
    except ValueError as err:
        msg = f"{what}: not a number ({err})"
        raise InputError(msg) from err
    if not numbers or len(numbers) % n_joints:
        msg = f"{what} must have {n_joints} values per configuration, got {len(numbers)}"
        raise ConfigError(msg)
    q = np.array(numbers).reshape(-1, n_joints)
    if not np.isfinite(q).all():
        msg = f"{what} contain NaN or inf"
        raise InputError(msg)
    return np.radians(q) if degrees else q


def _read_joints_file(path: str, n_joints: int, *, degrees: bool) -> NDArray[np.float64]:
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as err:
        msg = f"cannot read joints file {path}: {err.strerror}"
        raise InputError(msg) from err
    rows = [
        line.replace(";", ",").replace(",", " ").split()
        for line in text.splitlines()
        if line.strip() and not line.lstrip().startswith("#")
    ]
    try:
        q = np.array([[float(v) for v in row] for row in rows if not row[0][0].isalpha()])
    except ValueError as err:
        msg = f"joints file {path}: not a number ({err})"
        raise InputError(msg) from err
    if q.ndim != 2 or q.shape[1] != n_joints:
        msg = f"joints file {path} must have {n_joints} numbers per row, got shape {q.shape}"
        raise ConfigError(msg)
    if not np.isfinite(q).all():
        msg = f"joints file {path} contains NaN or inf"
        raise InputError(msg)
    return np.radians(q) if degrees else q


def _trials(text: str) -> int | str:
    if text == "auto":
        return "auto"
    try:
        value = int(text)
    except ValueError as err:
        msg = f"--trials must be a positive integer or 'auto', got {text!r}"
        raise ConfigError(msg) from err
    if value <= 0:
        msg = f"--trials must be a positive integer or 'auto', got {text!r}"
        raise ConfigError(msg)
    return value


def _progress_bar(enabled: bool, label: str) -> tuple[Callable[[int, int | None], None] | None, Callable[[], None]]:
    if not enabled:
        return None, lambda: None
    from tqdm import tqdm

    bar = tqdm(total=None, unit="trial", desc=label, file=sys.stderr, leave=False, dynamic_ncols=True)

    def update(done: int, target: int | None) -> None:
        if target is not None and bar.total != target:
            bar.total = target
        bar.update(done - bar.n)

    return update, bar.close


def _print_calibration(result: Any) -> None:
    print(
        f"Calibration of {result.model.name}: {result.n_poses} poses, "
        f"{int(result.estimated.sum())} parameters identified"
    )
    print(
        f"  lambda = {result.lambda_:.4g} ({result.lambda_method}), condition number "
        f"{result.condition_number:.3g}, {result.iterations} iterations, {result.message}"
    )
    print(
        f"  residual RMS {result.rms_before * 1e3:.4f} mm -> {result.rms_after * 1e3:.4f} mm, "
        f"max {result.max_before * 1e3:.4f} mm -> {result.max_after * 1e3:.4f} mm"
    )
    print("  parameter            nominal        estimate   1st-order std")
    kinds = result.model.layout.kinds
    for i, name in enumerate(result.parameter_names):
        if not result.estimated[i]:
            continue
        if kinds[i] == "length":
            print(
                f"  {name:<16} {result.nominal[i] * 1e3:12.4f} mm {result.estimate[i] * 1e3:12.4f} mm "
                f"{result.linearized_std[i] * 1e6:9.2f} um"
            )
        else:
            print(
                f"  {name:<16} {np.degrees(result.nominal[i]):12.5f} deg {np.degrees(result.estimate[i]):11.5f} deg "
                f"{np.degrees(result.linearized_std[i]) * 1e3:8.3f} mdeg"
            )
    if result.dependencies:
        print("  not identifiable from position data (kept at nominal):")
        for dep in result.dependencies:
            print(f"    {dep}")
    for warning in result.warnings:
        print(f"  warning: {warning}")


def _print_adequacy(result: Any) -> None:
    ad = result.model_adequacy
    if ad.adequate:
        print(
            f"Model adequacy: residuals consistent with the stated tracker and encoder noise "
            f"(p = {ad.p_value:.3g}); no model error left for the residual source"
        )
    else:
        u = ", ".join(f"{v * 1e6:.1f}" for v in ad.standard_uncertainty)
        used = "included" if "residual" in result.settings.sources else "NOT included: add --sources ...,residual"
        print(
            f"Model adequacy: residuals exceed the stated noise (p = {ad.p_value:.3g}); model error "
            f"u = ({u}) um per measurement-frame axis, {used}"
        )


def _cmd_simulate(args: argparse.Namespace) -> int:
    from robocal_uncertainty.app import simulate
    from robocal_uncertainty.core import EncoderNoise, SimulationSettings, TrackerNoise

    model = _load_robot(args.robot)
    settings = SimulationSettings(
        n_poses=args.poses,
        frame=args.frame,
        tracker_noise=TrackerNoise(a=args.tracker_noise_um * 1e-6, b=args.tracker_noise_um_per_m * 1e-6),
        encoder_noise=EncoderNoise(half_width=float(np.radians(args.encoder_noise_deg))),
    )
    files = simulate(model, settings, args.out, seed=args.seed, overwrite=args.force)
    print(
        f"wrote {files.campaign_path} ({files.simulation.campaign.n_poses} poses, points in the {args.frame} frame) "
        f"and truth {files.truth_path}"
    )
    return 0


def _cmd_import_csv(args: argparse.Namespace) -> int:
    from robocal_uncertainty.bagio import write_campaign
    from robocal_uncertainty.importers import read_tracker_csv

    campaign = read_tracker_csv(
        args.csv, length_unit=args.length_unit, angle_unit=args.angle_unit, skip_invalid=args.skip_invalid
    )
    write_campaign(args.out, campaign, overwrite=args.force)
    skipped = campaign.metadata.get("skipped_rows") or []
    print(
        f"wrote {args.out}: {campaign.n_poses} poses, joints {', '.join(campaign.joint_names)}, "
        f"points in the {campaign.frame} frame ({campaign.frame_id})"
        + (f", {len(skipped)} invalid rows skipped" if skipped else "")
    )
    return 0


def _campaign_and_robot(args: argparse.Namespace) -> tuple[Any, Any]:
    """Read the campaign (its reader warnings printed as ``warning:`` lines) and the robot;
    refuse campaign joint readings outside the robot's joint limits."""
    import warnings

    from robocal_uncertainty.bagio import read_campaign
    from robocal_uncertainty.core import check_joint_limits

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        campaign = read_campaign(args.campaign)
    notes = [str(w) for w in campaign.metadata.get("warnings") or ()]
    notes += [str(w.message) for w in caught if str(w.message) not in notes]
    for note in notes:
        print(f"warning: {note}", file=sys.stderr)
    model = _load_robot(args.robot, base_known=False if args.base_unknown else None)
    check_joint_limits(
        model,
        campaign.reorder_joints(model.joint_names).joint_positions,
        what=f"{args.campaign}: campaign pose",
        degrees_hint="the readings look like degrees (import-csv --angle-unit deg?)",
    )
    return campaign, model


def _test_joints(args: argparse.Namespace, model: Any) -> NDArray[np.float64]:
    from robocal_uncertainty.core import check_joint_limits

    if args.test_joints_file:
        q = _read_joints_file(args.test_joints_file, model.n_joints, degrees=args.degrees)
        what = f"{args.test_joints_file}: test configuration"
    elif args.test_joints:
        q = _parse_joint_values(args.test_joints, model.n_joints, degrees=args.degrees, what="--test-joints")
        what = "--test-joints configuration"
    else:
        raise ConfigError("give --test-joints or --test-joints-file")
    check_joint_limits(model, q, what=what, degrees_hint=None if args.degrees else "did you mean --degrees?")
    return q


def _lambda_arg(text: str) -> str | float:
    if text in ("auto", "gcv", "lcurve"):
        return text
    try:
        return float(text)
    except ValueError as err:
        msg = f"--lambda must be 'auto', 'gcv' or a number, got {text!r}"
        raise ConfigError(msg) from err


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from robocal_uncertainty.core import identify
    from robocal_uncertainty.core.calibration_file import write_calibration

    campaign, model = _campaign_and_robot(args)
    result = identify(model, campaign, lambda_=_lambda_arg(args.lambda_), accept_unconverged=args.accept_unconverged)
    _print_calibration(result)
    if args.json:
        write_calibration(args.json, result, robot=str(args.robot))
        print(f"wrote {args.json}")
    return 0


def _cmd_fk(args: argparse.Namespace) -> int:
    from robocal_uncertainty.app import tool_points
    from robocal_uncertainty.core import check_joint_limits
    from robocal_uncertainty.core.calibration_file import apply_calibration, read_calibration

    model = _load_robot(args.robot)
    if args.calibration:
        model = apply_calibration(model, read_calibration(args.calibration), where=f"calibration {args.calibration}")
    if args.joints_file:
        q = _read_joints_file(args.joints_file, model.n_joints, degrees=args.degrees)
        what = f"{args.joints_file}: configuration"
    elif args.joints:
        q = _parse_joint_values(args.joints, model.n_joints, degrees=args.degrees, what="--joints")
        what = "--joints configuration"
    else:
        raise ConfigError("give --joints or --joints-file")
    check_joint_limits(model, q, what=what, degrees_hint=None if args.degrees else "did you mean --degrees?")
    points = tool_points(model, q, calibrated=bool(args.calibration), frame=args.frame)
    print(
        f"# tool point of the {points.model} {model.name} model in frame {points.frame_id} ({points.frame} frame), mm"
    )
    print(f"# x_{points.frame_id} y_{points.frame_id} z_{points.frame_id}")
    for row in points.points:
        print(" ".join(f"{v * 1e3:.6f}" for v in row))
    if args.json:
        Path(args.json).write_text(json.dumps(points.to_dict(), indent=2) + "\n", encoding="utf-8")
    return 0


def _uncertainty_settings(args: argparse.Namespace, campaign: Any, sources: Sequence[str]) -> Any:
    from robocal_uncertainty.core import EncoderNoise, TrackerNoise
    from robocal_uncertainty.uncertainty import UncertaintySettings

    return UncertaintySettings(
        sources=tuple(sources),
        tracker_noise=TrackerNoise(a=args.tracker_noise_um * 1e-6, b=args.tracker_noise_um_per_m * 1e-6),
        encoder_noise=EncoderNoise(half_width=float(np.radians(args.encoder_noise_deg))),
        lambda_range=None if args.lambda_range is None else (args.lambda_range[0], args.lambda_range[1]),
        min_poses=args.min_poses,
        subset_size=args.subset_size,
    )


def _evaluation_options(args: argparse.Namespace, sources: Sequence[str], test_joints: NDArray[np.float64]) -> Any:
    """The :class:`EvaluationOptions` of the parsed uncertainty arguments."""
    from robocal_uncertainty.uncertainty import EvaluationOptions, parse_sources

    for option in ("budget_trials", "sweep_trials", "max_trials"):
        value = getattr(args, option)
        if value <= 0:
            msg = f"--{option.replace('_', '-')} must be a positive integer, got {value}"
            raise ConfigError(msg)
    return EvaluationOptions(
        lambda_=_lambda_arg(args.lambda_),
        uncertainty=_uncertainty_settings(args, None, parse_sources(list(sources))),
        test_joints=test_joints,
        trials=_trials(args.trials),
        seed=args.seed,
        coverage=args.coverage,
        max_trials=args.max_trials,
        output_frame=args.frame,
        accept_unconverged=args.accept_unconverged,
        budget=args.budget,
        budget_trials=args.budget_trials,
        sweeps=args.sweeps,
        sweep_trials=args.sweep_trials,
    )


def _timed_progress(enabled: bool, label: str) -> tuple[Callable[[int, int | None], None], Callable[[], float]]:
    """A progress callback (a bar on stderr when `enabled`) and a function that closes the bar
    and returns the seconds from now to the last progress report (the main Monte Carlo run)."""
    update, close = _progress_bar(enabled, label)
    start = time.perf_counter()
    last = [start]

    def progress(done: int, target: int | None) -> None:
        last[0] = time.perf_counter()
        if update is not None:
            update(done, target)

    def finish() -> float:
        close()
        return max(last[0] - start, 1e-9)

    return progress, finish


def run_evaluation(
    model: Any,
    campaign: Any,
    test_joints: NDArray[np.float64],
    *,
    sources: Sequence[str],
    args: argparse.Namespace,
    out_dir: Path,
    label: str,
) -> Any:
    """Evaluate through :func:`robocal_uncertainty.app.evaluate`, print and write the report:
    shared by ``evaluate``, ``demo`` and ``replay``. Returns the uncertainty result."""
    from robocal_uncertainty.app import evaluate

    options = _evaluation_options(args, sources, test_joints)
    progress, finish = _timed_progress(not args.no_progress, label)
    try:
        from robocal_uncertainty.montecarlo.executor import open_executor

        # --dask (evaluate only) or --workers: one executor for the main run, budget and sweeps.
        with open_executor(workers=args.workers, dask=getattr(args, "dask", None)) as executor:
            evaluation = evaluate(model, campaign, options, executor=executor, progress=progress)
    finally:
        elapsed = finish()
    _print_evaluation(evaluation, options, model, out_dir, elapsed, histograms=getattr(args, "histograms", None))
    return evaluation.uncertainty


def _print_evaluation(
    evaluation: Any, options: Any, model: Any, out_dir: Path, elapsed: float, *, histograms: int | str | None = None
) -> None:
    """Print an :class:`~robocal_uncertainty.app.Evaluation` and write its report."""
    from robocal_uncertainty.report import format_budget, format_table2, write_report

    result = evaluation.uncertainty
    _print_calibration(evaluation.calibration)
    print()
    _print_adequacy(result)
    print(f"Positions in frame {result.frame_id} ({result.frame} frame; --frame base|measurement)")
    print(format_table2(result))
    adaptive = result.adaptive
    if adaptive is not None:
        state = "converged" if adaptive.converged else "NOT converged"
        print(
            f"adaptive JCGM 101 7.9: {state} at {adaptive.n_dig} significant digits of u, "
            f"{adaptive.n_sequences} sequences of {adaptive.sequence_trials} trials"
        )
    print(f"{result.n_trials} trials in {elapsed:.1f} s ({result.n_trials / elapsed:.0f} trials/s)")
    if evaluation.budget:
        print()
        print(f"Uncertainty budget: each source alone, {options.budget_trials} trials each")
        print(format_budget(evaluation.budget))
    for warning in result.warnings:
        print(f"warning: {warning}")
    path = write_report(
        out_dir,
        result,
        robot_name=model.name,
        budget=dict(evaluation.budget) or None,
        sweeps=list(evaluation.sweeps) if options.sweeps else None,
        input_warnings=evaluation.input_warnings,
        histograms=histograms,
    )
    print(f"report written to {path}")


def _add_uncertainty_args(p: argparse.ArgumentParser, *, trials_default: str) -> None:
    p.add_argument(
        "--trials",
        default=trials_default,
        help="number of Monte Carlo trials, or 'auto' for the JCGM 101 adaptive procedure (default %(default)s)",
    )
    p.add_argument(
        "--max-trials", type=int, default=2_000_000, help="cap of the adaptive procedure (default %(default)s)"
    )
    p.add_argument("--coverage", type=float, default=0.95, help="coverage probability p (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="root seed of the random streams (default %(default)s)")
    p.add_argument("--lambda", dest="lambda_", default="auto", help="auto (L-curve corner), gcv, or a fixed value")
    p.add_argument(
        "--lambda-range",
        type=float,
        nargs=2,
        metavar=("LOW", "HIGH"),
        help="range of lambda for the 'lambda' source (default lambda*/5 .. 5 lambda*)",
    )
    p.add_argument("--min-poses", type=int, help="smallest pose count of the 'n_poses' source")
    p.add_argument("--subset-size", type=int, help="pose count of the 'pose_choice' source")
    p.add_argument(
        "--tracker-noise-um",
        type=float,
        default=5.0,
        help="tracker error half-width a per coordinate, um (default %(default)s, uniform)",
    )
    p.add_argument(
        "--tracker-noise-um-per-m",
        type=float,
        default=0.0,
        help="distance-proportional part b of the MPE a + b L, um/m (default %(default)s)",
    )
    p.add_argument(
        "--encoder-noise-deg",
        type=float,
        default=0.005,
        help="encoder error half-width, deg (default %(default)s, uniform)",
    )
    p.add_argument("--workers", type=int, default=1, help="worker processes (never changes the result)")
    p.add_argument(
        "--budget",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also run each source alone (uncertainty budget)",
    )
    p.add_argument(
        "--budget-trials", type=int, default=2000, help="trials per source of the budget (default %(default)s)"
    )
    p.add_argument(
        "--sweeps",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="uncertainty against lambda and against the number of equations (report plots)",
    )
    p.add_argument("--sweep-trials", type=int, default=300, help="trials per sweep point (default %(default)s)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument(
        "--histograms",
        type=_histogram_count,
        metavar="N|all",
        help="report: histogram figures for the first N test configurations, or all (default: all of up to 10, "
        "else the first 6 and the worst); not used by validate",
    )
    _add_frame_and_convergence_args(p)


def _histogram_count(text: str) -> int | str:
    if text == "all":
        return text
    try:
        count = int(text)
    except ValueError:
        count = -1
    if count < 0:
        msg = f"expected a count >= 0 or 'all', got {text!r}"
        raise argparse.ArgumentTypeError(msg)
    return count


def _add_frame_and_convergence_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--frame",
        choices=("measurement", "base"),
        default="measurement",
        help="frame of the output positions: the frame of the campaign's points (default), or the robot base "
        "frame (for a tracker campaign the base transform's uncertainty then does not enter)",
    )
    p.add_argument(
        "--accept-unconverged",
        action="store_true",
        help="use an identification that did not converge instead of stopping with an error",
    )


def _cmd_evaluate(args: argparse.Namespace) -> int:
    campaign, model = _campaign_and_robot(args)
    test_q = _test_joints(args, model)
    from robocal_uncertainty.uncertainty import parse_sources

    run_evaluation(
        model,
        campaign,
        test_q,
        sources=parse_sources(args.sources),
        args=args,
        out_dir=Path(args.out),
        label="evaluate",
    )
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from robocal_uncertainty.app import replay
    from robocal_uncertainty.pipeline import CollectorSettings

    model = _load_robot(args.robot, base_known=False if args.base_unknown else None)
    options = _evaluation_options(args, _sources_arg(args.sources), _test_joints(args, model))

    def log(cause: str, message: str) -> None:
        print(f"replay: dropped ({cause}): {message}", file=sys.stderr)

    progress, finish = _timed_progress(not args.no_progress, "replay")
    try:
        replayed = replay(
            args.bag,
            model,
            options,
            joint_topic=args.joint_topic,
            point_topic=args.point_topic,
            tracker_frame_id=args.tracker_frame,
            collector=CollectorSettings(
                window_s=args.window_s,
                joint_motion_threshold=args.joint_motion_threshold_rad,
                tracker_scatter_threshold=args.tracker_scatter_threshold_m,
                min_points=args.min_points,
            ),
            campaign_path=args.campaign_out,
            log=log,
            workers=args.workers,
            progress=progress,
        )
    finally:
        elapsed = finish()
    result = replayed.replay
    dropped = ", ".join(f"{k}: {v}" for k, v in sorted(result.dropped.items()) if v) or "none"
    print(f"replay of {args.bag}: {len(result.samples)} static poses found; dropped messages: {dropped}")
    if args.campaign_out:
        print(f"campaign written to {args.campaign_out}")
    _print_evaluation(
        replayed.evaluation, options, model, Path(args.out), elapsed, histograms=getattr(args, "histograms", None)
    )
    return 0


def _sources_arg(text: str) -> tuple[str, ...]:
    from robocal_uncertainty.uncertainty import parse_sources

    return tuple(parse_sources(text))


def _cmd_validate(args: argparse.Namespace) -> int:
    from robocal_uncertainty.app import validate
    from robocal_uncertainty.bagio import read_campaign
    from robocal_uncertainty.report.validation_report import format_validation, write_validation_report

    options = _evaluation_options(args, _sources_arg(args.sources), None)
    campaign, model = _campaign_and_robot(args)
    validation_campaign = read_campaign(args.validation_campaign) if args.validation_campaign else None
    validation = validate(
        model,
        campaign,
        options,
        train_poses=args.train_poses,
        holdout_fraction=args.holdout_fraction,
        k_folds=args.k_folds,
        validation_campaign=validation_campaign,
        workers=args.workers,
        progress=print,
    )
    print()
    print(format_validation(validation))
    out = write_validation_report(
        args.out,
        validation,
        extra={"campaign": str(args.campaign), "robot": str(args.robot), "trials": int(options.trials)},
    )
    print(f"report written to {out}")
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from robocal_uncertainty.core import SimulationSettings, simulate_campaign

    model = _load_robot("paper_arm")
    sim = simulate_campaign(model, SimulationSettings(n_poses=53), seed=args.seed)
    print("Demo: the seed's arm (Table 1), a simulated 53-pose campaign with tracker noise +-5 um and")
    print("encoder noise +-0.005 deg (uniform), evaluated at the seed's test joints")
    print(f"({', '.join(f'{v:g}' for v in PAPER_TEST_JOINTS_DEG)}) deg. Sources: {', '.join(DEMO_SOURCES)}.")
    print()
    test_q = np.radians(np.array(PAPER_TEST_JOINTS_DEG))[None, :]
    result = run_evaluation(
        model, sim.campaign, test_q, sources=DEMO_SOURCES, args=args, out_dir=Path(args.out), label="demo"
    )
    from robocal_uncertainty.core import forward_points

    truth = forward_points(model.layout, sim.true_model.parameter_vector(), test_q)[0]
    inside = [result.poses[0].axes[i].probabilistically_symmetric.contains(float(truth[i])) for i in range(3)]
    print(
        "simulated truth at the test joints: (" + ", ".join(f"{v * 1e3:.4f}" for v in truth) + ") mm; "
        f"inside the 95 % intervals (x, y, z): {inside}"
    )
    from robocal_uncertainty.report.table2 import format_seed_comparison

    print()
    print(format_seed_comparison(result))
    return 0


def _add_dask_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--dask",
        metavar="ADDRESS",
        help="run the trial blocks on a Dask cluster: scheduler address, or 'local' for a LocalCluster of "
        "--workers processes (needs the [dask] extra; never changes the result)",
    )


def _cmd_map(args: argparse.Namespace) -> int:
    from robocal_uncertainty.montecarlo.executor import open_executor
    from robocal_uncertainty.report.map_report import weakest_region, write_map_report
    from robocal_uncertainty.uncertainty.sources import parse_sources
    from robocal_uncertainty.uncertainty.workspace_map import grid_configurations, map_workspace, sample_configurations

    campaign, model = _campaign_and_robot(args)
    campaign = campaign.reorder_joints(model.joint_names)
    span = np.column_stack([campaign.joint_positions.min(axis=0), campaign.joint_positions.max(axis=0)])
    limits = span if args.within_campaign else None
    if args.from_file:
        q = _read_joints_file(args.from_file, model.n_joints, degrees=args.degrees)
    elif args.grid:
        q = grid_configurations(model, args.grid[0] if len(args.grid) == 1 else args.grid, limits=limits)
    else:
        q = sample_configurations(model, args.configurations, rng=np.random.default_rng(args.seed), limits=limits)
    settings = _uncertainty_settings(args, None, parse_sources(args.sources))
    progress, finish = _timed_progress(not args.no_progress, "map")
    try:
        with open_executor(workers=args.workers, dask=args.dask) as executor:
            wmap = map_workspace(
                model,
                campaign,
                q,
                settings=settings,
                lambda_=_lambda_arg(args.lambda_),
                accept_unconverged=args.accept_unconverged,
                trials=args.trials,
                seed=args.seed,
                frame=args.frame,
                coverage=args.coverage,
                regions=range(min(args.regions, len(q))),
                block_size=args.block_size,
                executor=executor,
                progress=progress,
            )
    finally:
        elapsed = finish()
    files = write_map_report(wmap, args.out)
    weak = weakest_region(wmap)
    print(f"{len(wmap)} configurations x {wmap.n_trials} trials in {elapsed:.1f} s; positions in frame {wmap.frame_id}")
    print(
        f"u_pos: median {weak.median_u * 1e6:.1f} um, 95th percentile {weak.p95_u * 1e6:.1f} um, "
        f"max {weak.max_u * 1e6:.1f} um"
    )
    worst = int(wmap.order[0])
    where = ", ".join(f"{v:.3f}" for v in wmap.positions[worst])
    print(f"weakest: configuration {worst + 1} at ({where}) m, reach {wmap.reach[worst]:.3f} m")
    for warning in wmap.warnings:
        print(f"warning: {warning}")
    print(f"map report written to {files.markdown.parent}")
    return 0


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="robocal-uncertainty",
        description="Robot arm calibration from laser-tracker points and its Monte Carlo uncertainty (JCGM 101).",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser(
        "demo", help="the main job on the embedded default: seed's arm, simulated 53-pose campaign, Table 2 and report"
    )
    p.add_argument("--out", default="robocal_report", help="report directory (default %(default)s)")
    _add_uncertainty_args(p, trials_default="20000")
    p.set_defaults(func=_cmd_demo)

    p = sub.add_parser("simulate", help="write a simulated campaign MCAP (truth in a sidecar .truth.json)")
    p.add_argument("--robot", default="paper_arm", help="robot YAML or shipped model name (default %(default)s)")
    p.add_argument("--out", required=True, help="campaign .mcap to write")
    p.add_argument("--poses", type=int, default=53)
    p.add_argument(
        "--frame",
        choices=("base", "tracker"),
        default="base",
        help="points in the robot base frame or in a tracker frame with an unknown base",
    )
    p.add_argument("--tracker-noise-um", type=float, default=5.0, help="tracker error half-width a, um (uniform)")
    p.add_argument("--tracker-noise-um-per-m", type=float, default=0.0, help="MPE distance part b, um/m")
    p.add_argument("--encoder-noise-deg", type=float, default=0.005, help="encoder error half-width, deg (uniform)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--force", action="store_true", help="overwrite an existing file")
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser("import-csv", help="convert a tracker CSV export into a campaign MCAP")
    p.add_argument("csv")
    p.add_argument("--out", required=True)
    p.add_argument("--length-unit", help="unit of length columns whose header states none (m, mm, um)")
    p.add_argument("--angle-unit", help="unit of joint columns whose header states none (rad, deg)")
    p.add_argument("--skip-invalid", action="store_true", help="drop invalid rows instead of failing")
    p.add_argument("--force", action="store_true")
    p.set_defaults(func=_cmd_import_csv)

    p = sub.add_parser("calibrate", help="identify the parameter errors from a campaign")
    p.add_argument("campaign")
    p.add_argument("--robot", required=True)
    p.add_argument("--lambda", dest="lambda_", default="auto", help="auto (L-curve corner), gcv, or a fixed value")
    p.add_argument("--json", help="write the result here (SI units)")
    p.add_argument(
        "--base-unknown",
        action="store_true",
        help="identify the base transform even if the robot config says it is known",
    )
    p.add_argument(
        "--accept-unconverged",
        action="store_true",
        help="report an identification that did not converge instead of stopping with an error",
    )
    p.set_defaults(func=_cmd_calibrate)

    p = sub.add_parser("fk", help="tool positions of the nominal or calibrated model")
    p.add_argument("--robot", required=True)
    p.add_argument("--calibration", help="calibration JSON from 'calibrate --json'")
    p.add_argument("--joints", nargs="+", help="joint values, n_joints per configuration")
    p.add_argument("--joints-file", help="CSV/whitespace file, one configuration per row")
    p.add_argument("--degrees", action="store_true", help="joint values are in degrees (default radians)")
    p.add_argument(
        "--frame",
        choices=("measurement", "base"),
        help="frame of the printed points: the measurement (tracker) frame when the calibration identified the "
        "base (default then), else the robot base frame",
    )
    p.add_argument("--json", help="also write both frames' points here (SI units)")
    p.set_defaults(func=_cmd_fk)

    p = sub.add_parser("evaluate", help="Monte Carlo uncertainty of the calibrated tool position")
    p.add_argument("campaign")
    p.add_argument("--robot", required=True)
    p.add_argument("--test-joints", nargs="+", help="joint values of the test configurations")
    p.add_argument("--test-joints-file")
    p.add_argument("--degrees", action="store_true")
    p.add_argument(
        "--sources",
        default="tracker,encoder",
        help="comma list of tracker, encoder, lambda, n_poses, pose_choice, residual, or all",
    )
    p.add_argument("--out", default="robocal_report")
    p.add_argument(
        "--base-unknown",
        action="store_true",
        help="identify the base transform even if the robot config says it is known",
    )
    _add_uncertainty_args(p, trials_default="auto")
    _add_dask_arg(p)
    p.set_defaults(func=_cmd_evaluate)

    p = sub.add_parser(
        "replay", help="replay a raw bag: detect static poses, calibrate, evaluate (same report as evaluate)"
    )
    p.add_argument("bag", help="raw recording: .mcap file or rosbag2 directory")
    p.add_argument("--robot", required=True)
    p.add_argument("--test-joints", nargs="+")
    p.add_argument("--test-joints-file")
    p.add_argument("--degrees", action="store_true")
    p.add_argument("--sources", default="tracker,encoder")
    p.add_argument("--out", default="robocal_report")
    p.add_argument(
        "--base-unknown",
        action="store_true",
        help="identify the base transform even if the robot config says it is known",
    )
    p.add_argument("--joint-topic", default="/joint_states")
    p.add_argument("--point-topic", default="/tracker/point")
    p.add_argument("--tracker-frame", help="frame_id of valid tracker points (default: the most frequent)")
    p.add_argument("--window-s", type=float, default=0.5, help="static window length, s (default %(default)s)")
    p.add_argument("--joint-motion-threshold-rad", type=float, default=5e-4, help="max joint motion in the window, rad")
    p.add_argument(
        "--tracker-scatter-threshold-m", type=float, default=1e-4, help="max tracker scatter in the window, m"
    )
    p.add_argument("--min-points", type=int, default=10, help="min tracker points per static window")
    p.add_argument("--campaign-out", help="also write the collected campaign MCAP here")
    _add_uncertainty_args(p, trials_default="auto")
    p.set_defaults(func=_cmd_replay)

    p = sub.add_parser(
        "validate",
        help="prove the uncertainty statement: calibrate on some poses, check the coverage of held-out measurements",
    )
    p.add_argument("campaign")
    p.add_argument("--robot", required=True)
    split = p.add_argument_group("what is held out (default: --holdout-fraction 0.25)")
    split.add_argument("--train-poses", type=int, help="calibrate on this many random poses, hold out the rest")
    split.add_argument("--holdout-fraction", type=float, help="fraction of the poses held out at random")
    split.add_argument("--k-folds", type=int, help="k-fold cross-validation: every pose held out once")
    split.add_argument("--validation-campaign", help="a second campaign of the same tracker set-up, held out whole")
    p.add_argument(
        "--sources",
        default="tracker,encoder,residual",
        help="sources of the statement under test (default %(default)s)",
    )
    p.add_argument("--out", default="robocal_validation", help="report directory (default %(default)s)")
    p.add_argument(
        "--base-unknown",
        action="store_true",
        help="identify the base transform even if the robot config says it is known",
    )
    _add_uncertainty_args(p, trials_default="5000")
    p.set_defaults(func=_cmd_validate)

    p = sub.add_parser("map", help="uncertainty map over the workspace: u at many configurations, where it is weakest")
    p.add_argument("campaign")
    p.add_argument("--robot", required=True)
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--configurations", type=int, default=1000, help="uniform random configurations (default %(default)s)"
    )
    where.add_argument(
        "--grid", type=int, nargs="+", metavar="STEPS", help="grid: values per joint (one for all, or one per joint)"
    )
    where.add_argument("--from-file", help="CSV/whitespace file, one configuration per row")
    p.add_argument("--degrees", action="store_true", help="--from-file values are in degrees (default radians)")
    p.add_argument(
        "--within-campaign", action="store_true", help="sample inside the campaign's joint span, not the joint limits"
    )
    p.add_argument("--sources", default="tracker,encoder", help="comma list of sources, or all (default %(default)s)")
    p.add_argument("--trials", type=int, default=10_000, help="Monte Carlo trials (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="root seed of the trials and of random configurations")
    p.add_argument(
        "--coverage", type=float, default=0.95, help="coverage probability of the regions (default %(default)s)"
    )
    p.add_argument("--regions", type=int, default=0, help="first N configurations keep samples for a JCGM 102 region")
    p.add_argument("--block-size", type=int, default=1000, help="trials per random stream (default %(default)s)")
    p.add_argument("--lambda", dest="lambda_", default="auto", help="auto (L-curve corner), gcv, or a fixed value")
    p.add_argument("--tracker-noise-um", type=float, default=5.0, help="tracker half-width a, um (uniform)")
    p.add_argument("--tracker-noise-um-per-m", type=float, default=0.0, help="MPE distance part b, um/m")
    p.add_argument("--encoder-noise-deg", type=float, default=0.005, help="encoder half-width, deg (uniform)")
    p.add_argument("--base-unknown", action="store_true", help="identify the base transform even if known")
    p.add_argument("--workers", type=int, default=1, help="local worker processes (never changes the result)")
    _add_dask_arg(p)
    p.add_argument("--out", default="robocal_map", help="report directory (default %(default)s)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    _add_frame_and_convergence_args(p)
    p.set_defaults(func=_cmd_map, lambda_range=None, min_poses=None, subset_size=None)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit status."""
    parser = _build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except CalibError as err:
        print(f"robocal-uncertainty {args.command}: error: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"robocal-uncertainty {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (e.g. `| head`): stop quietly, as command-line tools do.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141


if __name__ == "__main__":
    sys.exit(main())
