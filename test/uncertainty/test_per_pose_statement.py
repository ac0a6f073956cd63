"""The per-pose statement of many configurations (what the held-out check reads) and its fast parts.

``evaluate_uncertainty(per_pose=True)`` skips the coverage regions and propagates the GUM
within each configuration only; the held-out check draws its own JCGM 102 regions for every
pose at once. Each is checked against the full computation it replaces.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import SimulationSettings, load_robot_model, simulate_campaign
from robocal_uncertainty.montecarlo.distributions import (
    CorrelatedNormal,
    IndependentCopies,
    IndependentNormal,
    IndependentRectangular,
)
from robocal_uncertainty.montecarlo.gum import propagate_gum
from robocal_uncertainty.montecarlo.region import coverage_region
from robocal_uncertainty.uncertainty import UncertaintySettings, evaluate_uncertainty
from robocal_uncertainty.uncertainty.holdout import RELIABILITY_LEVELS, _inside_regions

ROOT = Path(__file__).resolve().parents[2]


def test_block_propagation_is_the_full_covariance_within_each_block() -> None:
    rng = np.random.default_rng(0)
    inputs = {
        "rect": IndependentRectangular(rng.uniform(0.0, 1.0, 12)),
        "copies": IndependentCopies(CorrelatedNormal(np.zeros(2), np.array([[2.0, 0.5], [0.5, 1.0]])), 5),
        "dense": CorrelatedNormal(np.zeros(3), np.eye(3) * 0.3 + 0.1),
        "normal": IndependentNormal(np.ones(4)),
    }
    jac = rng.normal(size=(12, 12 + 10 + 3 + 4))

    def model(x: np.ndarray) -> np.ndarray:
        return np.broadcast_to(np.zeros(12), (x.shape[0], 12))

    full = propagate_gum(model, inputs, sensitivities=jac).covariance
    blocks = propagate_gum(model, inputs, sensitivities=jac, output_blocks=3).covariance
    inside = np.kron(np.eye(4), np.ones((3, 3))).astype(bool)
    np.testing.assert_allclose(blocks[inside], full[inside], rtol=1e-13, atol=1e-15 * np.abs(full).max())
    assert not blocks[~inside].any() and full[~inside].any()


def test_per_pose_statement_keeps_the_samples_and_the_per_pose_numbers() -> None:
    model = load_robot_model(ROOT / "config/paper_arm.yaml")
    sim = simulate_campaign(model, SimulationSettings(n_poses=28), seed=3)
    test_q = sim.campaign.joint_positions[:5] + 0.05
    args = (model, sim.campaign, test_q)
    kw = {"uncertainty": UncertaintySettings(sources=("tracker", "encoder", "residual")), "trials": 300, "seed": 2}
    full = evaluate_uncertainty(*args, **kw)  # type: ignore[arg-type]
    lean = evaluate_uncertainty(*args, per_pose=True, **kw)  # type: ignore[arg-type]
    np.testing.assert_array_equal(lean.samples, full.samples)
    assert lean.not_converged == full.not_converged
    for a, b in zip(full.poses, lean.poses):
        assert a.region is not None and b.region is None
        np.testing.assert_array_equal(a.covariance, b.covariance)
        assert a.gum is not None and b.gum is not None
        np.testing.assert_allclose(b.gum.covariance, a.gum.covariance, rtol=1e-12, atol=1e-12 * a.gum.covariance.max())
        np.testing.assert_allclose(b.gum.d_low, a.gum.d_low, rtol=1e-9, atol=1e-15)
        assert b.gum.validated == a.gum.validated


def test_held_out_regions_are_the_jcgm_102_regions_of_each_pose() -> None:
    rng = np.random.default_rng(4)
    shape = rng.normal(size=(6, 3, 3)) * 1e-4
    pred = np.einsum("pij,mpj->mpi", shape, rng.standard_t(5, size=(2000, 6, 3))) + rng.normal(size=(6, 3))
    # Points spread over the regions' edges: some in, some out at every level.
    points = pred.mean(axis=0)[:, None] + np.einsum("pij,pkj->pki", shape, rng.normal(size=(6, 40, 3)) * 1.7)
    levels = np.asarray(RELIABILITY_LEVELS)
    inside = np.stack([_inside_regions(pred, points[:, k], levels) for k in range(points.shape[1])], axis=-1)
    expected = np.array(
        [[coverage_region(pred[:, i], float(level)).contains(points[i]) for i in range(6)] for level in levels]
    )
    np.testing.assert_array_equal(inside, expected)
    assert 0.2 < inside.mean() < 0.8


@pytest.mark.parametrize("levels", [(0.5,), (0.95, 0.99)])
def test_held_out_regions_at_repeated_ranks(levels: tuple[float, ...]) -> None:
    # 60 trials: several levels fall on the same order statistic.
    rng = np.random.default_rng(1)
    pred = rng.normal(size=(60, 3, 3))
    points = rng.normal(size=(3, 3))
    lv = np.asarray((*levels, 0.505, 0.51))
    inside = _inside_regions(pred, points, lv)
    for i in range(3):
        for j, level in enumerate(lv):
            assert inside[j, i] == coverage_region(pred[:, i], float(level)).contains(points[i])
