"""Seconds per simulated scan of the per-cloud coverage study (``section CLOUD --coverage-study N``).

For each cloud written by ``benchmarks/section_study_clouds.py`` this builds the cloud's study
scenario and times :func:`~robocal_uncertainty.inspection.coverage_study.study_scan` (method
``denoised``, 2 000 trials, the smooth family) on a few scans, one process, and prints the
median per scan and what N scans per family (four families) would take on one worker. The
outcomes of the scans are printed too: a speed-up must not change them.

Run: ``python benchmarks/section_study_clouds.py --out section_clouds`` then
``python benchmarks/section_scan_time.py section_clouds/rotor37_400.txt ... [--scans 3]``.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from robocal_uncertainty.app.section_inspection import load_section_nominal, resolve_instrument
from robocal_uncertainty.inspection.coverage_study import scenario_from_cloud, study_scan
from robocal_uncertainty.inspection.point_cloud import read_point_cloud

NOMINALS = {"cascade": "cascade", "rotor37": "rotor37"}
INSTRUMENTS = {"cmm09": "config/instruments/cmm_0.9_400.yaml"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("clouds", nargs="+", type=Path, help="clouds of section_study_clouds.py")
    parser.add_argument("--scans", type=int, default=3, help="scans timed per cloud (default %(default)s)")
    parser.add_argument("--per-family", type=int, default=200, help="N for the projected study time")
    args = parser.parse_args()
    for path in args.clouds:
        nominal = NOMINALS[path.stem.split("_")[0]]
        instrument = next((v for k, v in INSTRUMENTS.items() if k in path.stem), "cmm_reference_paper")
        curve = load_section_nominal(nominal)
        scenario = scenario_from_cloud(read_point_cloud(path), curve, resolve_instrument(instrument)[0])
        scenario.landmarks  # noqa: B018  (built once per study, not per scan)
        seconds, outcomes = [], []
        for index in range(args.scans):
            start = time.perf_counter()
            outcome = study_scan("smooth", index, scenario=scenario)
            seconds.append(time.perf_counter() - start)
            outcomes.append("".join("1" if v else "0" for v in outcome.inside) + ("F" if outcome.flagged else ""))
        per_scan = statistics.median(seconds)
        total = per_scan * 4 * args.per_family / 60.0
        print(
            f"{path.name}: {scenario.n_points} points, {per_scan:.2f} s per scan (median of {args.scans}); "
            f"N = {args.per_family} per family: {total:.1f} min on 1 worker; outcomes {' '.join(outcomes)}",
            flush=True,
        )


if __name__ == "__main__":
    main()
