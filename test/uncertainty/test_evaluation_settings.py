"""One settings type for an evaluation: the object and the keyword call of evaluate_uncertainty
are the same evaluation; the command line's options and the uncertainty node's parameters are
built by the same functions; how the trials run (RunContext) never changes the result."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.app import RunContext, evaluate
from robocal_uncertainty.core import (
    EncoderNoise,
    SimulationSettings,
    TrackerNoise,
    identify,
    load_robot_model,
    simulate_campaign,
)
from robocal_uncertainty.uncertainty import (
    EvaluationSettings,
    UncertaintySettings,
    build_evaluation_settings,
    evaluate_uncertainty,
)
from robocal_uncertainty.uncertainty.calibration.settings import build_uncertainty_settings

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
        uncertainty=sources,
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


def test_the_service_and_the_monte_carlo_take_the_same_settings(case) -> None:
    model, campaign, calibration = case
    settings = EvaluationSettings(test_joints=TEST_JOINTS, trials=200, seed=2, coverage=0.99, frame="base")
    service = evaluate(model, campaign, settings, calibration=calibration).uncertainty
    direct = evaluate_uncertainty(model, campaign, TEST_JOINTS, settings, calibration=calibration)
    assert np.array_equal(service.samples, direct.samples)
    assert (service.n_trials, service.seed, service.coverage_probability, service.frame) == (200, 2, 0.99, "base")


def test_run_context_never_changes_the_result(case) -> None:
    model, campaign, calibration = case
    settings = EvaluationSettings(trials=600, seed=7, block_size=200)
    seen: list[tuple[int, int | None]] = []
    alone = evaluate_uncertainty(model, campaign, TEST_JOINTS, settings, calibration=calibration)
    chunked = evaluate_uncertainty(
        model,
        campaign,
        TEST_JOINTS,
        settings,
        calibration=calibration,
        run=RunContext(chunk_blocks=2, progress=lambda done, target: seen.append((done, target))),
    )
    assert np.array_equal(alone.samples, chunked.samples)
    assert seen and seen[-1] == (600, 600)


def test_user_units_are_converted_once_for_the_cli_and_the_node() -> None:
    built = build_uncertainty_settings(
        sources="tracker,encoder",
        tracker_noise_um=5.0,
        tracker_noise_um_per_m=2.0,
        encoder_noise_deg=0.005,
        linear_encoder_noise_um=7.0,
        tracker_xyz_m=(1, 2, 3),
    )
    assert built == UncertaintySettings(
        sources=("tracker", "encoder"),
        tracker_noise=TrackerNoise(a=5.0 * 1e-6, b=2.0 * 1e-6),
        encoder_noise=EncoderNoise(half_width=float(np.radians(0.005)), linear_half_width=7.0 * 1e-6),
        tracker_xyz=(1.0, 2.0, 3.0),
    )
    settings = build_evaluation_settings(built, trials="auto", frame="base", test_joints=TEST_JOINTS[0])
    assert settings.uncertainty is built and settings.trials == "auto" and settings.test_joints.shape == (1, 6)
    # The command line's options go through the same builder.
    from robocal_uncertainty.cli._evaluation import evaluation_options

    args = argparse.Namespace(
        backend="numpy", budget_trials=5, sweep_trials=5, max_trials=100, lambda_="auto", trials="300", seed=1,
        coverage=0.95, frame="base", accept_unconverged=False, budget=False, sweeps=False, tracker_noise_um=5.0,
        tracker_noise_um_per_m=2.0, encoder_noise_deg=0.005, linear_encoder_noise_um=7.0, lambda_range=None,
        min_poses=None, subset_size=None,
    )  # fmt: skip
    cli = evaluation_options(args, ["tracker", "encoder"], TEST_JOINTS)
    assert cli.uncertainty.tracker_noise == built.tracker_noise and cli.uncertainty.encoder_noise == built.encoder_noise
    assert (cli.trials, cli.seed, cli.frame, cli.max_trials) == (300, 1, "base", 100)


def test_unknown_field_is_a_type_error(case) -> None:
    model, campaign, calibration = case
    with pytest.raises(TypeError, match="no field 'trails'"):
        evaluate_uncertainty(model, campaign, TEST_JOINTS, trails=100, calibration=calibration)
    with pytest.raises(TypeError, match="no field 'settings'"):  # the old alias of `uncertainty` is gone
        EvaluationSettings().replace(settings=None)
    with pytest.raises(TypeError):
        build_evaluation_settings(UncertaintySettings(), output_frame="base")
