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
import re
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.errors import CalibError, ConfigError, InputError
from robocal_uncertainty.uncertainty.sources import sources_help

__all__ = ["PAPER_TEST_JOINTS_DEG", "main"]

PAPER_TEST_JOINTS_DEG = (-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451)
"""The robot seed's test configuration (Table 2), degrees."""

DEMO_SOURCES = ("tracker", "encoder", "lambda", "n_poses", "pose_choice")

DEFAULT_PAIRING_TOLERANCE_MS = 50.0
"""Default of ``--pairing-tolerance-ms``: a tracker point stamped up to this long before or after
its joint reading is paired with it (tracker latency of a real recording is a few ms; poses are
seconds apart)."""


def _load_robot(name: str, *, base_known: bool | None = None) -> Any:
    from robocal_uncertainty.core.robot_config import load_robot_model, resolve_robot_config

    path = resolve_robot_config(name)
    try:
        model = load_robot_model(path)
    except ConfigError as err:
        if str(path) in str(err) or Path(path).name in str(err):
            raise
        msg = f"robot config {path}: {err}"  # every message names the file it is about
        raise ConfigError(msg) from err
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
    """Joint configurations from a text file: one per row, numbers separated by commas,
    semicolons or whitespace; blank lines, ``#`` comments and a header row are skipped."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except UnicodeDecodeError as err:
        msg = f"cannot read joints file {path}: not UTF-8 text"
        raise InputError(msg) from err
    except OSError as err:
        msg = f"cannot read joints file {path}: {err.strerror}"
        raise InputError(msg) from err
    rows: list[list[float]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        cells = line.replace(";", ",").replace(",", " ").split()
        if not cells or cells[0].startswith("#") or (not rows and cells[0][0].isalpha()):
            continue
        try:
            values = [float(v) for v in cells]
        except ValueError:
            bad = next(v for v in cells if not _is_number(v))
            msg = f"joints file {path}, line {number}: {bad!r} is not a number"
            raise InputError(msg) from None
        if len(values) != n_joints:
            msg = f"joints file {path}, line {number}: {len(values)} values, the robot has {n_joints} joints"
            raise ConfigError(msg)
        if not np.isfinite(values).all():
            msg = f"joints file {path}, line {number}: NaN or inf"
            raise InputError(msg)
        rows.append(values)
    if not rows:
        msg = f"joints file {path} has no configuration (one row of {n_joints} numbers per configuration)"
        raise ConfigError(msg)
    q = np.array(rows)
    return np.radians(q) if degrees else q


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


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


class _Progress:
    """Progress bars on stderr (tqdm) for the phases of a run: the main Monte Carlo, the
    budget, the sweeps and the report. Drawn only when `enabled` and stderr is a terminal;
    the main run's duration (first to last progress report) is measured either way."""

    def __init__(self, enabled: bool, label: str, *, max_trials: int | None = None) -> None:
        self.enabled = enabled and sys.stderr.isatty()
        self.label = label
        self.max_trials = max_trials
        self.start = time.perf_counter()
        self.last = self.start
        self._bars: dict[str, Any] = {}

    def _bar(self, key: str, desc: str, total: int | None, unit: str) -> Any:
        bar = self._bars.get(key)
        if bar is None:
            from tqdm import tqdm

            bar = tqdm(total=total, unit=unit, desc=desc, file=sys.stderr, leave=False, dynamic_ncols=True)
            self._bars[key] = bar
        return bar

    def main(self, done: int, target: int | None) -> None:
        """``progress(done, target)`` of the main Monte Carlo run (target None: adaptive)."""
        self.last = time.perf_counter()
        if not self.enabled:
            return
        if target is None:
            bar = self._bar("main", f"{self.label} (adaptive JCGM 101 7.9)", None, "trial")
            bar.update(done - bar.n)
            rate = done / max(self.last - self.start, 1e-9)
            if self.max_trials:
                bar.set_postfix_str(
                    f"stops when u is stable; at most {self.max_trials} trials, "
                    f"<= {max(self.max_trials - done, 0) / rate:.0f} s more",
                    refresh=False,
                )
            return
        bar = self._bar("main", self.label, target, "trial")
        bar.total = target
        bar.update(done - bar.n)

    def phase(self, phase: str, done: int, total: int | None) -> None:
        """``phase_progress`` of :func:`robocal_uncertainty.app.evaluate` (budget, sweeps)."""
        if not self.enabled:
            return
        self.close("main")
        desc = {"budget": "budget (each source alone)", "sweeps": "sweeps (u vs lambda, vs equations)"}.get(
            phase, phase
        )
        bar = self._bar(phase, desc, total, "trial")
        bar.update(done - bar.n)
        if total is not None and done >= total:
            self.close(phase)

    def note(self, text: str) -> None:
        """A one-line status on stderr (e.g. while the report is written), when drawing."""
        if self.enabled:
            print(f"{self.label}: {text}", file=sys.stderr, flush=True)

    def close(self, key: str | None = None) -> None:
        for name in [key] if key is not None else list(self._bars):
            bar = self._bars.pop(name, None) if name is not None else None
            if bar is not None:
                bar.close()

    def elapsed(self) -> float:
        """Seconds of the main run (start to its last progress report)."""
        return max(self.last - self.start, 1e-9)


def _print_calibration(result: Any) -> None:
    print(
        f"Calibration of {result.model.name}: {_count(result.n_poses, 'pose')}, "
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
    if result.measurement.measures_orientation:
        stated, used = result.measurement.std, 1.0 / result.measurement.weights
        print(
            f"  rotation residual RMS {result.rotation_rms_before * 1e3:.5g} mrad -> "
            f"{result.rotation_rms_after * 1e3:.5g} mrad (position RMS above: the position part)"
        )

        def triple(std: Any) -> str:
            return (
                f"position ({', '.join(f'{v * 1e6:.3g}' for v in std[:3])}) um, "
                f"rotation ({', '.join(f'{v * 1e6:.3g}' for v in std[3:])}) urad"
            )

        if result.weighting == "variance_components":
            print(
                f"  weighting: each residual divided by its scatter (variance components, "
                f"{result.weighting_iterations} fits): {triple(used)}; stated: {triple(stated)}"
            )
        else:
            print(f"  weighting: each residual divided by its stated standard uncertainty, {triple(stated)}")
    from robocal_uncertainty.report.table2 import format_significant, round_to_uncertainty

    print("  parameter            nominal        estimate   1st-order std")
    kinds = result.model.layout.kinds
    for i, name in enumerate(result.parameter_names):
        if not result.estimated[i]:
            continue
        scale, unit, uscale, uunit = (
            (1e3, "mm", 1e6, "um")
            if kinds[i] == "length"
            else (float(np.degrees(1.0)), "deg", float(np.degrees(1.0)) * 1e3, "mdeg")
        )
        u = float(result.linearized_std[i])
        print(
            f"  {name:<16} {result.nominal[i] * scale:12.6g} {unit:<3} "
            f"{round_to_uncertainty(result.estimate[i] * scale, u * scale):>12} {unit:<3} "
            f"{format_significant(u * uscale):>8} {uunit}"
        )
    if result.dependencies:
        print(f"  not identifiable from the {result.measurement.quantity}s (kept at nominal):")
        from robocal_uncertainty.core.observability import describe_dependency

        for dep in result.dependencies:
            print(f"    {describe_dependency(dep)}")
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
        std = ad.standard_uncertainty
        u = f"({', '.join(f'{v * 1e6:.1f}' for v in std[:3])}) um"
        if len(std) > 3:  # 6-DOF residuals: the rotation part is in rad
            u = f"position {u}, rotation ({', '.join(f'{v * 1e6:.1f}' for v in std[3:])}) urad"
        used = "included" if "residual" in result.settings.sources else "NOT included: add --sources ...,residual"
        print(
            f"Model adequacy: residuals exceed the stated noise (p = {ad.p_value:.3g}); model error "
            f"u = {u} per measurement-frame axis, {used}"
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
        f"wrote {files.campaign_path} ({_count(files.simulation.campaign.n_poses, 'pose')}, "
        f"points in the {args.frame} frame) "
        f"and truth {files.truth_path}"
    )
    return 0


def _cmd_import_csv(args: argparse.Namespace) -> int:
    from robocal_uncertainty.bagio import write_campaign
    from robocal_uncertainty.importers import read_tracker_csv

    joint_columns = None
    if args.joint_columns is not None:
        joint_columns = [name.strip() for name in args.joint_columns.split(",") if name.strip()]
        if not joint_columns:
            raise ConfigError("--joint-columns needs a comma list of column names")
    orientation_columns = None
    if args.orientation_columns is not None:
        orientation_columns = [name.strip() for name in args.orientation_columns.split(",") if name.strip()]
    campaign = read_tracker_csv(
        args.csv,
        length_unit=args.length_unit,
        angle_unit=args.angle_unit,
        skip_invalid=args.skip_invalid,
        joint_columns=joint_columns,
        orientation_columns=orientation_columns,
        orientation_unit=args.orientation_unit,
        orientation_convention=args.orientation_convention,
    )
    write_campaign(args.out, campaign, overwrite=args.force)
    skipped = campaign.metadata.get("skipped_rows") or []
    print(
        f"wrote {args.out}: {_count(campaign.n_poses, 'pose')}, joints {', '.join(campaign.joint_names)}, "
        f"points in the {campaign.frame} frame ({campaign.frame_id})"
        + (f", {_count(len(skipped), 'invalid row')} skipped" if skipped else "")
    )
    return 0


def _campaign_and_robot(args: argparse.Namespace) -> tuple[Any, Any]:
    """Read the campaign (its reader warnings printed as ``warning:`` lines) and the robot;
    refuse campaign joint readings outside the robot's joint limits."""
    campaign = _read_campaign_checked(args, args.campaign)
    _check_campaign_counts(args, campaign.n_poses)
    model = _load_robot(args.robot, base_known=False if args.base_unknown else None)
    _check_campaign_joints(model, campaign, args.campaign)
    return campaign, model


def _read_campaign_checked(args: argparse.Namespace, path: str) -> Any:
    """One campaign read as every command reads it: with ``--pairing-tolerance-ms``, a raw
    recording refused, the reader's warnings printed as ``warning:`` lines."""
    import warnings

    from robocal_uncertainty.bagio import read_campaign

    tolerance_ms = getattr(args, "pairing_tolerance_ms", DEFAULT_PAIRING_TOLERANCE_MS)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        campaign = read_campaign(path, stamp_tolerance_ns=round(tolerance_ms * 1e6))
    _refuse_raw_recording(path, campaign)
    notes = [str(w) for w in campaign.metadata.get("warnings") or ()]
    notes += [str(w.message) for w in caught if str(w.message) not in notes]
    for note in notes:
        print(f"warning: {note}", file=sys.stderr)
    return campaign


def _check_campaign_joints(model: Any, campaign: Any, path: str) -> None:
    from robocal_uncertainty.core import check_joint_limits

    check_joint_limits(
        model,
        campaign.reorder_joints(model.joint_names).joint_positions,
        what=f"{path}: campaign pose",
        degrees_hint="the readings look like degrees (import-csv --angle-unit deg?)",
    )


RAW_RECORDING_GAP_S = 0.25
"""A campaign whose tracker points are typically closer in time than this is a raw recording:
a robot cannot move to a new pose and settle that fast (the shipped raw bags stream points every
5 ms; a campaign has one point per pose, seconds apart)."""


def _refuse_raw_recording(path: str, campaign: Any) -> None:
    """Refuse a raw recording read as a campaign: pairing every streamed tracker point with a
    joint reading turns the motion between poses into "poses", and the calibration is nonsense."""
    stamps = campaign.stamps_ns
    if stamps is None or campaign.n_poses < 3:
        return
    gap_s = float(np.median(np.diff(np.sort(np.asarray(stamps, dtype=np.int64))))) / 1e9
    if gap_s < RAW_RECORDING_GAP_S:
        msg = (
            f"{path}: {campaign.n_poses} tracker points, typically {gap_s * 1e3:.3g} ms apart: this is a raw "
            "recording (a campaign has one point per static pose, seconds apart), not a campaign: use 'replay' on it"
        )
        raise InputError(msg)


def _test_joints(args: argparse.Namespace, model: Any) -> NDArray[np.float64]:
    return _joint_configurations(
        model,
        args.test_joints_file,
        args.test_joints,
        degrees=args.degrees,
        flag="--test-joints",
        noun="test configuration",
    )


def _joint_configurations(
    model: Any, path: str | None, values: Sequence[str] | None, *, degrees: bool, flag: str, noun: str
) -> NDArray[np.float64]:
    """Configurations [rad] from ``{flag}-file`` `path` or ``{flag}`` `values`, within the joint limits."""
    from robocal_uncertainty.core import check_joint_limits

    if path:
        q = _read_joints_file(path, model.n_joints, degrees=degrees)
        what = f"{path}: {noun}"
    elif values:
        q = _parse_joint_values(values, model.n_joints, degrees=degrees, what=flag)
        what = f"{flag} configuration"
    else:
        msg = f"give {flag} or {flag}-file"
        raise ConfigError(msg)
    check_joint_limits(model, q, what=what, degrees_hint=None if degrees else "did you mean --degrees?")
    return q


def _lambda_arg(text: str) -> str | float:
    if text in ("auto", "gcv", "lcurve"):
        return text
    try:
        return float(text)
    except ValueError as err:
        msg = f"--lambda must be 'auto', 'gcv' or a number, got {text!r}"
        raise ConfigError(msg) from err


def _count(n: int, noun: str) -> str:
    """``1 pose``, ``2 poses``."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


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
    from robocal_uncertainty.core.calibration_file import apply_calibration, read_calibration

    model = _load_robot(args.robot)
    if args.calibration:
        model = apply_calibration(model, read_calibration(args.calibration), where=f"calibration {args.calibration}")
    q = _joint_configurations(
        model, args.joints_file, args.joints, degrees=args.degrees, flag="--joints", noun="configuration"
    )
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


def _evaluation_options(
    args: argparse.Namespace, sources: Sequence[str], test_joints: NDArray[np.float64] | None
) -> Any:
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
    """A progress callback (a bar on stderr when `enabled` and stderr is a terminal) and a
    function that closes the bar and returns the seconds to the last progress report."""
    bars = _Progress(enabled, label)

    def finish() -> float:
        bars.close()
        return bars.elapsed()

    return bars.main, finish


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
    shared by ``evaluate`` and ``demo``. Returns the uncertainty result."""
    from robocal_uncertainty.app import evaluate
    from robocal_uncertainty.montecarlo.executor import open_executor

    options = _evaluation_options(args, sources, test_joints)
    bars = _Progress(not args.no_progress, label, max_trials=args.max_trials)
    try:
        # --dask (evaluate only) or --workers: one executor for the main run, budget and sweeps.
        with open_executor(workers=args.workers, dask=getattr(args, "dask", None)) as executor:
            evaluation = evaluate(
                model, campaign, options, executor=executor, progress=bars.main, phase_progress=bars.phase
            )
    finally:
        bars.close()
    _print_evaluation(evaluation, options, model, out_dir, bars, args)
    return evaluation.uncertainty


def _seconds(value: float) -> str:
    return f"{value:.1f} s" if value >= 1 else f"{value:.2g} s"


def _print_evaluation(
    evaluation: Any, options: Any, model: Any, out_dir: Path, bars: _Progress, args: argparse.Namespace
) -> None:
    """Print an :class:`~robocal_uncertainty.app.Evaluation` and write its report (an
    earlier report's files in `out_dir` are removed first; ``--force`` was checked)."""
    from robocal_uncertainty.app.output_paths import clear_earlier_report
    from robocal_uncertainty.report import format_budget, format_table2, write_report

    result = evaluation.uncertainty
    elapsed = bars.elapsed()
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
    print(f"{result.n_trials} trials in {_seconds(elapsed)} ({result.n_trials / elapsed:.0f} trials/s)")
    if evaluation.budget:
        print()
        print(format_budget(evaluation.budget))
        print(f"(each source alone, {options.budget_trials} trials each)")
    for note in evaluation.notes:
        print(f"note: {_in_cli_words(note)}")
    for warning in result.warnings:
        print(f"warning: {warning}")
    clear_earlier_report(out_dir)
    bars.note(f"writing the report to {out_dir} ...")
    path = write_report(
        out_dir,
        result,
        robot_name=model.name,
        budget=dict(evaluation.budget) or None,
        sweeps=list(evaluation.sweeps) if options.sweeps else None,
        input_warnings=evaluation.input_warnings,
        histograms=getattr(args, "histograms", None),
    )
    print(f"report written to {path}")


def _add_noise_args(p: argparse.ArgumentParser) -> None:
    """The tracker and encoder noise models, shared by simulate and the Monte Carlo commands."""
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
    p.add_argument(
        "--lambda",
        dest="lambda_",
        default="auto",
        help="auto (L-curve corner), gcv, or a fixed value (default %(default)s)",
    )
    p.add_argument(
        "--lambda-range",
        type=float,
        nargs=2,
        metavar=("LOW", "HIGH"),
        help="range of lambda for the 'lambda' source (default lambda*/5 .. 5 lambda*)",
    )
    p.add_argument(
        "--min-poses",
        type=int,
        help="smallest pose count of the 'n_poses' source (default: 40 equations or 1.5 x the identifiable "
        "parameters, whichever is more; lowered for a smaller campaign)",
    )
    p.add_argument(
        "--subset-size",
        type=int,
        help="pose count of the 'pose_choice' source (default: 33/53 of the campaign's poses)",
    )
    _add_noise_args(p)
    p.add_argument(
        "--workers", type=int, default=1, help="worker processes (never changes the result; default %(default)s)"
    )
    p.add_argument(
        "--budget",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also run each source alone (uncertainty budget; default on)",
    )
    p.add_argument(
        "--budget-trials", type=int, default=2000, help="trials per source of the budget (default %(default)s)"
    )
    p.add_argument(
        "--sweeps",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="uncertainty against lambda and against the number of equations (report plots; default on)",
    )
    p.add_argument("--sweep-trials", type=int, default=300, help="trials per sweep point (default %(default)s)")
    p.add_argument(
        "--no-progress", action="store_true", help="no progress bars (default: shown when stderr is a terminal)"
    )
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
        sources=parse_sources(_default_sources(args.sources, campaign, "tracker,encoder")),
        args=args,
        out_dir=Path(args.out),
        label="evaluate",
    )
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from robocal_uncertainty.app import replay
    from robocal_uncertainty.pipeline import CollectorSettings

    model = _load_robot(args.robot, base_known=False if args.base_unknown else None)
    sources = args.sources
    if sources is None:
        # A tracker pose topic means a 6-DOF campaign: its orientation noise is an input too.
        sources = "tracker,encoder,tracker_orientation" if args.tracker_pose_topic else "tracker,encoder"
    options = _evaluation_options(args, _sources_arg(sources), _test_joints(args, model))
    window = _window_arg(args.window_s)
    settings = CollectorSettings(
        window_s=window if window is not None else CollectorSettings().window_s,
        joint_motion_threshold=args.joint_motion_threshold_rad,
        tracker_scatter_threshold=args.tracker_scatter_threshold_m,
        min_points=args.min_points,
        orientation_scatter_threshold=args.orientation_scatter_threshold_rad,
    )
    if args.campaign_out and args.force:
        Path(args.campaign_out).unlink(missing_ok=True)  # --force: replay writes a new campaign

    def log(cause: str, message: str) -> None:
        print(f"replay: dropped ({cause}): {message}", file=sys.stderr)

    bars = _Progress(not args.no_progress, "replay", max_trials=args.max_trials)
    try:
        replayed = replay(
            args.bag,
            model,
            options,
            joint_topic=args.joint_topic,
            point_topic=args.point_topic,
            tracker_pose_topic=args.tracker_pose_topic,
            tracker_frame_id=args.tracker_frame,
            collector=settings,
            campaign_path=args.campaign_out,
            log=log,
            auto_window=window is None,
            workers=args.workers,
            progress=bars.main,
            phase_progress=bars.phase,
        )
    finally:
        bars.close()
    result = replayed.replay
    dropped = ", ".join(f"{k}: {v}" for k, v in sorted(result.dropped.items()) if v) or "none"
    used = result.collector
    how = "auto, from the joints' still intervals" if window is None else "--window-s"
    print(
        f"replay of {args.bag}: {_count(len(result.samples), 'static pose')} found "
        f"(window {used.window_s:g} s, {how}); dropped messages: {dropped}"
    )
    if args.campaign_out:
        print(f"campaign written to {args.campaign_out}")
    _print_evaluation(replayed.evaluation, options, model, Path(args.out), bars, args)
    return 0


def _default_sources(given: str | None, campaign: Any, default: str) -> str:
    """``--sources`` as given, else `default` plus the orientation noise of a 6-DOF campaign."""
    if given is not None:
        return given
    return default + ",tracker_orientation" if campaign.measurement.measures_orientation else default


def _sources_arg(text: str) -> tuple[str, ...]:
    from robocal_uncertainty.uncertainty import parse_sources

    return tuple(parse_sources(text))


def _cmd_validate(args: argparse.Namespace) -> int:
    from robocal_uncertainty.app import validate
    from robocal_uncertainty.report.validation_report import format_validation, write_validation_report

    campaign, model = _campaign_and_robot(args)
    options = _evaluation_options(
        args, _sources_arg(_default_sources(args.sources, campaign, "tracker,encoder,residual")), None
    )
    validation_campaign = None
    if args.validation_campaign:
        validation_campaign = _read_campaign_checked(args, args.validation_campaign)
        _check_campaign_joints(model, validation_campaign, args.validation_campaign)
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
    from robocal_uncertainty.app.output_paths import clear_earlier_report

    clear_earlier_report(args.out)
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
        "inside the 95 % intervals: " + ", ".join(f"{a} {'yes' if v else 'no'}" for a, v in zip("xyz", inside))
    )
    from robocal_uncertainty.report.table2 import format_seed_comparison

    print()
    print(format_seed_comparison(result))
    return 0


def _cmd_section(args: argparse.Namespace) -> int:
    from robocal_uncertainty.app.section_inspection import DEMO_SCENARIO, inspect_section, section_demo
    from robocal_uncertainty.montecarlo.engine import AdaptiveSettings
    from robocal_uncertainty.report.section_report import (
        coverage_summary,
        format_repeatability_budget,
        format_section_table,
        write_section_report,
    )

    if args.demo == (args.cloud is not None):
        raise ConfigError("section needs a CLOUD file or bag, or --demo (not both)")
    if args.cloud is not None and args.nominal is None:
        raise ConfigError("section needs --nominal (a file, or a shipped blade: rotor37, rotor37:K, cascade)")
    if args.demo and (args.nominal or args.unit or args.topic or args.message is not None):
        raise ConfigError(
            "--demo uses the shipped Rotor 37 scenario: --nominal, --unit, --topic, --message do not apply"
        )
    if args.demo and args.repeat_scans is not None:
        raise ConfigError("--repeat-scans needs measured scans of CLOUD's section; --demo simulates no repeats")
    if args.repeat_scans is not None and len(args.repeat_scans) < 2:
        raise ConfigError(
            f"--repeat-scans needs at least 2 repeated scans for a standard deviation, got {len(args.repeat_scans)}"
        )
    trials = _trials(args.trials) if args.trials is not None else (100_000 if args.demo else 1_000_000)
    adaptive = AdaptiveSettings() if trials == "auto" else None
    count = None if trials == "auto" else int(trials)
    progress, finish = _timed_progress(not args.no_progress, "section")
    try:
        if args.demo:
            print(
                "Demo: NASA Rotor 37 surface 2 at the seed's size (x7.14), a simulated "
                f"{DEMO_SCENARIO['n_points']}-point "
                "CMM scan with offsets (-0.1013, 0.0538) mm, twist 0.0512 deg, a 5 um 3-wave form error and one draw "
                "of the instrument errors; the true parameters are known."
            )
            run = section_demo(
                trials=count,
                adaptive=adaptive,
                seed=args.seed,
                workers=args.workers,
                instrument=args.instrument,
                progress=progress,
                method=args.method,
            )
        else:
            run = inspect_section(
                args.cloud,
                args.nominal,
                unit=args.unit,
                nominal_unit=args.nominal_unit,
                instrument=args.instrument,
                trials=count,
                adaptive=adaptive,
                seed=args.seed,
                workers=args.workers,
                topic=args.topic,
                message=args.message,
                progress=progress,
                method=args.method,
                repeat_scans=args.repeat_scans,
            )
    finally:
        finish()
    result = run.result
    frame = f", frame {run.cloud.frame_id}" if run.cloud.frame_id else ""
    print(
        f"{run.cloud.n_points} points ({run.cloud.source}{frame}); nominal {run.nominal}; instrument {run.instrument}; "
        f"{result.monte_carlo.n_trials} trials, seed {result.monte_carlo.seed}, {run.elapsed_s:.1f} s"
    )
    print()
    print(format_section_table(result, run.corrections, truth=run.truth))
    print()
    if result.gum_with_repeatability is not None:
        print(format_repeatability_budget(result))
        print()
    print(f"note: {coverage_summary(result.method)}")
    from robocal_uncertainty.app.output_paths import clear_earlier_report

    clear_earlier_report(args.out)
    extra = {
        "cloud": run.cloud.source,
        "frame_id": run.cloud.frame_id,
        "n_points": run.cloud.n_points,
        "nominal": run.nominal,
        "instrument_file": run.instrument,
        "elapsed_s": run.elapsed_s,
        "workers": run.workers,
        "demo": bool(args.demo),
        "repeat_scans": list(run.repeats),
    }
    files = write_section_report(result, run.corrections, args.out, truth=run.truth, extra=extra)
    print(f"section report written to {files.markdown.parent}")
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
    from robocal_uncertainty.app.output_paths import clear_earlier_report

    clear_earlier_report(args.out)
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


def _cmd_suggest(args: argparse.Namespace) -> int:
    from robocal_uncertainty.app import suggest_poses
    from robocal_uncertainty.core import identify
    from robocal_uncertainty.uncertainty import parse_sources

    campaign, model = _campaign_and_robot(args)
    campaign = campaign.reorder_joints(model.joint_names)
    test_q = _test_joints(args, model)
    candidates = None
    if args.candidates_file:
        candidates = _joint_configurations(
            model, args.candidates_file, None, degrees=args.degrees, flag="--candidates-file", noun="candidate"
        )
        if args.count > len(candidates):
            msg = (
                f"--count {args.count} is more than the {_count(len(candidates), 'configuration')} "
                f"in --candidates-file {args.candidates_file}"
            )
            raise ConfigError(msg)
    settings = _uncertainty_settings(args, None, parse_sources(args.sources))
    lambda_ = _lambda_arg(args.lambda_)
    calibration = identify(model, campaign, lambda_=lambda_, accept_unconverged=args.accept_unconverged)
    result = suggest_poses(
        model,
        campaign,
        test_q,
        settings=settings,
        calibration=calibration,
        lambda_=lambda_,
        candidates=candidates,
        n_candidates=args.candidates,
        count=args.count,
        monte_carlo_check=args.check,
        trials=args.trials,
        seed=args.seed,
        frame=args.frame,
    )
    unit = "deg" if args.degrees else "rad"
    source = (
        f"the {_count(len(result.candidates), 'configuration')} of {args.candidates_file}"
        if args.candidates_file
        else f"{len(result.candidates)} candidates drawn inside the joint limits (seed {args.seed})"
    )
    print(f"Next-best poses for {model.name} ({campaign.n_poses} poses measured), ranked among {source}")
    print(
        f"u_pos = sqrt(trace of the tool-position covariance), RMS over the "
        f"{_count(len(test_q), 'test configuration')}, frame {result.frame_id}; sources {', '.join(settings.sources)}"
    )
    print(_format_suggestions(result, unit))
    if result.trials:
        print(
            f"Monte Carlo: {result.trials} trials, seed {result.seed}, with suggestions 1..rank added as simulated "
            "measurements at the calibrated model's points"
        )
    if args.json:
        text = json.dumps(_suggestions_dict(result, model, args, test_q, settings), indent=2, allow_nan=False)
        Path(args.json).write_text(text + "\n", encoding="utf-8")
        print(f"wrote {args.json}")
    if args.csv_out:
        Path(args.csv_out).write_text(_suggestions_csv(result, unit), encoding="utf-8")
        print(f"wrote {args.csv_out}")
    return 0


def _suggestion_joints(q: NDArray[np.float64], unit: str) -> list[float]:
    """Joint positions [rad] in `unit` ("rad" or "deg")."""
    return [float(v) for v in (np.degrees(q) if unit == "deg" else q)]


def _format_suggestions(result: Any, unit: str) -> str:
    """The suggestion table: rank, joints in `unit`, predicted and Monte Carlo RMS u_pos in µm."""
    digits = 4 if unit == "deg" else 6
    header = [
        "rank",
        *(f"{name} / {unit}" for name in result.joint_names),
        "predicted RMS u_pos / µm",
        "Monte Carlo RMS u_pos / µm",
    ]

    def um(value: float | None) -> str:
        return "-" if value is None else f"{value * 1e6:.3f}"

    rows = [["now", *([""] * len(result.joint_names)), um(result.current_u_m), um(result.monte_carlo_current_u_m)]]
    for rank, s in enumerate(result.suggestions, start=1):
        joints = (f"{v:.{digits}f}" for v in _suggestion_joints(s.joint_positions, unit))
        rows.append([str(rank), *joints, um(s.predicted_u_m), um(s.monte_carlo_u_m)])
    widths = [max(len(row[c]) for row in [header, *rows]) for c in range(len(header))]
    lines = ["  ".join(cell.rjust(w) for cell, w in zip(row, widths)) for row in [header, *rows]]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def _suggestions_dict(
    result: Any, model: Any, args: argparse.Namespace, test_q: NDArray[np.float64], settings: Any
) -> dict[str, Any]:
    """The suggestions as a robot program reads them: SI units, named in every key."""
    s = result.suggestions
    return {
        "command": "robocal-uncertainty suggest",
        "robot": model.name,
        "campaign": str(args.campaign),
        "units": {
            "_rad": "radian",
            "_deg": "degree",
            "_m": "metre (u_pos = sqrt(trace of the tool-position covariance), RMS over the test configurations)",
            "_m2": "square metre",
        },
        "joint_names": list(result.joint_names),
        "frame_id": result.frame_id,
        "frame": args.frame,
        "sources": list(settings.sources),
        "tracker_noise": {"a_m": settings.tracker_noise.a, "b_m_per_m": settings.tracker_noise.b},
        "encoder_noise_half_width_rad": settings.encoder_noise.half_width,
        "test_joint_positions_rad": test_q.tolist(),
        "candidates": {
            "file": args.candidates_file,
            "count": len(result.candidates),
            "seed": None if args.candidates_file else result.seed,
        },
        "seed": result.seed,
        "monte_carlo_trials": result.trials,
        "current_rms_u_pos_m": result.current_u_m,
        "monte_carlo_current_rms_u_pos_m": result.monte_carlo_current_u_m,
        "suggestions": [
            {
                "rank": rank,
                "joint_positions_rad": _suggestion_joints(p.joint_positions, "rad"),
                "joint_positions_deg": _suggestion_joints(p.joint_positions, "deg"),
                "reduction_m2": p.reduction_m2,
                "predicted_rms_u_pos_m": p.predicted_u_m,
                "monte_carlo_rms_u_pos_m": p.monte_carlo_u_m,
            }
            for rank, p in enumerate(s, start=1)
        ],
    }


def _suggestions_csv(result: Any, unit: str) -> str:
    """One row of joint positions per suggestion, best first, in `unit` (readable back as a
    ``--joints-file``, ``--test-joints-file`` or ``--candidates-file``)."""
    lines = [
        f"# robocal-uncertainty suggest: next-best poses, best first; joint positions in {unit}",
        ",".join(f"{name}_{unit}" for name in result.joint_names),
    ]
    lines += [",".join(repr(v) for v in _suggestion_joints(s.joint_positions, unit)) for s in result.suggestions]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------------
# Early checks: every option and output path is checked before any computation, with the
# command line's own words (flags, units, 1-based counts).

_POSITIVE_INTS = (
    "workers",
    "max_trials",
    "budget_trials",
    "sweep_trials",
    "min_poses",
    "subset_size",
    "poses",
    "block_size",
    "train_poses",
    "count",
    "candidates",
)
_NON_NEGATIVE_INTS = ("seed", "regions", "check")
_NON_NEGATIVE_FLOATS = (
    ("tracker_noise_um", "um"),
    ("tracker_noise_um_per_m", "um/m"),
    ("encoder_noise_deg", "deg"),
    ("pairing_tolerance_ms", "ms"),
)
_POSITIVE_FLOATS = (("joint_motion_threshold_rad", "rad"), ("tracker_scatter_threshold_m", "m"))

_INTERNAL_WORDS = (
    # Names the library's messages use for what the command line calls otherwise.
    (r"\(pass overwrite=True to replace it\)", "(give --force to replace it)"),
    (r"\badaptive\.max_trials\b", "--max-trials"),
    (r"or give the unit explicitly\)", "or give --unit)"),
    (r"\blambda_range\b", "--lambda-range"),
    (r"\bmin_poses\b", "--min-poses"),
    (r"\bsubset_size\b", "--subset-size"),
    (r"\bwindow_s\b", "--window-s"),
    (r"\bmin_points\b", "--min-points"),
    (r"\bjoint_motion_threshold\b", "--joint-motion-threshold-rad"),
    (r"\btracker_scatter_threshold\b", "--tracker-scatter-threshold-m"),
    (r"\bk_folds\b", "--k-folds"),
    (r"\bn_train\b", "--train-poses"),
    (r"\bthe pairing tolerance of ([0-9.e+-]+) ms\b", r"--pairing-tolerance-ms \1"),
)


def _flag(dest: str) -> str:
    return "--lambda" if dest == "lambda_" else "--" + dest.replace("_", "-")


def _in_cli_words(message: str) -> str:
    """A library message with its argument names replaced by the command line's flags."""
    import re

    for pattern, flag in _INTERNAL_WORDS:
        message = re.sub(pattern, flag, message)
    return message


def _check_options(args: argparse.Namespace) -> None:
    """Refuse bad option values before anything is read or computed (one line each)."""
    for dest in _POSITIVE_INTS:
        value = getattr(args, dest, None)
        if value is not None and value < 1:
            msg = f"{_flag(dest)} must be a positive integer, got {value}"
            raise ConfigError(msg)
    for dest in _NON_NEGATIVE_INTS:
        value = getattr(args, dest, None)
        if value is not None and value < 0:
            msg = f"{_flag(dest)} must be an integer >= 0, got {value}"
            raise ConfigError(msg)
    for dest, unit in _NON_NEGATIVE_FLOATS:
        value = getattr(args, dest, None)
        if value is not None and not (np.isfinite(value) and value >= 0):
            msg = f"{_flag(dest)} must be a finite number >= 0 {unit}, got {value:g}"
            raise ConfigError(msg)
    for dest, unit in _POSITIVE_FLOATS:
        value = getattr(args, dest, None)
        if value is not None and not (np.isfinite(value) and value > 0):
            msg = f"{_flag(dest)} must be a finite number > 0 {unit}, got {value:g}"
            raise ConfigError(msg)
    trials = getattr(args, "trials", None)
    if isinstance(trials, str):
        _trials(trials)
    elif trials is not None and trials < 1:
        msg = f"--trials must be a positive integer, got {trials}"
        raise ConfigError(msg)
    coverage = getattr(args, "coverage", None)
    if coverage is not None and not 0.0 < coverage < 1.0:
        hint = f"; did you mean {coverage / 100:g}?" if 50.0 <= coverage < 100.0 else ""
        msg = f"--coverage is a probability in (0, 1), got {coverage:g}{hint}"
        raise ConfigError(msg)
    if getattr(args, "lambda_", None) is not None:
        _lambda_arg(args.lambda_)
    lambda_range = getattr(args, "lambda_range", None)
    if lambda_range is not None:
        low, high = lambda_range
        if not (np.isfinite(low) and np.isfinite(high) and 0.0 <= low < high):
            msg = f"--lambda-range needs 0 <= LOW < HIGH, got {low:g} {high:g}"
            raise ConfigError(msg)
    fraction = getattr(args, "holdout_fraction", None)
    if fraction is not None and not 0.0 < fraction < 1.0:
        msg = f"--holdout-fraction must lie in (0, 1), got {fraction:g}"
        raise ConfigError(msg)
    k_folds = getattr(args, "k_folds", None)
    if k_folds is not None and k_folds < 2:
        msg = f"--k-folds must be an integer >= 2, got {k_folds}"
        raise ConfigError(msg)
    min_points = getattr(args, "min_points", None)
    if min_points is not None and min_points < 2:
        msg = f"--min-points must be an integer >= 2, got {min_points}"
        raise ConfigError(msg)
    window = getattr(args, "window_s", None)
    if window is not None and window != "auto":
        _window_arg(window)
    grid = getattr(args, "grid", None)
    if grid is not None and min(grid) < 2:
        msg = f"--grid needs at least 2 values per joint, got {' '.join(map(str, grid))}"
        raise ConfigError(msg)
    if getattr(args, "trials", None) == "auto" and args.command == "validate":
        raise ConfigError("validate needs a fixed number of --trials, not auto")
    if args.command == "suggest":
        if args.check > args.count:
            msg = f"--check {args.check} is more than the --count {args.count} suggestions"
            raise ConfigError(msg)
        if not args.candidates_file and args.count > args.candidates:
            msg = f"--count {args.count} is more than the --candidates {args.candidates} drawn"
            raise ConfigError(msg)
    dask = getattr(args, "dask", None)
    if dask is not None and not _DASK_ADDRESS.match(dask.strip()):
        msg = f"--dask must be 'local' or a scheduler address such as tcp://host:8786, got {dask!r}"
        raise ConfigError(msg)


_DASK_ADDRESS = re.compile(
    r"^(?:local|inproc://\S+|(?:[a-z][a-z0-9+.-]*://)?(?:\[[0-9a-fA-F:.]+\]|[^\s:/\[\]]+):\d{1,5})$"
)
"""What ``--dask`` accepts: ``local`` or ``[scheme://]host:port`` (as ``distributed`` parses it)."""


def _window_arg(text: str) -> float | None:
    """``--window-s``: a number of seconds > 0, or ``auto`` (None)."""
    if text == "auto":
        return None
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (np.isfinite(value) and value > 0):
        msg = f"--window-s must be 'auto' or a number of seconds > 0, got {text!r}"
        raise ConfigError(msg)
    return value


def _check_outputs(args: argparse.Namespace) -> None:
    """Refuse output paths that cannot or must not be written, before any work (--force rule)."""
    from robocal_uncertainty.app.output_paths import check_output_file, check_report_directory
    from robocal_uncertainty.app.simulation import truth_path

    force = bool(getattr(args, "force", False))
    if args.command in ("simulate", "import-csv"):
        check_output_file(args.out, force=force, option="--out")
        if args.command == "simulate":
            check_output_file(truth_path(args.out), force=force, option="truth file")
    elif args.command in ("demo", "evaluate", "replay", "validate", "map", "section"):
        check_report_directory(args.out, force=force, option="--out")
    if getattr(args, "csv_out", None):
        check_output_file(args.csv_out, force=force, option="--csv")
        if args.json and Path(args.json).resolve() == Path(args.csv_out).resolve():
            msg = f"--json and --csv name the same file {args.json}"
            raise ConfigError(msg)
    if getattr(args, "json", None):
        check_output_file(args.json, force=force, option="--json")
    if getattr(args, "campaign_out", None):
        check_output_file(args.campaign_out, force=force, option="--campaign-out")
    _check_outputs_are_not_inputs(args)


_INPUTS = (
    ("csv", "the tracker CSV being imported"),
    ("campaign", "the campaign being read"),
    ("bag", "the bag being replayed"),
    ("validation_campaign", "the --validation-campaign"),
    ("calibration", "the --calibration being applied"),
    ("robot", "the --robot config"),
    ("joints_file", "the --joints-file"),
    ("test_joints_file", "the --test-joints-file"),
    ("from_file", "the --from-file"),
    ("candidates_file", "the --candidates-file"),
    ("cloud", "the point cloud being read"),
    ("nominal", "the --nominal section"),
    ("instrument", "the --instrument config"),
)
"""Input paths of the commands (attribute, words): no output file may be one of them."""


def _check_outputs_are_not_inputs(args: argparse.Namespace) -> None:
    """Refuse an output file that is one of the command's inputs: even with --force,
    replacing it would destroy the data the command reads."""
    from robocal_uncertainty.app.simulation import truth_path

    outputs: list[tuple[str, str]] = []
    if args.command in ("simulate", "import-csv"):
        outputs.append(("--out", str(args.out)))
        if args.command == "simulate":
            outputs.append(("truth file", str(truth_path(args.out))))
    for dest, option in (("json", "--json"), ("csv_out", "--csv"), ("campaign_out", "--campaign-out")):
        if getattr(args, dest, None):
            outputs.append((option, str(getattr(args, dest))))
    for option, out in outputs:
        if not Path(out).exists():
            continue
        for dest, words in _INPUTS:
            given = getattr(args, dest, None)
            if isinstance(given, str) and Path(given).exists() and os.path.samefile(out, given):
                msg = f"{option} {out} is {words}"
                raise ConfigError(msg)


def _check_campaign_counts(args: argparse.Namespace, n_poses: int) -> None:
    """Options bounded by the campaign's size, checked right after reading it."""
    for dest in ("min_poses", "subset_size"):
        value = getattr(args, dest, None)
        if value is not None and value > n_poses:
            msg = f"{_flag(dest)} {value} is more than the campaign's {n_poses} poses"
            raise ConfigError(msg)
    train = getattr(args, "train_poses", None)
    if train is not None and train >= n_poses:
        msg = f"--train-poses {train} leaves no pose to hold out: the campaign has {n_poses} poses"
        raise ConfigError(msg)
    k_folds = getattr(args, "k_folds", None)
    if k_folds is not None and k_folds > n_poses:
        msg = f"--k-folds {k_folds} is more than the campaign's {n_poses} poses"
        raise ConfigError(msg)


def _add_force_arg(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--force", action="store_true", help=f"replace {what} if it exists (default: refuse)")


def _add_base_unknown_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--base-unknown",
        action="store_true",
        help="identify the base transform even if the robot config says it is known",
    )


def _add_campaign_args(p: argparse.ArgumentParser) -> None:
    """The campaign positional, --robot, --base-unknown and --pairing-tolerance-ms."""
    p.add_argument("campaign", help="campaign: .mcap file or rosbag2 directory")
    p.add_argument("--robot", required=True, help="robot YAML file or shipped model name (paper_arm, ur10)")
    _add_base_unknown_arg(p)
    p.add_argument(
        "--pairing-tolerance-ms",
        type=float,
        default=DEFAULT_PAIRING_TOLERANCE_MS,
        help="recordings without our campaign metadata: pair each tracker point with the joint reading nearest in "
        "stamp when it is at most this far, ms (default %(default)g)",
    )


def _add_test_joint_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--test-joints", nargs="+", help="joint values of the test configurations, n_joints each")
    p.add_argument("--test-joints-file", help="CSV/whitespace file of test configurations, one per row")
    p.add_argument("--degrees", action="store_true", help="test joint values are in degrees (default radians)")


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("robocal_uncertainty")
    except PackageNotFoundError:
        return "(not installed)"


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="robocal-uncertainty",
        description="Robot arm calibration from laser-tracker points and its Monte Carlo uncertainty (JCGM 101).",
        epilog="Exit status: 0 success, 1 error (one line on stderr), 2 usage error (argparse), "
        "130 interrupted, 141 output pipe closed (e.g. | head).",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser(
        "demo", help="the main job on the embedded default: seed's arm, simulated 53-pose campaign, Table 2 and report"
    )
    p.add_argument("--out", default="robocal_report", help="report directory (default %(default)s)")
    _add_force_arg(p, "an earlier report in --out")
    _add_uncertainty_args(p, trials_default="20000")
    p.set_defaults(func=_cmd_demo)

    p = sub.add_parser("simulate", help="write a simulated campaign MCAP (truth in a sidecar .truth.json)")
    p.add_argument("--robot", default="paper_arm", help="robot YAML file or shipped model name (default %(default)s)")
    p.add_argument("--out", required=True, help="campaign .mcap to write; the truth goes to the same name .truth.json")
    p.add_argument("--poses", type=int, default=53, help="number of measured poses (default %(default)s)")
    p.add_argument(
        "--frame",
        choices=("base", "tracker"),
        default="base",
        help="points in the robot base frame or in a tracker frame with an unknown base (default %(default)s)",
    )
    _add_noise_args(p)
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated robot, poses and noise (default 0)")
    _add_force_arg(p, "the campaign and truth files")
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser("import-csv", help="convert a tracker CSV export into a campaign MCAP")
    p.add_argument("csv", help="tracker CSV (comma-, semicolon- or tab-separated, units in the header)")
    p.add_argument("--out", required=True, help="campaign .mcap to write")
    p.add_argument(
        "--length-unit", help="unit of length columns whose header states none: m, mm, um (default: none assumed)"
    )
    p.add_argument(
        "--angle-unit", help="unit of joint columns whose header states none: rad, deg (default: none assumed)"
    )
    p.add_argument(
        "--joint-columns",
        help="comma list of the joint column names, in joint order (default: columns named *joint* or q1, q2, ...)",
    )
    p.add_argument("--skip-invalid", action="store_true", help="drop invalid rows instead of failing (default: fail)")
    p.add_argument(
        "--orientation-columns",
        help="comma list of the three Euler-angle columns of a 6-DOF probe, in the convention's order "
        "(ipa profile: measurement_rx,measurement_ry,measurement_rz; default: points only)",
    )
    p.add_argument("--orientation-unit", help="unit of orientation columns whose header states none: rad, deg")
    p.add_argument(
        "--orientation-convention",
        help="Euler convention of the orientation columns: intrinsic_xyz, extrinsic_xyz, intrinsic_zyx, "
        "intrinsic_zyz (ipa: intrinsic_xyz; giving it alone reads the ipa orientations)",
    )
    _add_force_arg(p, "the campaign file")
    p.set_defaults(func=_cmd_import_csv)

    p = sub.add_parser("calibrate", help="identify the parameter errors from a campaign")
    _add_campaign_args(p)
    p.add_argument(
        "--lambda",
        dest="lambda_",
        default="auto",
        help="auto (L-curve corner), gcv, or a fixed value (default %(default)s)",
    )
    p.add_argument("--json", help="also write the result to this JSON file (SI units)")
    _add_force_arg(p, "the --json file")
    p.add_argument(
        "--accept-unconverged",
        action="store_true",
        help="report an identification that did not converge instead of stopping with an error",
    )
    p.set_defaults(func=_cmd_calibrate)

    p = sub.add_parser("fk", help="tool positions of the nominal or calibrated model")
    p.add_argument("--robot", required=True, help="robot YAML file or shipped model name (paper_arm, ur10)")
    p.add_argument("--calibration", help="calibration JSON from 'calibrate --json' (default: the nominal model)")
    p.add_argument("--joints", nargs="+", help="joint values, n_joints per configuration")
    p.add_argument("--joints-file", help="CSV/whitespace file, one configuration per row")
    p.add_argument("--degrees", action="store_true", help="joint values are in degrees (default radians)")
    p.add_argument(
        "--frame",
        choices=("measurement", "base"),
        help="frame of the printed points: the measurement (tracker) frame when the calibration identified the "
        "base (default then), else the robot base frame",
    )
    p.add_argument("--json", help="also write both frames' points to this JSON file (SI units)")
    _add_force_arg(p, "the --json file")
    p.set_defaults(func=_cmd_fk)

    p = sub.add_parser("evaluate", help="Monte Carlo uncertainty of the calibrated tool position")
    _add_campaign_args(p)
    _add_test_joint_args(p)
    p.add_argument(
        "--sources",
        default=None,
        help=f"comma list of {sources_help()} (default tracker,encoder; and tracker_orientation for a 6-DOF campaign)",
    )
    p.add_argument("--out", default="robocal_report", help="report directory (default %(default)s)")
    _add_force_arg(p, "an earlier report in --out")
    _add_uncertainty_args(p, trials_default="auto")
    _add_dask_arg(p)
    p.set_defaults(func=_cmd_evaluate)

    p = sub.add_parser(
        "replay", help="replay a raw bag: detect static poses, calibrate, evaluate (same report as evaluate)"
    )
    p.add_argument("bag", help="raw recording: .mcap file or rosbag2 directory")
    p.add_argument("--robot", required=True, help="robot YAML file or shipped model name (paper_arm, ur10)")
    _add_base_unknown_arg(p)
    _add_test_joint_args(p)
    p.add_argument(
        "--sources",
        default=None,
        help=f"comma list of {sources_help()} (default tracker,encoder; and tracker_orientation with "
        "--tracker-pose-topic)",
    )
    p.add_argument("--out", default="robocal_report", help="report directory (default %(default)s)")
    _add_force_arg(p, "an earlier report in --out and the --campaign-out file")
    p.add_argument("--joint-topic", default="/joint_states", help="sensor_msgs/JointState topic (default %(default)s)")
    p.add_argument(
        "--point-topic", default="/tracker/point", help="geometry_msgs/PointStamped topic (default %(default)s)"
    )
    p.add_argument(
        "--tracker-pose-topic",
        help="6-DOF tracker: geometry_msgs/PoseStamped (or PoseWithCovarianceStamped) topic read instead of "
        "--point-topic; the campaign then holds orientations (e.g. /tracker/pose)",
    )
    p.add_argument("--tracker-frame", help="frame_id of valid tracker points (default: the most frequent)")
    p.add_argument(
        "--window-s",
        default="auto",
        help="static window length, s, or auto: 0.5 s, shortened to half the typical still interval of the "
        "joints when the recording's dwells are shorter (default %(default)s)",
    )
    p.add_argument(
        "--joint-motion-threshold-rad",
        type=float,
        default=5e-4,
        help="max joint motion in a static window, rad (default %(default)s)",
    )
    p.add_argument(
        "--tracker-scatter-threshold-m",
        type=float,
        default=1e-4,
        help="max tracker scatter in a static window, m (default %(default)s)",
    )
    p.add_argument(
        "--orientation-scatter-threshold-rad",
        type=float,
        default=2e-3,
        help="6-DOF tracker: max range of any rotation-matrix entry in a static window, rad (default %(default)s)",
    )
    p.add_argument(
        "--min-points", type=int, default=10, help="min tracker points averaged per static pose (default %(default)s)"
    )
    p.add_argument("--campaign-out", help="also write the collected campaign MCAP here")
    _add_uncertainty_args(p, trials_default="auto")
    p.set_defaults(func=_cmd_replay)

    p = sub.add_parser(
        "validate",
        help="prove the uncertainty statement: calibrate on some poses, check the coverage of held-out measurements",
    )
    _add_campaign_args(p)
    split = p.add_argument_group("what is held out (default: --holdout-fraction 0.25)")
    split.add_argument("--train-poses", type=int, help="calibrate on this many random poses, hold out the rest")
    split.add_argument("--holdout-fraction", type=float, help="fraction of the poses held out at random")
    split.add_argument("--k-folds", type=int, help="k-fold cross-validation: every pose held out once")
    split.add_argument("--validation-campaign", help="a second campaign of the same tracker set-up, held out whole")
    p.add_argument(
        "--sources",
        default=None,
        help=f"sources of the statement under test: {sources_help()} (default tracker,encoder,residual; "
        "and tracker_orientation for a 6-DOF campaign)",
    )
    p.add_argument("--out", default="robocal_validation", help="report directory (default %(default)s)")
    _add_force_arg(p, "an earlier report in --out")
    _add_uncertainty_args(p, trials_default="5000")
    p.set_defaults(func=_cmd_validate)

    p = sub.add_parser("map", help="uncertainty map over the workspace: u at many configurations, where it is weakest")
    p.add_argument("campaign", help="campaign: .mcap file or rosbag2 directory")
    p.add_argument("--robot", required=True, help="robot YAML file or shipped model name (paper_arm, ur10)")
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
    p.add_argument("--sources", default="tracker,encoder", help=f"comma list of {sources_help()} (default %(default)s)")
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
    _add_force_arg(p, "an earlier map report in --out")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    _add_frame_and_convergence_args(p)
    p.set_defaults(func=_cmd_map, lambda_range=None, min_poses=None, subset_size=None)

    p = sub.add_parser(
        "suggest",
        help="next-best poses: the configurations whose measurement lowers the uncertainty at the test "
        "configurations most (first-order ranking, optional Monte Carlo check)",
    )
    _add_campaign_args(p)
    p.add_argument("--test-joints", nargs="+", help="joint values of the test configurations, n_joints each")
    p.add_argument("--test-joints-file", help="CSV/whitespace file of test configurations, one per row")
    p.add_argument(
        "--degrees",
        action="store_true",
        help="joint values (--test-joints, --candidates-file, the printed table and --csv) are in degrees "
        "(default radians)",
    )
    p.add_argument("--count", type=int, default=5, help="number of poses suggested, best first (default %(default)s)")
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--candidates",
        type=int,
        default=500,
        help="rank this many configurations drawn uniformly inside the joint limits less 0.05 rad, with --seed "
        "(default %(default)s)",
    )
    where.add_argument("--candidates-file", help="rank these configurations instead: CSV/whitespace file, one per row")
    p.add_argument(
        "--check",
        type=int,
        default=0,
        help="Monte Carlo check of the first K suggestions: the campaign with suggestions 1..k added as simulated "
        "measurements is evaluated (default %(default)s: none)",
    )
    p.add_argument("--trials", type=int, default=2000, help="Monte Carlo trials per check (default %(default)s)")
    p.add_argument(
        "--seed", type=int, default=0, help="seed of the candidate draw and of every check (default %(default)s)"
    )
    p.add_argument(
        "--sources",
        default="tracker,encoder",
        help="the ranking weighs the poses with the tracker and encoder noise (each only if listed); the checks use "
        f"every listed source: {sources_help()} (default %(default)s)",
    )
    p.add_argument("--lambda", dest="lambda_", default="auto", help="auto (L-curve corner), gcv, or a fixed value")
    _add_noise_args(p)
    p.add_argument("--json", help="write the suggestions to this JSON file (SI units, also degrees)")
    p.add_argument(
        "--csv",
        dest="csv_out",
        help="write the suggested joint positions to this CSV file, best first, in rad (deg with --degrees)",
    )
    _add_force_arg(p, "the --json and --csv files")
    _add_frame_and_convergence_args(p)
    p.set_defaults(func=_cmd_suggest, lambda_range=None, min_poses=None, subset_size=None)

    p = sub.add_parser(
        "section",
        help="blade-section parameters (thickness, chord, offsets, twist, profiles) and their Monte Carlo "
        "uncertainty from a CMM point cloud or a PointCloud2 bag",
    )
    p.add_argument("cloud", nargs="?", help="CMM export (x y z [i j k], unit stated) or .mcap/rosbag2 with PointCloud2")
    p.add_argument("--demo", action="store_true", help="simulated 1836-point scan of the shipped Rotor 37 section")
    p.add_argument("--nominal", help="nominal section file, or a shipped blade: rotor37, rotor37:K, cascade")
    p.add_argument(
        "--unit", help="length unit of CLOUD when the file states none: m, mm, um, in (default: none assumed)"
    )
    p.add_argument("--nominal-unit", help="length unit of the --nominal file when it states none")
    p.add_argument("--instrument", help="instrument YAML or shipped name (default: cmm_seed, the seed's CMM)")
    p.add_argument("--topic", help="PointCloud2 topic of a bag (default: its only PointCloud2 topic)")
    p.add_argument("--message", type=int, help="0-based message index in the topic (default: all messages joined)")
    p.add_argument(
        "--repeat-scans",
        nargs="+",
        metavar="CLOUD",
        help="2 or more repeated scans of the same section (formats and --unit as CLOUD): their standard "
        "deviation is the GUM budget's u3 (repeatability), shown for the chord as in the seed's table",
    )
    p.add_argument(
        "--trials", help="Monte Carlo trials, or auto (JCGM 101 7.9) (default 1000000, the seed's; --demo 100000)"
    )
    p.add_argument("--seed", type=int, default=0, help="root seed of the random streams (default %(default)s)")
    p.add_argument(
        "--workers", type=int, default=1, help="worker processes (never changes the result; default %(default)s)"
    )
    p.add_argument(
        "--method",
        choices=("denoised", "seed"),
        default="denoised",
        help="denoised: Monte Carlo of the error around the denoised cloud (intervals coverage-verified); "
        "seed: perturb the measured cloud as the seed does (max/min intervals under-cover) (default %(default)s)",
    )
    p.add_argument("--out", default="section_report", help="report directory (default %(default)s)")
    _add_force_arg(p, "an earlier report in --out")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_section)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit status."""
    parser = _build_parser()
    args = parser.parse_args(argv)
    try:
        _check_options(args)
        _check_outputs(args)
        return int(args.func(args))
    except CalibError as err:
        print(f"robocal-uncertainty {args.command}: error: {_in_cli_words(str(err))}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"robocal-uncertainty {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (e.g. `| head`): stop quietly, as command-line tools do.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141
    except OSError as err:
        # The checks before the work cannot foresee everything (a full disk, a directory
        # removed or made read-only during the run): still one line, naming the file.
        where = f" {err.filename}" if err.filename is not None else ""
        print(
            f"robocal-uncertainty {args.command}: error: cannot access{where}: {err.strerror or err}", file=sys.stderr
        )
        return 1


if __name__ == "__main__":
    sys.exit(main())
