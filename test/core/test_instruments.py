"""Instruments: each one's Monte Carlo draws agree with its stated GUM variance, and the
consumers (simulation, calibration sources, section inspection) use the one definition.

Independent references: the analytic variances of the seeds' models (a uniform error of
half-width h has variance h^2 / 3; the CMM's MPE E = A + L/K with L in mm giving um), checked
against the sample statistics of many draws. Tolerance: the sample variance of N uniform draws
has relative standard error sqrt(0.8 / N) (excess kurtosis -1.2); N = 200 000 gives 0.2 %, so
1.5 % is over seven standard errors.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core.instruments import (
    CmmInstrument,
    EncoderNoise,
    TrackerNoise,
    point_displacements,
    point_error_sources,
)
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model
from robocal_uncertainty.core.simulation import SimulationSettings, draw_joint_positions, simulate_measurements
from robocal_uncertainty.uncertainty.sources import SOURCE_REGISTRY, TrialContext, UncertaintySettings

CONFIG = Path(__file__).resolve().parents[2] / "config"
N = 200_000
RTOL = 0.015


def test_tracker_mpe_draws_have_the_stated_variance() -> None:
    tracker = TrackerNoise(a=5e-6, b=4e-6)
    distance = np.array([0.5, 2.0, 6.0])
    half = 5e-6 + 4e-6 * distance  # MPE a + b L [m]
    draws = tracker.sample(np.random.default_rng(0), np.broadcast_to(distance, (N, 3)))
    assert draws.shape == (N, 3, 3)
    assert np.all(np.abs(draws) <= half[None, :, None])
    expected = np.repeat(half**2 / 3.0, 3)
    np.testing.assert_allclose(draws.reshape(N, 9).var(axis=0), expected, rtol=RTOL)
    np.testing.assert_allclose(tracker.std(distance) ** 2, half**2 / 3.0, rtol=1e-15)
    gum = tracker.distribution(distance).covariance()
    np.testing.assert_allclose(gum, np.diag(expected), rtol=1e-15, atol=0.0)


def test_tracker_distribution_leaves_a_pose_orientation_alone() -> None:
    tracker = TrackerNoise(a=5e-6, b=1e-6)
    noise = tracker.distribution([1.0, 3.0], dimension=6, rotation_components=(3, 4, 5))
    expected = np.array([6e-6] * 3 + [0.0] * 3 + [8e-6] * 3 + [0.0] * 3)
    np.testing.assert_allclose(noise.half_widths, expected, rtol=1e-15, atol=0.0)
    draws = noise.sample(np.random.default_rng(1), 1000).reshape(1000, 2, 6)
    assert np.all(draws[..., 3:] == 0.0)


@pytest.mark.parametrize("prismatic", [(False,) * 4, (True, False, False, True)])
def test_encoder_draws_have_the_stated_variance(prismatic: tuple[bool, ...]) -> None:
    encoder = EncoderNoise(half_width=float(np.radians(0.005)), linear_half_width=7e-6)
    half = np.where(prismatic, 7e-6, np.radians(0.005))
    draws = encoder.sample_joints(np.random.default_rng(2), (N, 4), prismatic)
    assert np.all(np.abs(draws) <= half)
    np.testing.assert_allclose(draws.var(axis=0), half**2 / 3.0, rtol=RTOL)
    np.testing.assert_allclose(encoder.variances(prismatic), half**2 / 3.0, rtol=1e-15)
    np.testing.assert_allclose(np.diag(encoder.distribution(prismatic, 2).covariance()), np.tile(half**2 / 3.0, 2))
    # GUM covariance through a joint Jacobian against the covariance of the propagated draws.
    jac = np.random.default_rng(3).normal(size=(3, 4)) * np.where(prismatic, 1.0, 0.8)
    propagated = draws @ jac.T
    np.testing.assert_allclose(
        np.cov(propagated.T),
        encoder.covariance(jac, prismatic),
        rtol=0.03,
        atol=1e-3 * np.abs(jac).max() ** 2 * half.max() ** 2,
    )


def test_encoder_revolute_draws_equal_with_and_without_the_joint_flags() -> None:
    encoder = EncoderNoise()
    a = encoder.sample(np.random.default_rng(4), (5, 6))
    b = encoder.sample_joints(np.random.default_rng(4), (5, 6), ())
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, np.random.default_rng(4).uniform(-encoder.half_width, encoder.half_width, (5, 6)))


def test_cmm_sources_have_the_seeds_variances() -> None:
    """MPE E = A + L/K (L in mm gives um), thermal 1.15e-3 L dt um for a length L in mm,
    probing P / sqrt(3) along the probe vector."""
    cmm = CmmInstrument()
    points = np.array([[0.03, 0.0], [0.0, -0.02], [0.01, 0.01]])
    reference = np.zeros(2)
    normals = points / np.linalg.norm(points, axis=1, keepdims=True)
    sources = {s.name: s for s in point_error_sources(cmm, points, normals, reference=reference)}
    index = np.arange(3)
    length_mm = np.linalg.norm(points, axis=1) * 1e3
    mpe_um = 1.2 + length_mm / 350.0
    mpe = sources["mpe"].displacement(sources["mpe"].draw(np.random.default_rng(5), N), index)
    np.testing.assert_allclose(mpe.reshape(N, 6).var(axis=0), np.repeat((mpe_um * 1e-6) ** 2 / 3.0, 2), rtol=RTOL)
    thermal = sources["thermal"].displacement(sources["thermal"].draw(np.random.default_rng(6), N), index)
    radial = np.einsum("tij,ij->ti", thermal, normals)  # change of each point's distance from the reference
    seed_um = 1.15e-3 * length_mm * 0.3  # the seed's standard uncertainty of a length change
    np.testing.assert_allclose(radial.std(axis=0) * 1e6, seed_um, rtol=RTOL)
    assert sources["thermal"].draw_uncertainty == pytest.approx(2e-6 / np.sqrt(3.0), rel=1e-15)
    probing = sources["probing"].displacement(sources["probing"].draw(np.random.default_rng(7), N), index)
    along = np.einsum("tij,ij->ti", probing, normals)
    np.testing.assert_allclose(along.std(axis=0), 2e-6 / np.sqrt(3.0), rtol=RTOL)
    # The sum the simulated scans draw is the sum of the sources' draws, one stream in turn.
    total = point_displacements(tuple(sources.values()), np.random.default_rng(8), 4)
    rng = np.random.default_rng(8)
    parts = sum(s.displacement(s.draw(rng, 4), index) for s in sources.values())
    np.testing.assert_array_equal(total, parts)


def test_simulation_draws_are_the_instruments_draws() -> None:
    """simulate_measurements draws the tracker errors, then the encoder errors, from the
    instruments' own definitions."""
    model = load_robot_model(CONFIG / "paper_arm.yaml")
    settings = SimulationSettings(n_poses=7, tracker_noise=TrackerNoise(a=5e-6, b=2e-6))
    q = draw_joint_positions(model, 7, rng=np.random.default_rng(9))
    params = model.parameter_vector()
    readings, points, std = simulate_measurements(params, model, q, settings, rng=np.random.default_rng(10))
    clean, true_points, _ = simulate_measurements(
        params,
        model,
        q,
        SimulationSettings(n_poses=7, tracker_noise=TrackerNoise(a=0.0), encoder_noise=EncoderNoise(0.0, 0.0)),
        rng=np.random.default_rng(10),
    )
    distance = np.linalg.norm(true_points - np.asarray(settings.tracker_xyz), axis=1)
    rng = np.random.default_rng(10)
    # points = true + noise, so their difference equals the noise to the rounding of the sum.
    np.testing.assert_allclose(points - true_points, settings.tracker_noise.sample(rng, distance), rtol=0.0, atol=1e-15)
    np.testing.assert_allclose(
        readings - q, settings.encoder_noise.sample_joints(rng, q.shape, model.prismatic), rtol=0.0, atol=1e-15
    )
    np.testing.assert_array_equal(clean, q)
    np.testing.assert_array_equal(std, np.repeat(settings.tracker_noise.std(distance)[:, None], 3, axis=1))


def test_calibration_sources_take_the_instruments_distributions() -> None:
    settings = UncertaintySettings(
        sources=("tracker", "encoder"),
        tracker_noise=TrackerNoise(a=3e-6, b=1e-6),
        encoder_noise=EncoderNoise(half_width=1e-4, linear_half_width=2e-6),
    )
    ctx = TrialContext(
        n_poses=4,
        n_joints=3,
        n_test=2,
        measurement_dimension=3,
        distances=np.array([1.0, 2.0, 3.0, 4.0]),
        model_errors=np.zeros((4, 3)),
        lambda_star=0.0,
        lambda_range=None,
        min_poses=4,
        subset_size=4,
        prismatic=(False, True, False),
    )
    tracker = SOURCE_REGISTRY["tracker"].build(settings, ctx)
    encoder = SOURCE_REGISTRY["encoder"].build(settings, ctx)
    own_t = settings.tracker_noise.distribution(ctx.distances)
    own_e = settings.encoder_noise.distribution(ctx.prismatic, 6)
    np.testing.assert_array_equal(tracker.distribution.covariance(), own_t.covariance())
    np.testing.assert_array_equal(encoder.distribution.covariance(), own_e.covariance())
    np.testing.assert_array_equal(
        tracker.draw(np.random.default_rng(11), 5), own_t.sample(np.random.default_rng(11), 5)
    )
    np.testing.assert_array_equal(
        encoder.draw(np.random.default_rng(12), 5), own_e.sample(np.random.default_rng(12), 5)
    )


def test_section_inspection_uses_the_cmm_instrument_definition() -> None:
    from robocal_uncertainty.core.instruments import cmm
    from robocal_uncertainty.inspection import section_mc

    assert section_mc.point_error_sources is cmm.point_error_sources
    assert section_mc.ErrorSource is cmm.ErrorSource
