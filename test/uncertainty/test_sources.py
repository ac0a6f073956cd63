"""Uncertainty sources as objects: one random stream per source, one noise definition for
the Monte Carlo and the GUM, and a registry that new sources join without disturbing
the others."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core.identification import identify
from robocal_uncertainty.core.kinematics import forward_points_and_jacobian
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model
from robocal_uncertainty.core.robot_model import rpy_to_matrix
from robocal_uncertainty.core.simulation import SimulationSettings, UnmodelledErrors, simulate_campaign
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo.distributions import IndependentRectangular
from robocal_uncertainty.montecarlo.engine import block_rng
from robocal_uncertainty.montecarlo.streams import source_generator
from robocal_uncertainty.uncertainty.calibration import evaluate_uncertainty, prepare_calibration_trials
from robocal_uncertainty.uncertainty.sources import (
    SOURCE_REGISTRY,
    SOURCES,
    AdditiveSource,
    SourceSpec,
    UncertaintySettings,
    parse_sources,
    register_source,
    stream_id,
)

CONFIG = Path(__file__).resolve().parents[2] / "config"
TEST_JOINTS = np.radians([[10.0, 20.0, -30.0, 40.0, 30.0, 50.0], [-60.0, -40.0, 70.0, 10.0, -20.0, 5.0]])


@pytest.fixture(scope="module")
def tracker_campaign():
    """A tracker-frame campaign with real model error, so every smooth source acts."""
    model = load_robot_model(CONFIG / "paper_arm.yaml")
    settings = SimulationSettings(n_poses=40, frame="tracker", unmodelled=UnmodelledErrors(gear_amplitude=2e-4))
    sim = simulate_campaign(model, settings, seed=7)
    return model, sim.campaign, identify(model, sim.campaign)


def _zero_source(settings, context):
    width = context.n_test * context.measurement_dimension
    return AdditiveSource(
        "zero_offset",
        IndependentRectangular(np.zeros(width)),
        (("predictions", (context.n_test, context.measurement_dimension)),),
    )


def test_adding_a_source_leaves_the_other_sources_draws_bit_identical(tracker_campaign) -> None:
    """A registered source that draws (from its own stream) but perturbs nothing must leave
    every trial bit-identical: the other sources' streams do not move."""
    model, campaign, calibration = tracker_campaign
    register_source(SourceSpec("zero_offset", "test source: zero offsets", True, _zero_source))
    try:
        assert "zero_offset" in parse_sources("all")
        base = ("tracker", "encoder", "residual", "n_poses")
        runs = [
            prepare_calibration_trials(
                model,
                campaign,
                TEST_JOINTS,
                settings=UncertaintySettings(sources=sources),
                calibration=calibration,
                frame="base",
            )(block_rng(5, 3), 300)
            for sources in (base, (*base, "zero_offset"))
        ]
    finally:
        del SOURCE_REGISTRY["zero_offset"]
    np.testing.assert_array_equal(runs[0], runs[1])


def test_each_source_draws_from_its_own_seed_sequence(tracker_campaign) -> None:
    """The documented stream of source s in block b: SeedSequence(seed, spawn_key=(b, id(s)))."""
    model, campaign, calibration = tracker_campaign
    trials = prepare_calibration_trials(
        model, campaign, TEST_JOINTS, settings=UncertaintySettings(sources=("tracker",)), calibration=calibration
    )
    tracker = trials.sources[0]
    expected_rng = np.random.default_rng(np.random.SeedSequence(9, spawn_key=(4, stream_id("tracker"))))
    expected = expected_rng.uniform(-1.0, 1.0, size=(50, tracker.distribution.size)) * tracker.distribution.half_widths
    np.testing.assert_array_equal(tracker.draw(source_generator(block_rng(9, 4), stream_id("tracker")), 50), expected)
    # Removing a source from the selection leaves the others' draws alone.
    both = prepare_calibration_trials(
        model,
        campaign,
        TEST_JOINTS,
        settings=UncertaintySettings(sources=("tracker", "encoder")),
        calibration=calibration,
    )
    assert [s.name for s in both.sources] == ["tracker", "encoder"]
    np.testing.assert_array_equal(
        both.sources[0].draw(source_generator(block_rng(9, 4), stream_id("tracker")), 50), expected
    )


def test_gum_from_source_distributions_equals_a_dense_first_order_propagation(tracker_campaign) -> None:
    """Independent reference: the covariance of every measured coordinate built densely
    (tracker a^2/3, encoder J_q J_q^T h^2/3, model error Sigma_m) pushed through the
    linearised Tikhonov solution and the kinematics, in the robot base frame. The model error
    drawn independently from pose to pose (the field's GUM: test_model_error_field_draws)."""
    model, campaign, calibration = tracker_campaign
    settings = UncertaintySettings(sources=("tracker", "encoder", "residual"), model_error="independent")
    result = evaluate_uncertainty(
        model, campaign, TEST_JOINTS, uncertainty=settings, calibration=calibration, trials=200, seed=1, frame="base"
    )
    assert not result.model_adequacy.adequate
    layout = model.layout
    est = np.flatnonzero(calibration.estimated)
    scale = calibration.column_scale[est]
    n = campaign.n_poses
    _, jac = forward_points_and_jacobian(layout, calibration.estimate, campaign.joint_positions)
    a = jac.reshape(3 * n, layout.size)[:, est] / scale
    mask = calibration.penalized[est].astype(float)
    h = np.linalg.solve(a.T @ a + calibration.lambda_**2 * np.diag(mask), a.T)
    distances = np.linalg.norm(campaign.points, axis=1)
    cov_b = np.diag(np.repeat((settings.tracker_noise.a + settings.tracker_noise.b * distances) ** 2 / 3.0, 3))
    var_q = settings.encoder_noise.half_width**2 / 3.0
    theta = [idx["theta"] for idx in layout.joint_slices()]
    sigma_m = result.model_adequacy.inadequacy_covariance
    for i in range(n):
        jq = jac[i][:, theta]
        cov_b[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] += var_q * jq @ jq.T + sigma_m
    cov_p = (h @ cov_b @ h.T) / np.outer(scale, scale)
    b0 = layout.base_index
    p_base = calibration.estimate.copy()
    p_base[b0 : b0 + 6] = 0.0
    rot = rpy_to_matrix(calibration.estimate[b0 + 3 : b0 + 6]).T
    y, gy = forward_points_and_jacobian(layout, p_base, TEST_JOINTS)
    gy[:, :, b0 : b0 + 6] = 0.0
    for i, pose in enumerate(result.poses):
        g = gy[i][:, est]
        gq = gy[i][:, theta]
        expected = g @ cov_p @ g.T + var_q * gq @ gq.T + rot @ sigma_m @ rot.T
        np.testing.assert_allclose(pose.gum.estimate, y[i], rtol=0, atol=1e-12)
        np.testing.assert_allclose(pose.gum.covariance, expected, rtol=1e-9, atol=1e-20)


def test_registry_refuses_taken_names_and_lists_every_builtin() -> None:
    assert SOURCES == ("tracker", "encoder", "lambda", "n_poses", "pose_choice", "residual", "tracker_orientation")
    assert [SOURCE_REGISTRY[s].smooth for s in SOURCES] == [True, True, False, False, False, True, True]
    with pytest.raises(ConfigError, match="taken"):
        register_source(SourceSpec("tracker", "again", True, _zero_source))
    with pytest.raises(ConfigError, match="unknown uncertainty source"):
        parse_sources("tracker,laser")
