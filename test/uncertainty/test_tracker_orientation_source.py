"""The tracker_orientation source: orientation noise of 6-DOF campaigns as its own input, and
the tracker source restricted to the position components."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model
from robocal_uncertainty.core.simulation import SimulationSettings, simulate_campaign
from robocal_uncertainty.uncertainty.calibration import evaluate_uncertainty
from robocal_uncertainty.uncertainty.sources import (
    SOURCE_REGISTRY,
    TrialBatch,
    TrialContext,
    UncertaintySettings,
)

UR10 = Path(__file__).resolve().parents[2] / "config" / "ur10.yaml"


def _context(dim: int, rotation_std: np.ndarray | None) -> TrialContext:
    return TrialContext(
        n_poses=4,
        n_joints=6,
        n_test=1,
        measurement_dimension=dim,
        distances=np.full(4, 2.0),
        model_errors=np.zeros((4, dim)),
        lambda_star=0.0,
        lambda_range=None,
        min_poses=3,
        subset_size=3,
        rotation_std=rotation_std,
    )


def _apply(name: str, ctx: TrialContext, n: int = 20_000) -> np.ndarray:
    source = SOURCE_REGISTRY[name].build(UncertaintySettings(), ctx)
    batch = TrialBatch(n)
    source.apply(source.draw(np.random.default_rng(1), n), batch)
    assert batch.points is not None
    return batch.points


def test_tracker_perturbs_only_positions_of_poses() -> None:
    points = _apply("tracker", _context(6, np.array([1e-4, 2e-4, 3e-4])))
    assert np.all(points[..., 3:] == 0.0)
    assert np.all(points[..., :3] != 0.0)


def test_tracker_orientation_draws_the_rotation_std() -> None:
    std = np.array([1e-4, 2e-4, 3e-4])
    points = _apply("tracker_orientation", _context(6, std))
    assert np.all(points[..., :3] == 0.0)
    np.testing.assert_allclose(points[..., 3:].reshape(-1, 3).std(axis=0), std, rtol=0.02)
    assert SOURCE_REGISTRY["tracker_orientation"].smooth


def test_tracker_orientation_is_zero_for_points() -> None:
    assert np.all(_apply("tracker_orientation", _context(3, None), n=10) == 0.0)


@pytest.mark.parametrize(
    ("sources", "rot_range", "pos_max"),
    [(("tracker_orientation",), (1.5e-5, 3.5e-5), 6e-6), (("tracker",), (5e-7, 2e-6), 1.5e-6)],
)
def test_monte_carlo_of_a_6dof_campaign_separates_the_two_inputs(
    sources: tuple[str, ...], rot_range: tuple[float, float], pos_max: float
) -> None:
    """Measured: orientation noise 0.1 mrad per pose alone gives 21-25 urad on the tool
    rotation and 2.4-4.2 um on the position; tracker position noise alone 1.1-1.2 urad,
    1.0-1.1 um. (With variance-component weights the simulated encoder noise sets the position
    weights, 9-38 um, so the rotations also steer the position parameters: weighted by the
    stated 2.9 um the orientation noise moved the position by under 0.2 um.)"""
    model = load_robot_model(UR10)
    sim = simulate_campaign(model, SimulationSettings(frame="tracker", orientation_std=1e-4), seed=3)
    q = np.array([[0.3, -1.2, 1.1, 0.2, 0.5, 0.1]])
    result = evaluate_uncertainty(
        model, sim.campaign, q, uncertainty=UncertaintySettings(sources=sources), trials=1000, block_size=1000
    )
    assert "tool.rx" in result.parameter_names
    pose = result.poses[0]
    assert pose.orientation is not None
    rot_std = np.sqrt(np.diag(pose.orientation.covariance))
    assert np.all((rot_std > rot_range[0]) & (rot_std < rot_range[1])), rot_std
    assert np.sqrt(np.diag(pose.covariance)).max() < pos_max


@pytest.mark.parametrize("sources", [("tracker", "tracker_orientation"), ("tracker", "encoder", "tracker_orientation")])
def test_gum_of_a_six_dof_campaign_agrees_with_the_monte_carlo(sources: tuple[str, ...]) -> None:
    """Whitened (6-DOF) equations: the first-order propagation matches the trials' spread.

    The GUM once whitened the Jacobian twice and came out ~1e5 times too small.
    """
    model = load_robot_model(Path(__file__).resolve().parents[2] / "config" / "paper_arm.yaml")
    sim = simulate_campaign(model, SimulationSettings(orientation_std=2e-4, n_poses=30), seed=4)
    q = np.radians([[-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451], [10, -200, -90, -80, -50, 30]])
    result = evaluate_uncertainty(
        model, sim.campaign, q, uncertainty=UncertaintySettings(sources=sources), trials=1500, seed=2
    )
    for pose in result.poses:
        np.testing.assert_allclose(np.sqrt(np.diag(pose.covariance)), pose.gum.standard_uncertainty, rtol=0.12)
        rot = pose.orientation
        assert rot is not None and rot.fully_determined
        u_rot = [a.standard_uncertainty for a in rot.axes]
        np.testing.assert_allclose(u_rot, rot.gum.standard_uncertainty, rtol=0.12)
