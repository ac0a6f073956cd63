"""Sweeps: shapes, and fewer equations give a larger uncertainty."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from robocal_uncertainty.core import SimulationSettings, load_robot_model, simulate_campaign
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty import (
    EvaluationSettings,
    Sweep,
    UncertaintySettings,
    evaluate_sweeps,
    evaluate_uncertainty,
    sweep_equations,
    sweep_lambda,
)

REPO = Path(__file__).resolve().parents[2]
PAPER_TEST_JOINTS_DEG = (-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451)


@pytest.fixture(scope="module")
def setup() -> SimpleNamespace:
    model = load_robot_model(REPO / "config" / "paper_arm.yaml")
    sim = simulate_campaign(model, SimulationSettings(), seed=1)
    qt = np.radians(PAPER_TEST_JOINTS_DEG)
    settings = UncertaintySettings(sources=("tracker", "encoder"))
    result = evaluate_uncertainty(model, sim.campaign, qt, uncertainty=settings, trials=200, seed=1)
    return SimpleNamespace(model=model, campaign=sim.campaign, test_joints=qt, result=result)


def test_sweep_equations_fewer_poses_larger_u(setup):
    u = sweep_equations(
        setup.model,
        setup.campaign,
        setup.result.calibration,
        setup.test_joints,
        [20, 53],
        trials=300,
        seed=3,
    )
    assert u.shape == (2, 3)
    assert np.isfinite(u).all() and (u > 0).all()
    assert (u[0] > u[1]).all()
    assert np.linalg.norm(u[0]) > 1.2 * np.linalg.norm(u[1])


def test_sweep_lambda_shape(setup):
    cal = setup.result.calibration
    lams = [cal.lambda_, 3.0 * cal.lambda_]
    u = sweep_lambda(setup.model, setup.campaign, cal, setup.test_joints, lams, trials=200, seed=3)
    assert u.shape == (2, 3)
    assert np.isfinite(u).all() and (u > 0).all()
    # At the calibration's own lambda the sweep reuses it: same numbers as a direct call.
    direct = evaluate_uncertainty(setup.model, setup.campaign, setup.test_joints, calibration=cal, trials=200, seed=3)
    np.testing.assert_array_equal(u[0], [a.standard_uncertainty for a in direct.poses[0].axes])
    # Tikhonov shrinkage: the variance of the estimate falls as lambda grows (same trials).
    assert np.linalg.norm(u[1]) < np.linalg.norm(u[0])


def test_sweep_bad_inputs(setup):
    args = (setup.model, setup.campaign, setup.result.calibration, setup.test_joints)
    with pytest.raises(ConfigError, match="pose_counts must be integers"):
        sweep_equations(*args, [10.5], trials=50)
    with pytest.raises(ConfigError, match="subset_size = 2 must lie between"):
        sweep_equations(*args, [2], trials=50)  # fewer poses than identifiable / 3
    with pytest.raises(ConfigError, match="lambdas must be >= 0"):
        sweep_lambda(*args, [-1.0], trials=50)
    with pytest.raises(ConfigError, match="pose index 1 out of range"):
        sweep_lambda(*args, [1.0], trials=50, pose=1)
    with pytest.raises(ConfigError, match=r"must have shape \(3, 3\)"):
        Sweep("x", "x", np.arange(3.0), np.zeros((2, 3)))


def test_evaluate_sweeps_are_the_two_sweep_functions(setup):
    """The report's standard sweeps are sweep_lambda and sweep_equations on their grids."""
    cal = setup.result.calibration
    options = EvaluationSettings(test_joints=setup.test_joints, seed=5, sweep_trials=60)
    by_lambda, by_equations = evaluate_sweeps(setup.model, setup.campaign, cal, options)
    assert (by_lambda.name, by_equations.name) == ("lambda", "equations")
    assert by_lambda.values.shape == (9,) and by_lambda.reference == cal.lambda_
    assert by_equations.values[-1] == 3 * setup.campaign.n_poses
    again = sweep_equations(
        setup.model, setup.campaign, cal, setup.test_joints, by_equations.values[:2] / 3, trials=60, seed=5
    )
    np.testing.assert_array_equal(again, by_equations.standard_uncertainty[:2])
    with pytest.raises(ConfigError, match="test joint"):
        evaluate_sweeps(setup.model, setup.campaign, cal, EvaluationSettings())
