"""How often the family study's verification rule fails a study, by simulation of the binomial counts.

For the unflagged scan counts of the stored family study (``FAMILY_STUDY``, 9 parameters per
family), draw every cell's count of intervals that hold the truth from Binomial(N, c) and apply
the rule per cell (exact one-sided 5 % test, 92 % floor), the rule the report uses (the same
test Holm-adjusted over the study's cells) and the 92 % floor alone (no test). Prints, per rule,
the fraction of simulated studies in which some cell is not verified when every cell covers
c = 95 % (false failures), and the fraction of cells not verified when they cover 93, 92 or 91 %
(the power against a real shortfall).
The nine parameters of a family share their scans; drawing them independently is the setting in
which Holm's bound is tight (with positive correlation it fails fewer studies).

Run: ``python benchmarks/coverage_rule_study.py [--studies 4000] [--scans-scale 1.0] [--seed 1]``.
"""

from __future__ import annotations

import argparse

import numpy as np

from robocal_uncertainty.inspection.coverage_rule import binomial_tail, coverage_verified, holm_adjusted
from robocal_uncertainty.inspection.stored_studies import FAMILY_STUDY


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--studies", type=int, default=4000, help="simulated studies per coverage")
    parser.add_argument(
        "--scans-scale", type=float, default=1.0, help="scale the stored unflagged counts (1/3: a 200-scan study)"
    )
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    kept = np.array(
        [round((c.scans - c.flagged) * args.scans_scale) for study in FAMILY_STUDY.values() for c in study.values()]
    )
    rng = np.random.default_rng(args.seed)
    print(f"{kept.size} cells, unflagged scans per cell {kept.min()}-{kept.max()}, {args.studies} studies per row")
    print(f"{'coverage':>8s} {'rule':>9s} {'studies with a failed cell':>28s} {'cells failed':>13s}")
    for coverage in (0.95, 0.93, 0.92, 0.91):
        inside = rng.binomial(kept, coverage, size=(args.studies, kept.size))
        for rule in ("per cell", "Holm", "floor"):
            failed = np.empty(inside.shape, dtype=bool)
            for s, counts in enumerate(inside):
                tails = [binomial_tail(int(k), int(n)) for k, n in zip(counts, kept)]
                p = holm_adjusted(tails) if rule == "Holm" else [1.0] * len(tails) if rule == "floor" else tails
                failed[s] = [not coverage_verified(int(k), int(n), p_value=q) for k, n, q in zip(counts, kept, p)]
            print(f"{coverage:8.0%} {rule:>9s} {failed.any(axis=1).mean():28.3f} {failed.mean():13.3f}")


if __name__ == "__main__":
    main()
