"""Trials per second of the calibration Monte Carlo against a plain per-trial baseline.

Everything runs in this process on the same simulated 53-pose campaign of the seed's arm with
the same sources (tracker and encoder noise):
- baseline: for each trial, perturb the campaign and re-identify with
  ``scipy.optimize.least_squares`` (vectorised FK over the poses, default finite-difference
  Jacobian), then evaluate the tool at the test joints;
- engine, start-up included: :func:`evaluate_uncertainty` from the calibration to the
  uncertainty statement (preparation, all trials of a chunk re-identified at once, summaries);
- engine, start-up excluded: the trial blocks alone (``run_trials`` on the prepared trials);
- random draws alone: the sources drawing their values for the same trials (the part a
  faster solver cannot remove without changing the random streams);
- 6-DOF: the same campaign measured as poses (orientation noise 0.01 deg), sources tracker,
  encoder and tracker_orientation, trial blocks alone, against the point trials;
- the chain walk alone: one kinematics pass of the re-identification (the nearby-point walk
  over the 53 poses, point or pose) for a sub-batch of 256 trials, per trial; a trial takes one.
The ratios are printed; nothing here is a pass/fail test. With one worker every timing is in
CPU seconds of this process (on a shared machine the wall clock mostly measures the wait for a
core); with more workers, in wall-clock seconds.

Usage: python benchmarks/bench_monte_carlo.py [--trials 20000] [--baseline-trials 30] [--million]
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
from robocal_uncertainty.montecarlo.engine import run_trials
from robocal_uncertainty.montecarlo.executor import RunContext
from robocal_uncertainty.montecarlo.streams import source_generator
from robocal_uncertainty.uncertainty import (
    EvaluationSettings,
    UncertaintySettings,
    evaluate_uncertainty,
    prepare_calibration_trials,
)
from robocal_uncertainty.uncertainty.sources import stream_id

TEST_JOINTS = np.radians([-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451])
clock = time.process_time


def _peak_rss_mib() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return usage / 1024.0 if sys.platform != "darwin" else usage / 2**20


def baseline_rate(model, campaign, calibration, settings, n_trials: int, seed: int) -> float:
    layout = model.layout
    est = np.flatnonzero(calibration.estimated)
    rng = np.random.default_rng(seed)
    start = clock()
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
    return n_trials / (clock() - start)


def engine_rate(model, campaign, calibration, settings, n_trials: int, seed: int, workers: int) -> tuple[float, object]:
    """Trials per second of the whole evaluation (start-up included) and its result."""
    start = clock()
    result = evaluate_uncertainty(
        model,
        campaign,
        TEST_JOINTS,
        EvaluationSettings(uncertainty=settings, trials=n_trials, seed=seed),
        calibration=calibration,
        run=RunContext(workers=workers),
    )
    return n_trials / (clock() - start), result


def steady_rate(trials, n_trials: int, seed: int, workers: int) -> float:
    """Trials per second of the trial blocks alone (start-up excluded)."""
    start = clock()
    run_trials(trials, seed=seed, n_trials=n_trials, workers=workers)
    return n_trials / (clock() - start)


def draw_rate(trials, n_trials: int, seed: int, block: int = 10_000) -> float:
    """Trials per second of the sources' random draws alone (blocks of `block` trials)."""
    root = np.random.SeedSequence(seed)
    start = clock()
    for b in range(0, n_trials, block):
        rng = np.random.default_rng(root.spawn(1)[0])
        for source in trials.sources:
            source.draw(source_generator(rng, stream_id(source.name)), min(block, n_trials - b))
    return n_trials / (clock() - start)


def walk_time(trials, seed: int, n: int = 256, repeats: int = 20) -> float:
    """CPU seconds per trial of one kinematics pass of the re-identification (best of `repeats`)."""
    rng = np.random.default_rng(seed)
    solver = trials.solver
    q = trials.joint_positions + rng.uniform(-1e-4, 1e-4, (n, *trials.joint_positions.shape))
    params = trials.problem.parameters(np.repeat(trials.x_hat[None], n, axis=0))
    solver.predictor(params, q)
    best = np.inf
    for _ in range(repeats):
        start = clock()
        solver.predictor(params, q)
        best = min(best, clock() - start)
    return best / n


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20_000)
    parser.add_argument("--baseline-trials", type=int, default=30)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--million", action="store_true", help="also time 10^6 trials")
    args = parser.parse_args()
    global clock  # noqa: PLW0603 - one clock for every timing of the run
    clock = time.process_time if args.workers == 1 else time.perf_counter

    model = load_robot_model("config/paper_arm.yaml")
    campaign = simulate_campaign(model, SimulationSettings(), seed=1).campaign
    calibration = identify(model, campaign)
    settings = UncertaintySettings(sources=("tracker", "encoder"))
    engine_rate(model, campaign, calibration, settings, 500, 0, 1)  # warm-up
    points = prepare_calibration_trials(model, campaign, TEST_JOINTS, settings=settings, calibration=calibration)
    pose_campaign = simulate_campaign(model, SimulationSettings(orientation_std=float(np.radians(0.01))), seed=1)
    pose_settings = UncertaintySettings(sources=("tracker", "encoder", "tracker_orientation"))
    poses = prepare_calibration_trials(model, pose_campaign.campaign, TEST_JOINTS, settings=pose_settings)
    run_trials(poses, seed=0, n_trials=500)  # warm-up

    base = baseline_rate(model, campaign, calibration, settings, args.baseline_trials, 0)
    rate, result = engine_rate(model, campaign, calibration, settings, args.trials, 0, args.workers)
    steady = steady_rate(points, args.trials, 0, args.workers)
    steady_6 = steady_rate(poses, args.trials, 0, args.workers)
    draws = draw_rate(points, args.trials, 0)
    walk, walk_6 = walk_time(points, 0), walk_time(poses, 0)
    u = np.sqrt(np.diag(result.poses[0].covariance)) * 1e6
    print(f"campaign: 53 poses, {int(calibration.estimated.sum())} parameters, sources tracker+encoder")
    print(f"baseline (scipy least_squares per trial): {base:10.1f} trials/s  ({args.baseline_trials} trials)")
    print(
        f"engine, start-up included:                {rate:10.1f} trials/s  ({args.trials} trials, "
        f"{args.trials / rate:.2f} s, {1e6 / rate:.1f} us/trial, workers={args.workers})"
    )
    print(f"engine, start-up excluded:                {steady:10.1f} trials/s  ({1e6 / steady:.1f} us/trial)")
    print(f"speed-up engine / baseline: {rate / base:.0f}x start-up included, {steady / base:.0f}x excluded")
    print(
        f"random draws alone: {1e6 / draws:.1f} us/trial, {steady / draws:.0%} of a steady trial "
        f"(with a free re-identification the ratio could not exceed {draws / base:.0f}x)"
    )
    print(f"6-DOF trials (tracker+encoder+orientation), start-up excluded: {steady_6:10.1f} trials/s")
    print(f"6-DOF / point cost per trial: {steady / steady_6:.2f}x")
    print(f"chain walk alone (one per trial, best of 20): {walk * 1e6:.1f} us point, {walk_6 * 1e6:.1f} us pose")
    print(f"u(x, y, z) at the seed's test joints: {u[0]:.2f}, {u[1]:.2f}, {u[2]:.2f} um")
    if args.million:
        rate_m, _ = engine_rate(model, campaign, calibration, settings, 1_000_000, 0, args.workers)
        print(f"10^6 trials: {1e6 / rate_m:.0f} s ({rate_m:.0f} trials/s)")
    print(f"peak resident memory: {_peak_rss_mib():.0f} MiB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
