"""Sweeps: shapes, and fewer equations give a larger uncertainty."""

from __future__ import annotations

import numpy as np
import pytest

from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.report import Sweep, sweep_equations, sweep_lambda
from robocal_uncertainty.uncertainty import evaluate_uncertainty


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


def test_sweep_bad_inputs(setup):
    args = (setup.model, setup.campaign, setup.result.calibration, setup.test_joints)
    with pytest.raises(ConfigError):
        sweep_equations(*args, [10.5], trials=50)
    with pytest.raises(ConfigError):
        sweep_equations(*args, [2], trials=50)  # fewer poses than identifiable / 3
    with pytest.raises(ConfigError):
        sweep_lambda(*args, [-1.0], trials=50)
    with pytest.raises(ConfigError):
        sweep_lambda(*args, [1.0], trials=50, pose=1)
    with pytest.raises(ConfigError):
        Sweep("x", "x", np.arange(3.0), np.zeros((2, 3)))
