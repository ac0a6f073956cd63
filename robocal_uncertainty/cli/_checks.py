"""Early checks: every option and output path is checked before any computation, with the
command line's own words (flags, units, 1-based counts)."""

from __future__ import annotations

import argparse
import os
import re
from pathlib import Path

import numpy as np

from robocal_uncertainty.cli._common import flag, parse_lambda, parse_trials, parse_window
from robocal_uncertainty.errors import ConfigError

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
    ("linear_encoder_noise_um", "um"),
    ("pairing_tolerance_ms", "ms"),
)


_POSITIVE_FLOATS = (("joint_motion_threshold_rad", "rad"), ("tracker_scatter_threshold_m", "m"))


def check_options(args: argparse.Namespace) -> None:
    """Refuse bad option values before anything is read or computed (one line each)."""
    _check_number_options(args)
    _check_monte_carlo_options(args)
    _check_study_options(args)


def _check_number_options(args: argparse.Namespace) -> None:
    """The options that are positive or non-negative integers or finite numbers."""
    for dest in _POSITIVE_INTS:
        value = getattr(args, dest, None)
        if value is not None and value < 1:
            msg = f"{flag(dest)} must be a positive integer, got {value}"
            raise ConfigError(msg)
    for dest in _NON_NEGATIVE_INTS:
        value = getattr(args, dest, None)
        if value is not None and value < 0:
            msg = f"{flag(dest)} must be an integer >= 0, got {value}"
            raise ConfigError(msg)
    for dest, unit in _NON_NEGATIVE_FLOATS:
        value = getattr(args, dest, None)
        if value is not None and not (np.isfinite(value) and value >= 0):
            msg = f"{flag(dest)} must be a finite number >= 0 {unit}, got {value:g}"
            raise ConfigError(msg)
    for dest, unit in _POSITIVE_FLOATS:
        value = getattr(args, dest, None)
        if value is not None and not (np.isfinite(value) and value > 0):
            msg = f"{flag(dest)} must be a finite number > 0 {unit}, got {value:g}"
            raise ConfigError(msg)


def _check_monte_carlo_options(args: argparse.Namespace) -> None:
    """--trials, --coverage and --lambda, and whether the trials can state the coverage interval."""
    trials = getattr(args, "trials", None)
    if isinstance(trials, str):
        parse_trials(trials)
    elif trials is not None and trials < 1:
        msg = f"--trials must be a positive integer, got {trials}"
        raise ConfigError(msg)
    coverage = getattr(args, "coverage", None)
    if coverage is not None and not 0.0 < coverage < 1.0:
        hint = f"; did you mean {coverage / 100:g}?" if 50.0 <= coverage < 100.0 else ""
        msg = f"--coverage is a probability in (0, 1), got {coverage:g}{hint}"
        raise ConfigError(msg)
    if getattr(args, "lambda_", None) is not None:
        parse_lambda(args.lambda_)
    fixed = parse_trials(trials) if isinstance(trials, str) else trials
    if isinstance(fixed, int) and coverage is not None and 0.0 < coverage < 1.0 and args.command != "section":
        from robocal_uncertainty.uncertainty.statement_check import interval_trial_floor, recommended_trials

        floor = interval_trial_floor(coverage)
        if fixed < floor:
            msg = (
                f"--trials {fixed} cannot state a {coverage * 100:g} % coverage interval: below 2/(1-p) = {floor} "
                f"trials not one trial lies beyond either end (JCGM 101 7.2); give --trials "
                f"{recommended_trials(coverage)} or more, or --trials auto"
            )
            raise ConfigError(msg)


def _check_study_options(args: argparse.Namespace) -> None:
    """The options of particular verbs: lambda range, hold-out, folds, window, grid, suggest counts, dask."""
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
        parse_window(window)
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


def check_outputs(args: argparse.Namespace) -> None:
    """Refuse output paths that cannot or must not be written, before any work (--force rule)."""
    from robocal_uncertainty.app.output_paths import check_output_file, check_report_directory, claim_report_directory
    from robocal_uncertainty.app.simulation import truth_path

    force = bool(getattr(args, "force", False))
    sessions = args.command == "simulate" and (
        getattr(args, "sessions", None) is not None or getattr(args, "session_poses", None) is not None
    )
    if args.command in ("simulate", "import-csv") and not sessions:
        check_output_file(args.out, force=force, option="--out")
        if args.command == "simulate":
            check_output_file(truth_path(args.out), force=force, option="truth file")
    elif args.command in ("demo", "evaluate", "replay", "validate", "map", "section"):
        check_report_directory(args.out, force=force, option="--out")
        # Claimed before the work: a second command on the same --out refuses instead of
        # silently replacing this one's report (released when the command ends).
        claim_report_directory(args.out, option="--out")
    if getattr(args, "csv_out", None):
        check_output_file(args.csv_out, force=force, option="--csv")
        if args.json and Path(args.json).resolve() == Path(args.csv_out).resolve():
            msg = f"--json and --csv name the same file {args.json}"
            raise ConfigError(msg)
    if getattr(args, "json", None):
        check_output_file(args.json, force=force, option="--json")
    if getattr(args, "campaign_out", None):
        check_output_file(args.campaign_out, force=force, option="--campaign-out")
    check_outputs_are_not_inputs(args)


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


def check_outputs_are_not_inputs(args: argparse.Namespace) -> None:
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
