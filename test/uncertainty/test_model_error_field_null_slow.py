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
from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
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
def test_field_estimated_on_noise_alone_is_small() -> None:
    """The estimator itself, run whatever the adequacy test says: on noise alone its model error
    stays well below the noise. (Whether it is drawn depends on its scale's degrees of freedom
    only, which noise alone gives plenty of: a field this small changes no statement, the test
    above.)"""
    model = load_robot_model(ROOT / "config/paper_arm.yaml")
    ratios = []
    for seed in range(30):
        sim = simulate_campaign(model, SimulationSettings(), seed=seed)
        calibration = identify(model, sim.campaign)
        q = sim.campaign.joint_positions
        distances = np.full(q.shape[0], 2.0)
        adequacy = assess_model_adequacy(calibration, q, TrackerNoise(), EncoderNoise(), distances)
        noise = pose_noise_covariances(calibration, q, TrackerNoise(), EncoderNoise(), distances)
        # The estimate's own scale (the posterior of its correlation is drawn, and checked on
        # these campaigns, by the test above).
        estimate = estimate_field(calibration, q, noise, adequacy.residual_covariance, correlation_posterior=False)
        ratios.append(estimate.standard_uncertainty / np.sqrt(np.diag(adequacy.noise_covariance)))
    ratios_max = np.max(ratios, axis=1)
    print(
        f"median {np.median(ratios):.3g}, above 0.6: {int(np.sum(ratios_max > 0.6))} of 30, max {ratios_max.max():.3g}"
    )
    assert np.median(ratios) < 0.2  # measured 0.009
    # A component may come out near the noise from the noise's own fluctuation (measured: 2 of 30
    # seeds above 0.6, the largest 1.26); the residual source draws it only where the adequacy
    # test rejects the model, and then changes the statement by a few per cent (the test above).
    assert np.sum(ratios_max > 0.6) <= 4
