"""Tikhonov shrinkage is a bias the Monte Carlo cannot see (every trial is centred on the
calibration): the evaluation must estimate it and warn when it is not small against u.

Independent reference: the same campaign without noise, identified with the same lambda;
its position error at the test joints is the regularisation bias alone.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import SimulationSettings, forward_points, identify, load_robot_model, simulate_campaign
from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.uncertainty import UncertaintySettings
from robocal_uncertainty.uncertainty.calibration import evaluate_uncertainty
from robocal_uncertainty.uncertainty.calibration.gum import regularisation_bias
from robocal_uncertainty.uncertainty.calibration.preparation import prepare

ROOT = Path(__file__).resolve().parents[2]
TEST_JOINTS = np.radians([[10.0, 20.0, -30.0, 40.0, 30.0, 50.0], [-60.0, -40.0, 70.0, 10.0, -20.0, 5.0]])


@pytest.fixture(scope="module")
def campaigns():
    model = load_robot_model(ROOT / "config/paper_arm.yaml")
    noisy = simulate_campaign(model, SimulationSettings(n_poses=20), seed=3)
    quiet = SimulationSettings(
        n_poses=20, tracker_noise=TrackerNoise(a=0.0), encoder_noise=EncoderNoise(half_width=0.0)
    )
    clean = simulate_campaign(model, quiet, seed=3)
    return model, noisy, clean


def test_a_large_lambda_is_flagged_with_the_bias_it_causes(campaigns) -> None:
    model, noisy, clean = campaigns
    lam = 0.1  # about 30 times the L-curve corner of this campaign
    result = evaluate_uncertainty(model, noisy.campaign, TEST_JOINTS, trials=300, seed=0, lambda_=lam)
    prep = prepare(model, noisy.campaign, TEST_JOINTS, UncertaintySettings(), result.calibration, lam, "measurement")
    estimated = regularisation_bias(prep)
    truth = forward_points(model.layout, clean.true_model.parameter_vector(), TEST_JOINTS)
    noise_free = (
        forward_points(model.layout, identify(model, clean.campaign, lambda_=lam).estimate, TEST_JOINTS) - truth
    )
    # The estimate uses the shrunk x_hat for the unknown x: same direction, somewhat smaller.
    big = np.abs(noise_free) > 50e-6
    assert big.sum() >= 3
    ratio = estimated[big] / noise_free[big]
    assert np.all((ratio > 0.6) & (ratio < 1.1)), ratio
    flagged = [w for w in result.warnings if "regularisation" in w]
    assert len(flagged) == 2 and "smaller --lambda" in flagged[0]


def test_the_l_curve_corner_is_not_flagged(campaigns) -> None:
    model, noisy, _ = campaigns
    result = evaluate_uncertainty(model, noisy.campaign, TEST_JOINTS, trials=300, seed=0)
    assert not [w for w in result.warnings if "regularisation" in w]
