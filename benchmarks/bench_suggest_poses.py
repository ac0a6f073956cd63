"""Next-best poses against random poses on simulated campaigns (issue 12).

For each of `--campaigns` simulated campaigns of the paper arm (20 initial poses, tracker and
encoder noise), 10 poses suggested by :func:`robocal_uncertainty.app.suggest_poses` (greedy,
from 500 candidates inside the joint limits) and 10 random poses inside the limits are added as
simulated measurements at the calibrated model's predicted points; the Monte Carlo RMS over
the two test configurations of u_pos = sqrt(trace of the position covariance) is compared.
Prints per campaign and the mean ratio suggested / random (below 1: suggestions help more).

Usage: ``python benchmarks/bench_suggest_poses.py [--campaigns 10] [--added 10] [--trials 2000]``
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import time
from pathlib import Path

import numpy as np

from robocal_uncertainty.app import suggest_poses
from robocal_uncertainty.app.pose_suggestion import with_simulated_pose
from robocal_uncertainty.core import SimulationSettings, load_robot_model, simulate_campaign
from robocal_uncertainty.core.identification import identify
from robocal_uncertainty.core.simulation import draw_joint_positions
from robocal_uncertainty.uncertainty import UncertaintySettings, evaluate_uncertainty

ARM = Path(__file__).resolve().parents[1] / "robocal_uncertainty" / "data" / "paper_arm.yaml"
TEST_JOINTS = np.radians(
    [[-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451], [30.0, -180.0, 45.0, 10.0, -20.0, 5.0]]
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--campaigns", type=int, default=10)
    parser.add_argument("--initial", type=int, default=20)
    parser.add_argument("--added", type=int, default=10)
    parser.add_argument("--trials", type=int, default=2000)
    args = parser.parse_args()
    model = load_robot_model(ARM)
    settings = UncertaintySettings()

    def u(campaign: object, seed: int) -> float:
        result = evaluate_uncertainty(model, campaign, TEST_JOINTS, uncertainty=settings, trials=args.trials, seed=seed)
        return float(np.sqrt(np.mean([np.trace(p.covariance) for p in result.poses])))

    ratios = []
    for k in range(args.campaigns):
        campaign = simulate_campaign(model, SimulationSettings(n_poses=args.initial), seed=1000 + k).campaign
        calibration = identify(model, campaign)
        started = time.perf_counter()
        suggested = suggest_poses(
            model, campaign, TEST_JOINTS, calibration=calibration, n_candidates=500, count=args.added, seed=k
        )
        ranking_s = time.perf_counter() - started
        chosen = np.array([s.joint_positions for s in suggested.suggestions])
        random = draw_joint_positions(model, args.added, rng=np.random.default_rng(10_000 + k), margin=0.05)
        now = u(campaign, k)
        with_suggested = u(with_simulated_pose(campaign, model, calibration.estimate, chosen), k)
        with_random = u(with_simulated_pose(campaign, model, calibration.estimate, random), k)
        ratios.append(with_suggested / with_random)
        print(
            f"campaign {k}: u_pos {now * 1e6:.2f} um; +{args.added} suggested {with_suggested * 1e6:.2f} um, "
            f"+{args.added} random {with_random * 1e6:.2f} um, ratio {ratios[-1]:.3f} (ranking {ranking_s:.2f} s)"
        )
    print(
        f"mean ratio suggested/random over {args.campaigns} campaigns: {np.mean(ratios):.3f} "
        f"(min {np.min(ratios):.3f}, max {np.max(ratios):.3f})"
    )


if __name__ == "__main__":
    main()
