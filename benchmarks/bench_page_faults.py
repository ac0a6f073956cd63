"""CPU, system time and page faults of the calibration trials of the UR10 series D.

``run_trials`` of the shipped series D (632 poses, default sources tracker, encoder, residual;
the README's test joints) with the chosen backend, after a 2 000-trial warm-up: CPU seconds of
this process (user and system) and the minor page faults (first touches of fresh memory) the
trials made. Run it with and without glibc's malloc variables (``MALLOC_TRIM_THRESHOLD_``,
``MALLOC_TOP_PAD_``, ``MALLOC_MMAP_THRESHOLD_``) to see what returning freed memory to the
system between sub-batches costs. Nothing here is a pass/fail test; on a shared machine, run
the two one right after the other and compare.

Usage: python benchmarks/bench_page_faults.py [--trials 100000] [--backend numba]
"""

from __future__ import annotations

import os
import sys

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse
import resource
import time
from pathlib import Path

import numpy as np

from robocal_uncertainty.core import identify, load_robot_model
from robocal_uncertainty.importers.tracker_csv import read_tracker_csv
from robocal_uncertainty.montecarlo.engine import run_trials
from robocal_uncertainty.uncertainty import UncertaintySettings, prepare_calibration_trials

ROOT = Path(__file__).resolve().parents[1]
UR10_TEST_JOINTS = np.array([[0.934319, -1.79251, 1.5196, 0.272862, 0.934269, -1.57075]])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=100_000)
    parser.add_argument("--backend", default="numba")
    args = parser.parse_args()
    model = load_robot_model(ROOT / "config/ur10.yaml")
    campaign = read_tracker_csv(ROOT / "test/data/ur10_laser_tracker/measurements_iso_cubes.csv")
    campaign = campaign.reorder_joints(model.joint_names)
    calibration = identify(model, campaign)
    trials = prepare_calibration_trials(
        model,
        campaign,
        UR10_TEST_JOINTS,
        settings=UncertaintySettings(sources=("tracker", "encoder", "residual")),
        calibration=calibration,
        backend=args.backend,
    )
    run_trials(trials, seed=0, n_trials=2000)
    before = resource.getrusage(resource.RUSAGE_SELF)
    cpu = time.process_time()
    result = run_trials(trials, seed=0, n_trials=args.trials)
    cpu = time.process_time() - cpu
    after = resource.getrusage(resource.RUSAGE_SELF)
    malloc = {k: v for k, v in os.environ.items() if k.startswith("MALLOC_")} or "none"
    user = after.ru_utime - before.ru_utime
    system = after.ru_stime - before.ru_stime
    faults = after.ru_minflt - before.ru_minflt
    std = result.samples[:, 0].std() * 1e6
    print(f"UR10 series D, {campaign.n_poses} poses, {args.trials} trials, {args.backend}; malloc settings: {malloc}")
    print(f"  {cpu:.2f} s CPU ({user:.2f} s user, {system:.2f} s system), {faults} minor page faults")
    print(f"  first output's standard deviation {std:.3f} um (the same values either way)")
    print(f"load average: {', '.join(f'{v:.1f}' for v in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
