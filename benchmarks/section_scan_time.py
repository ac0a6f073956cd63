"""Seconds per simulated scan of the per-cloud coverage study (``section CLOUD --coverage-study N``).

For each cloud written by ``benchmarks/section_study_clouds.py`` this builds the cloud's study
scenario and times :func:`~robocal_uncertainty.inspection.coverage_study.study_scan` (method
``denoised``, 2 000 trials, the smooth family) on a few scans, one process, and prints the
median per scan and what N scans per family (four families) would take on one worker. The
outcomes of the scans are printed too: a speed-up must not change them. ``--profile`` also
prints where one scan's time goes (cProfile, cumulative, the package's functions).

Run: ``python benchmarks/section_study_clouds.py --out section_clouds`` then
``python benchmarks/section_scan_time.py section_clouds/rotor37_400.txt ... [--scans 3]
[--backend auto|numpy|numba] [--profile]`` (the scans' denoising and Monte Carlo on that
backend, default auto). ``--backend`` given twice (``--backend numpy --backend numba``) times
both on the same scans, alternating scan by scan so that a changing machine load falls on both
alike, and prints their ratio and whether the outcomes agree.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import statistics
import time
from pathlib import Path

from robocal_uncertainty.app.section_inspection import load_section_nominal, resolve_instrument
from robocal_uncertainty.inspection.coverage_study import scenario_from_cloud, study_scan
from robocal_uncertainty.inspection.point_cloud import read_point_cloud
from robocal_uncertainty.kernels.section_kernels import resolve_section_backend, warm_up

NOMINALS = {"cascade": "cascade", "rotor37": "rotor37"}
INSTRUMENTS = {"cmm09": "config/instruments/cmm_0.9_400.yaml"}


def _print_profile(profiler: cProfile.Profile) -> None:
    """The package's functions by cumulative time (share of the scan)."""
    stats = pstats.Stats(profiler)
    total = max(v[3] for v in stats.stats.values())  # type: ignore[attr-defined]
    rows = [
        (cumulative, f"{Path(file).stem}.{name}")
        for (file, _, name), (_, _, _, cumulative, _) in stats.stats.items()  # type: ignore[attr-defined]
        if "robocal_uncertainty" in file and not name.startswith("<")
    ]
    for cumulative, label in sorted(rows, reverse=True)[:14]:
        print(f"    {cumulative:7.2f} s {cumulative / total:5.0%}  {label}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("clouds", nargs="+", type=Path, help="clouds of section_study_clouds.py")
    parser.add_argument("--scans", type=int, default=3, help="scans timed per cloud (default %(default)s)")
    parser.add_argument("--per-family", type=int, default=200, help="N for the projected study time")
    parser.add_argument(
        "--backend",
        action="append",
        help="denoising and trial kernels of the scans (default auto); twice: both, alternating",
    )
    parser.add_argument("--profile", action="store_true", help="print where the first scan's time goes")
    args = parser.parse_args()
    backends = [resolve_section_backend(name) for name in (args.backend or ["auto"])]
    if any(b.name == "numba" for b in backends):
        warm_up()  # compiled or loaded from the disk cache before any scan is timed
    for path in args.clouds:
        nominal = NOMINALS[path.stem.split("_")[0]]
        instrument = next((v for k, v in INSTRUMENTS.items() if k in path.stem), "cmm_reference_paper")
        curve = load_section_nominal(nominal)
        scenario = scenario_from_cloud(read_point_cloud(path), curve, resolve_instrument(instrument)[0])
        scenario.landmarks  # noqa: B018  (built once per study, not per scan)
        if any(b.name == "numba" for b in backends):  # the denoising's kernels compiled before timing
            study_scan("smooth", 0, trials=100, scenario=scenario, backend="numba")
        seconds: dict[str, list[float]] = {b.name: [] for b in backends}
        outcomes: dict[str, list[str]] = {b.name: [] for b in backends}
        for index in range(args.scans):
            for backend in backends:
                start = time.perf_counter()
                profiler = cProfile.Profile() if args.profile and index == 0 else None
                if profiler is not None:
                    profiler.enable()
                outcome = study_scan("smooth", index, scenario=scenario, backend=backend.name)
                seconds[backend.name].append(time.perf_counter() - start)
                if profiler is not None:
                    profiler.disable()
                    print(f"  {backend.name}:")
                    _print_profile(profiler)
                flags = "".join("1" if v else "0" for v in outcome.inside) + ("F" if outcome.flagged else "")
                outcomes[backend.name].append(flags)
        for backend in backends:
            per_scan = statistics.median(seconds[backend.name])
            total = per_scan * 4 * args.per_family / 60.0
            print(
                f"{path.name}: {scenario.n_points} points, {per_scan:.2f} s per scan (median of {args.scans}, "
                f"denoising and trials on {backend.describe()}); "
                f"N = {args.per_family} per family: {total:.1f} min on 1 worker; "
                f"outcomes {' '.join(outcomes[backend.name])}",
                flush=True,
            )
        if len(backends) == 2:
            first, second = (b.name for b in backends)
            ratio = statistics.median(seconds[first]) / statistics.median(seconds[second])
            same = "the same" if outcomes[first] == outcomes[second] else "DIFFERENT"
            print(f"  {first} / {second}: {ratio:.2f}x per scan; outcomes {same}", flush=True)


if __name__ == "__main__":
    main()
