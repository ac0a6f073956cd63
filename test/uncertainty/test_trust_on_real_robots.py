"""Issue 7: numbers a calibration engineer can trust on a real robot.

References are independent of the Monte Carlo: a first-order propagation written out here,
the simulated truth, and held-out real measurements of the UR10 series.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import (
    SimulationSettings,
    UnmodelledErrors,
    forward_points_and_jacobian,
    identify,
    load_robot_model,
    simulate_campaign,
)
from robocal_uncertainty.core.robot_formats.robot_yaml import resolve_robot_config
from robocal_uncertainty.uncertainty import UncertaintySettings, evaluate_uncertainty
from robocal_uncertainty.uncertainty.holdout import split_campaign, validate_holdout

TEST_JOINTS = np.radians([-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451])
UR10_CSV = Path(__file__).resolve().parents[1] / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv"
UR10_TEST = np.array([0.934319, -1.79251, 1.5196, 0.272862, 0.934269, -1.57075])
ALL_NOISE = ("tracker", "encoder", "residual")


def _linear_parameter_std(calibration, campaign, settings: UncertaintySettings) -> np.ndarray:
    """First-order std of every estimated parameter under tracker + encoder noise, derived
    here from the Tikhonov normal equations with the base unpenalised."""
    layout = calibration.model.layout
    est = np.flatnonzero(calibration.estimated)
    n = campaign.n_poses
    _, jac = forward_points_and_jacobian(layout, calibration.estimate, campaign.joint_positions)
    scale = calibration.column_scale[est]
    a = jac.reshape(3 * n, -1)[:, est] / scale
    mask = np.array([not layout.names[k].startswith("base.") for k in est], dtype=float)
    h = np.linalg.solve(a.T @ a + calibration.lambda_**2 * np.diag(mask), a.T)
    theta = [idx["theta"] for idx in layout.joint_slices()]
    var_q = settings.encoder_noise.half_width**2 / 3.0
    sigma = np.zeros((3 * n, 3 * n))
    dist = np.linalg.norm(campaign.points, axis=1)
    for i in range(n):
        jq = jac[i][:, theta]
        block = var_q * jq @ jq.T + np.eye(3) * settings.tracker_noise.std(dist[i]) ** 2
        sigma[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = block
    return np.sqrt(np.diag(h @ sigma @ h.T)) / scale


@pytest.mark.parametrize("seed", [1, 2])
def test_base_parameters_centred_with_linearized_uncertainty(seed: int) -> None:
    model = load_robot_model(resolve_robot_config("paper_arm"))
    sim = simulate_campaign(model, SimulationSettings(frame="tracker"), seed=seed)
    settings = UncertaintySettings()
    result = evaluate_uncertainty(model, sim.campaign, TEST_JOINTS, uncertainty=settings, trials=6000, seed=seed)
    cal = result.calibration
    lin = _linear_parameter_std(cal, sim.campaign, settings)
    est = np.flatnonzero(cal.estimated)
    names = [cal.parameter_names[k] for k in est]
    checked = 0
    for j, name in enumerate(names):
        mc = result.parameters[j]
        k = est[j]
        if name.startswith("base."):
            checked += 1
            # Before the fix the samples held 0.0 for every base parameter.
            assert abs(mc.estimate - cal.estimate[k]) < 0.1 * mc.standard_uncertainty, name
            assert mc.standard_uncertainty == pytest.approx(lin[j], rel=0.2), name
    assert checked == 6


def test_residual_source_vanishes_without_model_error() -> None:
    model = load_robot_model(resolve_robot_config("paper_arm"))
    for seed, frame in ((1, "base"), (2, "tracker"), (3, "tracker")):
        sim = simulate_campaign(model, SimulationSettings(frame=frame), seed=seed)
        cal = identify(model, sim.campaign)
        noise = evaluate_uncertainty(
            model,
            sim.campaign,
            TEST_JOINTS,
            calibration=cal,
            trials=3000,
            seed=seed,
            uncertainty=UncertaintySettings(sources=("tracker", "encoder")),
        )
        resid = evaluate_uncertainty(
            model,
            sim.campaign,
            TEST_JOINTS,
            calibration=cal,
            trials=3000,
            seed=seed,
            uncertainty=UncertaintySettings(sources=("residual",)),
        )
        assert resid.model_adequacy.adequate
        u_noise = np.sqrt(np.trace(noise.poses[0].covariance))
        u_resid = np.sqrt(np.trace(resid.poses[0].covariance))
        assert u_resid < 0.1 * u_noise


def test_adequacy_test_rejects_about_one_percent_of_adequate_models() -> None:
    from robocal_uncertainty.uncertainty.model_adequacy import assess_model_adequacy

    model = load_robot_model(resolve_robot_config("paper_arm"))
    settings = UncertaintySettings()
    p_values = []
    for seed in range(60):
        sim = simulate_campaign(model, SimulationSettings(frame="base"), seed=1000 + seed)
        cal = identify(model, sim.campaign)
        dist = np.linalg.norm(sim.campaign.points - np.asarray(settings.tracker_xyz), axis=1)
        ad = assess_model_adequacy(
            cal, sim.campaign.joint_positions, settings.tracker_noise, settings.encoder_noise, dist
        )
        p_values.append(ad.p_value)
    p = np.array(p_values)
    # Calibrated test: p roughly uniform (mean 0.5), few rejections at 1 %.
    assert 0.35 < p.mean() < 0.65
    assert (p < 0.01).sum() <= 3


def test_model_error_is_detected_and_carried() -> None:
    model = load_robot_model(resolve_robot_config("paper_arm"))
    settings = SimulationSettings(frame="tracker", unmodelled=UnmodelledErrors(gear_amplitude=np.radians(0.01)))
    sim = simulate_campaign(model, settings, seed=4)
    result = evaluate_uncertainty(
        model, sim.campaign, TEST_JOINTS, trials=3000, seed=4, uncertainty=UncertaintySettings(sources=ALL_NOISE)
    )
    ad = result.model_adequacy
    assert not ad.adequate and ad.p_value < 1e-6
    # A 0.01 deg gear error on 0.4-0.9 m levers: tens of micrometres per axis.
    assert np.all((ad.standard_uncertainty > 20e-6) & (ad.standard_uncertainty < 150e-6))


@pytest.fixture(scope="module")
def ur10():
    if not UR10_CSV.exists():
        pytest.skip("UR10 data not present")
    from robocal_uncertainty.importers.tracker_csv import read_tracker_csv

    return load_robot_model(resolve_robot_config("ur10")), read_tracker_csv(UR10_CSV)


def test_ur10_monte_carlo_is_centred_on_the_calibrated_prediction(ur10) -> None:
    model, campaign = ur10
    train = campaign.subset(split_campaign(campaign.n_poses, n_train=53, seed=0)[0].train)
    result = evaluate_uncertainty(
        model, train, UR10_TEST, trials=6000, seed=0, uncertainty=UncertaintySettings(sources=ALL_NOISE)
    )
    pose = result.poses[0]
    u = np.sqrt(np.diag(pose.covariance))
    # Issue 7 saw z 0.10 mm off and parameters 2.4-2.7 u off with the old residual bootstrap.
    assert np.all(np.abs(pose.mean - pose.gum.estimate) < 0.3 * u)
    cal = result.calibration
    est = np.flatnonzero(cal.estimated)
    offsets = [abs(p.estimate - cal.estimate[k]) / p.standard_uncertainty for p, k in zip(result.parameters, est)]
    assert max(offsets) < 0.3


def test_ur10_holdout_intervals_hold_what_they_state(ur10) -> None:
    """53 training poses, the other 579 held out (the README's validate command)."""
    model, campaign = ur10
    v = validate_holdout(
        model,
        campaign,
        splits=split_campaign(campaign.n_poses, n_train=53, seed=0),
        settings=UncertaintySettings(sources=ALL_NOISE),
        trials=5000,
        seed=0,
    )
    assert v.n_held_out == 579
    # Issue 18's tolerance, 95 +- 4 %. On this split the leave-one-out model error (larger than
    # the in-sample one on 53 poses) makes the statement conservative: 97.2-98.8 % per axis,
    # normalised RMS 0.79-0.84; pooled over 4 random 53-pose draws 93.0 % inside the region,
    # RMS 0.97 (benchmarks/small_campaign_study.py).
    for axis in v.axes:
        assert 0.91 <= axis.inside_fraction <= 0.99, axis
        assert 0.75 <= axis.normalized_rms <= 1.15, axis
    assert 0.92 <= v.region_inside_fraction <= 0.98


def _pooled(model, settings: SimulationSettings, seeds: range) -> tuple[np.ndarray, np.ndarray, float]:
    inside, nrms2, region = [], [], []
    for seed in seeds:
        sim = simulate_campaign(model, dataclasses.replace(settings, n_poses=253), seed=seed)
        v = validate_holdout(
            model,
            sim.campaign,
            splits=split_campaign(253, n_train=53, seed=seed),
            settings=UncertaintySettings(sources=ALL_NOISE),
            trials=2000,
            seed=seed,
        )
        inside.append([a.inside_fraction for a in v.axes])
        nrms2.append([a.normalized_rms**2 for a in v.axes])
        region.append(v.region_inside_fraction)
    return np.mean(inside, axis=0), np.sqrt(np.mean(nrms2, axis=0)), float(np.mean(region))


@pytest.mark.parametrize(
    ("frame", "unmodelled"),
    [
        ("tracker", UnmodelledErrors()),
        ("tracker", UnmodelledErrors(gear_amplitude=np.radians(0.01))),
        ("base", UnmodelledErrors(compliance=np.radians(0.02))),
    ],
    ids=["adequate", "gear-error", "compliance"],
)
def test_simulated_holdout_coverage_with_and_without_model_error(frame: str, unmodelled: UnmodelledErrors) -> None:
    """Pooled over 6 campaigns: a single campaign's held-out errors share one calibration
    error, so its coverage scatters more than a binomial count would."""
    model = load_robot_model(resolve_robot_config("paper_arm"))
    inside, nrms, region = _pooled(model, SimulationSettings(frame=frame, unmodelled=unmodelled), range(6))
    assert np.all((inside >= 0.92) & (inside <= 0.98)), inside
    assert np.all((nrms >= 0.85) & (nrms <= 1.15)), nrms
    assert 0.92 <= region <= 0.98
