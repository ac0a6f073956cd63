"""Coverage that is honest: over many simulated campaigns where the model is right (tracker
and encoder noise only), the 95 % intervals contain the true tool position ~95 % of the time.

Slow (a few minutes on 2 cores): ``python -m pytest -m slow test/uncertainty/test_coverage_slow.py -s``.
Also runnable as a script: ``python test/uncertainty/test_coverage_slow.py [n_campaigns]``.
"""

from __future__ import annotations

import os
import sys

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import (
    SimulationSettings,
    forward_points,
    load_robot_model,
    simulate_campaign,
)
from robocal_uncertainty.uncertainty import UncertaintySettings, evaluate_uncertainty

ROOT = Path(__file__).resolve().parents[2]

TEST_JOINTS = np.radians([-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451])


def coverage_experiment(n_campaigns: int, *, trials: int = 2000, seed: int = 2024) -> dict[str, float]:
    """Fraction of campaigns whose intervals contain the truth, per axis and for the 3-D region."""
    model = load_robot_model(ROOT / "config/paper_arm.yaml")
    settings = SimulationSettings()
    rng = np.random.default_rng(seed)
    hits = np.zeros(3)
    region_hits = 0
    for i in range(n_campaigns):
        sim = simulate_campaign(model, settings, rng=np.random.default_rng(rng.integers(2**63)))
        # The arm asked to go to the test joints sits within the encoder error of them.
        q_true = TEST_JOINTS + settings.encoder_noise.sample(rng, TEST_JOINTS.shape)
        truth = forward_points(model.layout, sim.true_model.parameter_vector(), q_true[None])[0]
        result = evaluate_uncertainty(
            model, sim.campaign, TEST_JOINTS, uncertainty=UncertaintySettings(), trials=trials, seed=i
        )
        pose = result.poses[0]
        hits += [pose.axes[j].probabilistically_symmetric.contains(float(truth[j])) for j in range(3)]
        region_hits += bool(pose.region is not None and pose.region.contains(truth))
    return {
        "x": hits[0] / n_campaigns,
        "y": hits[1] / n_campaigns,
        "z": hits[2] / n_campaigns,
        "region": region_hits / n_campaigns,
        "n_campaigns": float(n_campaigns),
    }


@pytest.mark.slow
def test_95_percent_intervals_cover_the_truth_in_95_percent_of_campaigns() -> None:
    cover = coverage_experiment(200)
    print(cover)
    # Binomial standard error at 200 campaigns is 1.5 %; the issue asks for 95 % +- 3 %.
    for key in ("x", "y", "z", "region"):
        assert 0.92 <= cover[key] <= 0.98, (key, cover)


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 200
    print(coverage_experiment(n))
