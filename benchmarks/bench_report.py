"""Time and size of write_report with many test configurations against one.

Both reports come from the same simulated 53-pose campaign of the seed's arm (tracker
and encoder noise, 200 trials by default): one evaluated at a single test configuration,
one at 150 configurations drawn inside the joint limits. Each report is written into a
fresh temporary directory; the wall time of ``write_report`` and the size of the
directory are printed, with the ratios of the many-configuration report to the
single-configuration one. Issue 10 asks for under 10 s and under 5 MB at 150
configurations; nothing here is a pass/fail test.

``--histograms all`` draws the per-configuration figures of every configuration, as
reports did before they scaled (84 s and 40 MB for 150 configurations then).

Usage: python benchmarks/bench_report.py [--configurations 150] [--trials 200] [--histograms N|all]
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from robocal_uncertainty.core import SimulationSettings, load_robot_model, simulate_campaign
from robocal_uncertainty.core.simulation import draw_joint_positions
from robocal_uncertainty.report import write_report
from robocal_uncertainty.uncertainty import UncertaintySettings, evaluate_uncertainty

REPO = Path(__file__).resolve().parents[1]


def _histograms(text: str | None) -> int | str | None:
    if text is None or text == "all":
        return text
    return int(text)


def _write(result, histograms) -> tuple[float, int, int]:
    """Seconds, bytes and PNG count of one report written to a temporary directory."""
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        write_report(Path(tmp) / "report", result, robot_name="paper_arm", histograms=histograms)
        elapsed = time.perf_counter() - start
        files = [p for p in (Path(tmp) / "report").iterdir() if p.is_file()]
        return elapsed, sum(p.stat().st_size for p in files), sum(p.suffix == ".png" for p in files)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configurations", type=int, default=150)
    parser.add_argument("--trials", type=int, default=200)
    parser.add_argument("--histograms", default=None, help="N or 'all' (default: the report's own rule)")
    args = parser.parse_args()

    model = load_robot_model(REPO / "config" / "paper_arm.yaml")
    campaign = simulate_campaign(model, SimulationSettings(), seed=1).campaign
    many = draw_joint_positions(model, args.configurations, rng=np.random.default_rng(2), margin=np.radians(5.0))
    settings = UncertaintySettings(sources=("tracker", "encoder"))
    results = {
        n: evaluate_uncertainty(model, campaign, many[:n], uncertainty=settings, trials=args.trials, seed=1)
        for n in (1, args.configurations)
    }
    histograms = _histograms(args.histograms)
    _write(results[1], histograms)  # warm-up: matplotlib's font cache and imports
    rows = {n: _write(res, histograms) for n, res in results.items()}
    print(f"write_report, {args.trials} trials, histograms={args.histograms or 'default'}")
    print(f"{'configurations':>15} {'time / s':>9} {'size / MB':>10} {'PNGs':>5}")
    for n, (sec, size, pngs) in rows.items():
        print(f"{n:>15} {sec:>9.2f} {size / 1e6:>10.2f} {pngs:>5}")
    (t1, s1, _), (tn, sn, _) = rows[1], rows[args.configurations]
    print(f"ratio {args.configurations} : 1 configuration: time {tn / t1:.2f}x, size {sn / s1:.2f}x")


if __name__ == "__main__":
    main()
