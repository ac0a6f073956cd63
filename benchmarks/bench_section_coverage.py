"""Coverage study of the section intervals over scenario families of simulated parts (issue 23).

Families (``robocal_uncertainty.inspection.coverage_study``): ``smooth`` (form errors of 2-13
waves, 2-10 µm), ``side`` (a bump or dent of 1-10 µm over 1-20 mm on a side), ``edge`` (the same
within ±10 mm of the leading or trailing edge), ``erosion`` (an edge flattened by 1-10 µm over
1-20 mm). Each scan: one random part of the family, its noise-free scan evaluated by the
package's parameter extraction (the truth), one draw of the reference paper's CMM errors, method
``denoised`` with ``--trials`` Monte Carlo trials, and the residual check.

Run: ``python benchmarks/bench_section_coverage.py [--scans 60] [--workers 2] [--families ...] [--seed 23]
[--first 0]``.
Prints per family and parameter the coverage over all scans and over the scans the check did
not flag (± the binomial standard uncertainty at 95 %), the flagged count, the time, and the
counts in the form of ``inspection.stored_studies.FAMILY_COUNTS``.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from robocal_uncertainty.inspection.coverage_study import FAMILIES, run_study, summarize_study
from robocal_uncertainty.inspection.section import PARAMETER_NAMES


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scans", type=int, default=60, help="scans per family")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--trials", type=int, default=2000, help="Monte Carlo trials per scan")
    parser.add_argument("--families", nargs="+", default=list(FAMILIES), choices=FAMILIES)
    parser.add_argument("--seed", type=int, default=23, help="root seed of the study (the stored study: 23)")
    parser.add_argument(
        "--first", type=int, default=0, help="first scan index (scans first .. first + scans - 1 of every family)"
    )
    parser.add_argument("--misses", action="store_true", help="list every scan with a miss")
    args = parser.parse_args()

    start = time.perf_counter()
    outcomes = run_study(
        args.families, args.scans, trials=args.trials, workers=args.workers, root_seed=args.seed, first=args.first
    )
    elapsed = time.perf_counter() - start
    rows = summarize_study(outcomes)
    print(
        f"{len(outcomes)} scans ({args.scans} per family), {args.trials} trials each, {args.workers} workers: "
        f"root seed {args.seed}, scans {args.first}-{args.first + args.scans - 1}: {elapsed:.0f} s"
    )
    print("coverage of the 95 % intervals: unflagged scans (± binomial u) / all scans")
    print(f"{'parameter':24s} " + " ".join(f"{f:>26s}" for f in args.families))
    for name in PARAMETER_NAMES:
        cells = []
        for family in args.families:
            row = next(r for r in rows if r.family == family and r.parameter == name)
            cells.append(f"{row.coverage_unflagged:6.1%} ± {row.u_unflagged:4.1%} / {row.coverage_all:6.1%}")
        print(f"{name:24s} " + " ".join(f"{c:>26s}" for c in cells))
    print(
        f"{'flagged':24s} " + " ".join(f"{next(r for r in rows if r.family == f).flagged:>26d}" for f in args.families)
    )
    print("counts (scans, flagged, inside among unflagged, inside among all):")
    for family in args.families:
        chosen = [o for o in outcomes if o.family == family]
        inside = np.array([o.inside for o in chosen])
        flagged = np.array([o.flagged for o in chosen])
        kept = tuple(int(v) for v in inside[~flagged].sum(axis=0))
        every = tuple(int(v) for v in inside.sum(axis=0))
        print(f'    "{family}": ({len(chosen)}, {int(flagged.sum())}, {kept}, {every}),')
    if args.misses:
        for o in outcomes:
            if not o.inside.all():
                missed = ", ".join(PARAMETER_NAMES[j] for j in np.flatnonzero(~o.inside))
                p = "" if math.isnan(o.p_value) else f" p={o.p_value:.3f}"
                print(f"{o.family} {o.index}{' FLAGGED' if o.flagged else ''}{p}: {missed} ({o.part.describe()})")


if __name__ == "__main__":
    main()
