"""``robocal-uncertainty section``: its options (:func:`register`) and its work and printing (:func:`run`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from robocal_uncertainty.cli._common import parse_trials, timed_progress
from robocal_uncertainty.cli._options import add_backend_arg, add_dask_arg, add_force_arg
from robocal_uncertainty.errors import ConfigError


def register(sub: Any) -> None:
    """Add the ``section`` command and its options to the subparsers `sub`."""
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
    p.add_argument(
        "--instrument", help="instrument YAML or shipped name (default: cmm_reference_paper, the reference paper's CMM)"
    )
    p.add_argument("--topic", help="PointCloud2 topic of a bag (default: its only PointCloud2 topic)")
    p.add_argument("--message", type=int, help="0-based message index in the topic (default: all messages joined)")
    p.add_argument(
        "--repeat-scans",
        nargs="+",
        metavar="CLOUD",
        help="2 or more repeated scans of the same section (formats and --unit as CLOUD): their standard "
        "deviation is the GUM budget's u3 (repeatability), shown for the chord as in the reference paper's table",
    )
    p.add_argument(
        "--trials",
        help="Monte Carlo trials, or auto (JCGM 101 7.9) (default 1000000, the reference paper's; --demo 100000)",
    )
    p.add_argument("--seed", type=int, default=0, help="root seed of the random streams (default %(default)s)")
    p.add_argument(
        "--workers", type=int, default=1, help="worker processes (never changes the result; default %(default)s)"
    )
    p.add_argument(
        "--method",
        choices=("denoised", "perturbed", "seed"),
        default="denoised",
        help="denoised: Monte Carlo of the error around the denoised cloud (coverage-verified unless the cloud's "
        "residual check flags it); "
        "perturbed: perturb the measured cloud as the reference paper does (max/min intervals under-cover); "
        "seed: deprecated name of perturbed (default %(default)s)",
    )
    p.add_argument(
        "--coverage-study",
        type=int,
        metavar="N",
        help="also run the coverage study of this cloud: N simulated scans per family (smooth, side, edge, "
        "erosion) of its nominal, point layout, probe vectors and instrument, forms scaled to its level; "
        "the verdict becomes 'verified for this part, layout and instrument' or not (at least 53 unflagged "
        "scans per family are needed to verify; method denoised only)",
    )
    p.add_argument("--study-seed", type=int, default=23, help="root seed of the coverage study (default %(default)s)")
    p.add_argument(
        "--study-trials", type=int, default=2000, help="Monte Carlo trials per study scan (default %(default)s)"
    )
    add_backend_arg(p)
    add_dask_arg(p)
    p.add_argument("--out", default="section_report", help="report directory (default %(default)s)")
    add_force_arg(p, "an earlier report in --out")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from robocal_uncertainty.montecarlo.engine import AdaptiveSettings

    _check_args(args)
    trials = parse_trials(args.trials) if args.trials is not None else (100_000 if args.demo else 1_000_000)
    adaptive = AdaptiveSettings() if trials == "auto" else None
    count = None if trials == "auto" else int(trials)
    progress, finish = timed_progress(not args.no_progress, "section")
    pool = _early_pool(args)
    try:
        run = _inspect(args, count, adaptive, progress, pool)
    finally:
        finish()
        if pool is not None:
            pool.close()
    if args.coverage_study is not None:
        run = _coverage_study(run, args)
    _print_and_write(run, args)
    return 0


def _check_args(args: argparse.Namespace) -> None:
    """One-line errors for option combinations that cannot run; the deprecated method name mapped."""
    from robocal_uncertainty.app.section_inspection import RENAMED_INSTRUMENTS
    from robocal_uncertainty.inspection.section_mc import DEPRECATED_METHODS

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
    if args.method in DEPRECATED_METHODS:
        new = DEPRECATED_METHODS[args.method]
        print(
            f"robocal-uncertainty section: warning: --method {args.method} is deprecated, use --method {new}",
            file=sys.stderr,
        )
        args.method = new
    if args.instrument in RENAMED_INSTRUMENTS and not Path(args.instrument).is_file():
        new = RENAMED_INSTRUMENTS[args.instrument]
        print(
            f"robocal-uncertainty section: warning: --instrument {args.instrument} is deprecated, use {new}",
            file=sys.stderr,
        )
        args.instrument = new
    if args.coverage_study is not None and args.coverage_study < 1:
        raise ConfigError(f"--coverage-study needs N >= 1 scans per family, got {args.coverage_study}")
    if args.coverage_study is not None and args.method != "denoised":
        raise ConfigError("--coverage-study runs method denoised on every simulated scan: give --method denoised")
    if args.study_seed < 0 or args.study_trials < 100:
        raise ConfigError("--study-seed must be >= 0 and --study-trials >= 100")
    if args.dask is not None and args.coverage_study is None:
        raise ConfigError("--dask runs the scans of --coverage-study; give --coverage-study N")
    from robocal_uncertainty.kernels.section_kernels import resolve_section_backend

    resolve_section_backend(args.backend)  # an unknown, missing or kernel-less backend stops here


def _early_pool(args: argparse.Namespace) -> Any:
    """The Monte Carlo's worker processes, started now (None for one worker).

    They start (a fresh interpreter each, the imports, numba's kernels from its disk cache)
    while this process reads or simulates the cloud, denoises it and prepares the trials,
    instead of after: about 2 s of a two-worker run on this project's 2-core machine. The
    result is the same: the blocks and their streams do not depend on where they run.
    """
    if args.workers <= 1:
        return None
    from robocal_uncertainty.kernels.section_kernels import resolve_section_backend
    from robocal_uncertainty.montecarlo.executor import WorkerPool

    preload = ["robocal_uncertainty.inspection.section_mc"]
    if resolve_section_backend(args.backend).name == "numba":
        preload.append("robocal_uncertainty.kernels.section_kernels:warm_up")
    pool = WorkerPool(args.workers, preload=tuple(preload))
    pool.start(wait=False)
    return pool


def _inspect(args: argparse.Namespace, count: int | None, adaptive: Any, progress: Any, pool: Any = None) -> Any:
    """The demo or the inspection of CLOUD (:mod:`robocal_uncertainty.app.section_inspection`)."""
    from robocal_uncertainty.app.section_inspection import DEMO_SCENARIO, inspect_section, section_demo

    executor = None if pool is None else pool.executor()

    if args.demo:
        print(
            "Demo: NASA Rotor 37 surface 2 at the reference paper's size (x7.14), a simulated "
            f"{DEMO_SCENARIO['n_points']}-point "
            "CMM scan with offsets (-0.1013, 0.0538) mm, twist 0.0512 deg, a 5 µm 3-wave form error and one draw "
            "of the instrument errors; the true parameters are known."
        )
        return section_demo(
            trials=count,
            adaptive=adaptive,
            seed=args.seed,
            workers=args.workers,
            instrument=args.instrument,
            progress=progress,
            method=args.method,
            backend=args.backend,
            executor=executor,
        )
    return inspect_section(
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
        backend=args.backend,
        executor=executor,
    )


def _print_and_write(run: Any, args: argparse.Namespace) -> None:
    """The console table and note, then the report in ``args.out``."""
    from robocal_uncertainty.app.output_paths import clear_earlier_report
    from robocal_uncertainty.report.section_report import (
        coverage_summary,
        format_repeatability_budget,
        format_section_table,
        write_section_report,
    )

    result = run.result
    frame = f", frame {run.cloud.frame_id}" if run.cloud.frame_id else ""
    print(
        f"{run.cloud.n_points} points ({run.cloud.source}{frame}); nominal {run.nominal}; instrument {run.instrument}; "
        f"{result.monte_carlo.n_trials} trials, seed {result.monte_carlo.seed}, {run.elapsed_s:.1f} s"
        + ("" if result.backend is None else f", backend {result.backend.describe()}")
    )
    print()
    print(format_section_table(result, run.corrections, truth=run.truth, study=run.study))
    print()
    if result.gum_with_repeatability is not None:
        print(format_repeatability_budget(result))
        print()
    print(f"note: {coverage_summary(result, run.study)}")
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
    files = write_section_report(result, run.corrections, args.out, truth=run.truth, extra=extra, study=run.study)
    print(f"section report written to {files.markdown.parent}")


def _coverage_study(run: Any, args: argparse.Namespace) -> Any:
    """Run the cloud's own coverage study, printing the expected time first and progress on stderr."""
    import time

    from robocal_uncertainty.app.section_inspection import section_coverage_study
    from robocal_uncertainty.inspection.coverage_rule import MIN_STUDY_SCANS
    from robocal_uncertainty.inspection.coverage_study import FAMILIES
    from robocal_uncertainty.kernels.section_kernels import resolve_section_backend

    scans = int(args.coverage_study)
    total = scans * len(FAMILIES)
    workers = max(1, int(args.workers))
    start = time.perf_counter()
    print(
        f"Coverage study of this cloud: {scans} scans per family x {len(FAMILIES)} families = {total} simulated "
        f"scans of its nominal, layout and instrument, {args.study_trials} trials each, study seed {args.study_seed}, "
        f"trial kernels {resolve_section_backend(args.backend).describe()}",
        flush=True,
    )
    if scans < MIN_STUDY_SCANS:
        print(
            f"  note: with fewer than {MIN_STUDY_SCANS} scans per family nothing can be verified (a family needs "
            f"{MIN_STUDY_SCANS} scans its residual check does not flag; the stored study's check flagged 5-34 % "
            "of each family's scans)",
            flush=True,
        )

    def estimate(seconds: float) -> None:
        expected = seconds * (total - 1) / workers
        print(
            f"  first scan {seconds:.1f} s: expected {expected / 60:.1f} min more for the other {total - 1} "
            f"on {workers} worker(s)",
            flush=True,
        )

    step = max(1, total // 10)

    def progress(done: int, target: int) -> None:
        if not args.no_progress and (done % step == 0 or done == target):
            print(f"  study: {done}/{target} scans, {time.perf_counter() - start:.0f} s", file=sys.stderr, flush=True)

    return section_coverage_study(
        run,
        scans,
        seed=args.study_seed,
        trials=args.study_trials,
        workers=workers,
        dask=args.dask,
        progress=progress,
        estimate=estimate,
        backend=args.backend,
    )
