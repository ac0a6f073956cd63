"""Simulated campaigns without model error: the field comes out near zero and changes nothing.

Over many seeds of a 53-pose paper-arm campaign with only tracker and encoder noise, the
default statement (model error drawn as a field) and the independent one agree: where the
adequacy test accepts the model (about 99 %) no model error is drawn at all and the two runs are
identical bit for bit; where it rejects by chance, the field's model error stays below the
stated noise and the standard uncertainty moves by a few per cent at most.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import SimulationSettings, identify, load_robot_model, simulate_campaign
from robocal_uncertainty.core.simulation import EncoderNoise, TrackerNoise
from robocal_uncertainty.uncertainty import UncertaintySettings, evaluate_uncertainty
from robocal_uncertainty.uncertainty.model_adequacy import assess_model_adequacy, pose_noise_covariances
from robocal_uncertainty.uncertainty.model_error_draws import estimate_field

ROOT = Path(__file__).resolve().parents[2]
TEST_JOINTS = np.radians([-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451])
SEEDS = range(60)


@pytest.mark.slow
def test_no_model_error_no_change_over_many_seeds() -> None:
    model = load_robot_model(ROOT / "config/paper_arm.yaml")
    rejected = 0
    for seed in SEEDS:
        sim = simulate_campaign(model, SimulationSettings(), seed=seed)
        calibration = identify(model, sim.campaign)
        runs = {
            mode: evaluate_uncertainty(
                model,
                sim.campaign,
                TEST_JOINTS,
                uncertainty=UncertaintySettings(model_error=mode),
                calibration=calibration,
                trials=400,
                seed=seed,
                orientation=False,
            )
            for mode in ("field", "independent")
        }
        field, independent = runs["field"], runs["independent"]
        if field.model_adequacy.adequate:
            assert field.model_error_field is None
            np.testing.assert_array_equal(field.samples, independent.samples)
            continue
        rejected += 1
        noise = np.sqrt(np.diag(field.model_adequacy.noise_covariance))
        assert field.model_error_field is not None
        assert np.all(field.model_error_field.standard_uncertainty < noise), seed
        u_f = np.array([a.standard_uncertainty for a in field.poses[0].axes])
        u_i = np.array([a.standard_uncertainty for a in independent.poses[0].axes])
        np.testing.assert_allclose(u_f, u_i, rtol=0.1, err_msg=f"seed {seed}")
    # A 1 % test: 60 seeds reject 0.6 on average; 4 or more would be a 0.3 % event.
    assert rejected <= 3


@pytest.mark.slow
def test_field_estimated_on_noise_alone_is_small_and_not_identified() -> None:
    """The estimator itself, run whatever the adequacy test says: on noise alone its model error
    stays well below the noise (median 0.009 of the noise's u over 30 seeds) and an estimate is
    mostly not identified (it would not be drawn); those identified stay far below the noise."""
    model = load_robot_model(ROOT / "config/paper_arm.yaml")
    ratios = []
    identified = []
    for seed in range(30):
        sim = simulate_campaign(model, SimulationSettings(), seed=seed)
        calibration = identify(model, sim.campaign)
        q = sim.campaign.joint_positions
        distances = np.full(q.shape[0], 2.0)
        adequacy = assess_model_adequacy(calibration, q, TrackerNoise(), EncoderNoise(), distances)
        noise = pose_noise_covariances(calibration, q, TrackerNoise(), EncoderNoise(), distances)
        estimate = estimate_field(calibration, q, noise, adequacy.residual_covariance)
        ratios.append(estimate.standard_uncertainty / np.sqrt(np.diag(adequacy.noise_covariance)))
        identified.append(estimate.identified)
    ratios_max = np.max(ratios, axis=1)
    assert np.median(ratios) < 0.2  # measured 0.009
    assert sum(identified) <= 3  # measured 2 of 30
    # A component may come out near the noise from the noise's own fluctuation (measured: one of
    # 90 at 1.26), never in an estimate identified enough to be drawn.
    assert np.all(ratios_max[np.array(identified)] < 0.6)
