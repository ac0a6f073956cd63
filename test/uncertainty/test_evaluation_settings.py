"""evaluate_uncertainty takes its result-determining settings as one EvaluationSettings; the
keyword call of before (settings=, trials=, seed=, frame=, ...) is the same evaluation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import SimulationSettings, identify, load_robot_model, simulate_campaign
from robocal_uncertainty.uncertainty import (
    EvaluationOptions,
    EvaluationSettings,
    UncertaintySettings,
    evaluate_campaign,
    evaluate_uncertainty,
)

REPO = Path(__file__).resolve().parents[2]
TEST_JOINTS = np.radians([[-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451]])


@pytest.fixture(scope="module")
def case():
    model = load_robot_model(REPO / "config" / "paper_arm.yaml")
    campaign = simulate_campaign(model, SimulationSettings(n_poses=30), seed=3).campaign
    return model, campaign, identify(model, campaign)


def test_object_and_keyword_calls_are_the_same_evaluation(case) -> None:
    model, campaign, calibration = case
    sources = UncertaintySettings(sources=("tracker", "encoder", "lambda"))
    settings = EvaluationSettings(uncertainty=sources, trials=300, seed=4, coverage=0.9, frame="base")
    by_object = evaluate_uncertainty(model, campaign, TEST_JOINTS, settings, calibration=calibration)
    by_keywords = evaluate_uncertainty(
        model,
        campaign,
        TEST_JOINTS,
        settings=sources,
        trials=300,
        seed=4,
        coverage=0.9,
        frame="base",
        calibration=calibration,
    )
    # A keyword replaces the field of a given object.
    mixed = evaluate_uncertainty(
        model,
        campaign,
        TEST_JOINTS,
        EvaluationSettings(uncertainty=sources, seed=4),
        trials=300,
        coverage=0.9,
        frame="base",
        calibration=calibration,
    )
    for other in (by_keywords, mixed):
        assert np.array_equal(other.samples, by_object.samples)
        assert np.array_equal(other.rotation_samples, by_object.rotation_samples)
    assert by_object.n_trials == 300 and by_object.seed == 4 and by_object.frame == "base"
    assert by_object.coverage_probability == 0.9 and by_object.settings is sources
    # Another seed is another evaluation: the settings do reach the trials.
    other_seed = evaluate_uncertainty(model, campaign, TEST_JOINTS, settings.replace(seed=5), calibration=calibration)
    assert not np.array_equal(other_seed.samples, by_object.samples)


def test_options_give_the_evaluation_settings(case) -> None:
    model, campaign, calibration = case
    options = EvaluationOptions(test_joints=TEST_JOINTS, trials=200, seed=2, coverage=0.99, output_frame="base")
    settings = options.evaluation_settings()
    assert (settings.trials, settings.seed, settings.coverage, settings.frame) == (200, 2, 0.99, "base")
    assert settings.uncertainty is options.uncertainty and settings.lambda_ == options.lambda_
    via_options = evaluate_campaign(model, campaign, options, calibration=calibration)
    direct = evaluate_uncertainty(model, campaign, TEST_JOINTS, settings, calibration=calibration)
    assert np.array_equal(via_options.samples, direct.samples)


def test_unknown_keyword_is_a_type_error(case) -> None:
    model, campaign, calibration = case
    with pytest.raises(TypeError, match="unexpected keyword argument 'trails'"):
        evaluate_uncertainty(model, campaign, TEST_JOINTS, trails=100, calibration=calibration)
    assert EvaluationSettings().replace(settings=None).uncertainty == UncertaintySettings()
