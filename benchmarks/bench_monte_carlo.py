"""Trials per second of the calibration Monte Carlo against a plain per-trial baseline.

Both run in this process on the same simulated 53-pose campaign of the seed's arm with the
same sources (tracker and encoder noise):
- baseline: for each trial, perturb the campaign and re-identify with
  ``scipy.optimize.least_squares`` (vectorised FK over the poses, default finite-difference
  Jacobian), then evaluate the tool at the test joints;
- engine: :func:`evaluate_uncertainty` (all trials of a chunk re-identified at once).
The ratio of the two rates is printed; nothing here is a pass/fail test.

Usage: python benchmarks/bench_monte_carlo.py [--trials 10000] [--baseline-trials 30] [--million]
"""

from __future__ import annotations

import os

# One BLAS thread for both engine and baseline, as the command line does (see robocal_uncertainty/cli/__init__.py).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import resource
import sys
import time

import numpy as np
from scipy.optimize import least_squares

from robocal_uncertainty.core import (
    SimulationSettings,
    forward_points,
    identify,
    load_robot_model,
    simulate_campaign,
)
from robocal_uncertainty.uncertainty import UncertaintySettings, evaluate_uncertainty

TEST_JOINTS = np.radians([-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451])


def _peak_rss_mib() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return usage / 1024.0 if sys.platform != "darwin" else usage / 2**20


def baseline_rate(model, campaign, calibration, settings, n_trials: int, seed: int) -> float:
    layout = model.layout
    est = np.flatnonzero(calibration.estimated)
    rng = np.random.default_rng(seed)
    start = time.perf_counter()
    for _ in range(n_trials):
        q = campaign.joint_positions + settings.encoder_noise.sample(rng, campaign.joint_positions.shape)
        pts = campaign.points + settings.tracker_noise.sample(rng, np.full(campaign.n_poses, 2.0))

        def residual(p_est, q=q, pts=pts):
            p = calibration.nominal.copy()
            p[est] = p_est
            return (forward_points(layout, p, q) - pts).ravel()

        fit = least_squares(residual, calibration.estimate[est], x_scale=1.0 / calibration.column_scale[est])
        p = calibration.nominal.copy()
        p[est] = fit.x
        forward_points(layout, p, TEST_JOINTS[None])
    return n_trials / (time.perf_counter() - start)


def engine_rate(model, campaign, calibration, settings, n_trials: int, seed: int, workers: int) -> tuple[float, object]:
    start = time.perf_counter()
    result = evaluate_uncertainty(
        model,
        campaign,
        TEST_JOINTS,
        settings=settings,
        calibration=calibration,
        trials=n_trials,
        seed=seed,
        workers=workers,
    )
    return n_trials / (time.perf_counter() - start), result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=10_000)
    parser.add_argument("--baseline-trials", type=int, default=30)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--million", action="store_true", help="also time 10^6 trials")
    args = parser.parse_args()

    model = load_robot_model("config/paper_arm.yaml")
    campaign = simulate_campaign(model, SimulationSettings(), seed=1).campaign
    calibration = identify(model, campaign)
    settings = UncertaintySettings(sources=("tracker", "encoder"))
    engine_rate(model, campaign, calibration, settings, 500, 0, 1)  # warm-up

    base = baseline_rate(model, campaign, calibration, settings, args.baseline_trials, 0)
    rate, result = engine_rate(model, campaign, calibration, settings, args.trials, 0, args.workers)
    u = np.sqrt(np.diag(result.poses[0].covariance)) * 1e6
    print(f"campaign: 53 poses, {int(calibration.estimated.sum())} parameters, sources tracker+encoder")
    print(f"baseline (scipy least_squares per trial): {base:10.1f} trials/s  ({args.baseline_trials} trials)")
    print(
        f"engine (batched re-identification):       {rate:10.1f} trials/s  ({args.trials} trials, "
        f"{args.trials / rate:.1f} s, workers={args.workers})"
    )
    print(f"speed-up engine / baseline: {rate / base:.0f}x")
    print(f"u(x, y, z) at the seed's test joints: {u[0]:.2f}, {u[1]:.2f}, {u[2]:.2f} um")
    if args.million:
        rate_m, _ = engine_rate(model, campaign, calibration, settings, 1_000_000, 0, args.workers)
        print(f"10^6 trials: {1e6 / rate_m:.0f} s ({rate_m:.0f} trials/s)")
    print(f"peak resident memory: {_peak_rss_mib():.0f} MiB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
