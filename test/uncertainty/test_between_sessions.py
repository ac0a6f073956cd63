"""The between-session component: its estimate from sessions and its Monte Carlo source."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import identify, load_robot_model
from robocal_uncertainty.core.calibration_file import read_calibration, read_session_state, write_calibration
from robocal_uncertainty.core.session import LENGTH_SCALE, effect_jacobian
from robocal_uncertainty.core.simulation import SessionSimulationSettings, simulate_sessions
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty import UncertaintySettings, evaluate_uncertainty
from robocal_uncertainty.uncertainty.sessions.between import (
    estimate_between_sessions,
    identifiable_effects,
    with_between_sessions,
)
from robocal_uncertainty.uncertainty.sessions.state import session_state
from robocal_uncertainty.uncertainty.sources import SOURCE_REGISTRY

DATA = Path(__file__).resolve().parents[2] / "robocal_uncertainty" / "data"


@pytest.fixture(scope="module")
def sessions():
    model = dataclasses.replace(load_robot_model(DATA / "ur10.yaml"), base_known=False)
    sim = simulate_sessions(model, SessionSimulationSettings(n_sessions=4, n_poses=53), seed=2)
    first = sim.sessions[0]
    cal = identify(model, first.campaign)
    state, _ = session_state(cal, first.campaign, first.settings.tracker_noise, first.settings.encoder_noise)
    return model, sim, cal, state


def test_effects_left_out_are_those_the_re_registration_absorbs(sessions) -> None:
    _, sim, cal, _ = sessions
    names = identifiable_effects(cal.model, sim.sessions[1].campaign)
    # Joint 1's offset is the tracker's yaw; joint 6's turns the tool point (0.45 mm off its axis
    # here) as a remounted tool would.
    assert names == ("joint2.theta", "joint3.theta", "joint4.theta", "joint5.theta", LENGTH_SCALE)
    assert "joint1.theta" not in identifiable_effects(cal.model, sim.sessions[1].campaign, retool=False)


def test_session_effects_match_the_truth(sessions) -> None:
    _, sim, cal, state = sessions
    between = estimate_between_sessions(cal.model, state, [s.campaign for s in sim.sessions[1:]])
    assert between.n_sessions == 4 and between.group_dof == {"joint_offsets": 12.0, "length_scale": 3.0}
    for k, change in enumerate(sim.changes[1:]):
        truth = np.array([*change.joint_offset_drift[1:5], 23e-6 * change.temperature_delta])
        z = (between.session_effects[k] - truth) / between.session_effects_std[k]
        assert np.all(np.abs(z) < 4.0), z
    # A future session relative to the reference: twice the per-session variance.
    np.testing.assert_allclose(np.diag(between.covariance)[:4], 2 * between.group_std["joint_offsets"] ** 2)
    future = with_between_sessions(state, between)
    assert future.scope == "future sessions" and future.between_session_names == between.names
    with pytest.raises(ConfigError):
        estimate_between_sessions(cal.model, state, [])


def test_file_round_trip_with_between_sessions(sessions, tmp_path: Path) -> None:
    _, sim, cal, state = sessions
    between = estimate_between_sessions(cal.model, state, [sim.sessions[1].campaign])
    future = with_between_sessions(state, between)
    path = tmp_path / "cal.json"
    write_calibration(path, cal, robot="ur10", session=future)
    data = read_calibration(path)
    assert data["scope"] == "future sessions"
    back = read_session_state(data)
    assert back is not None and back.between_session_names == between.names
    np.testing.assert_allclose(back.between_session_covariance, between.covariance)
    assert back.between_session_dof == between.dof


def test_between_session_source_adds_the_effect_covariance(sessions) -> None:
    model, sim, cal, state = sessions
    assert "between_session" in SOURCE_REGISTRY
    between = estimate_between_sessions(cal.model, state, [s.campaign for s in sim.sessions[1:]])
    test_q = sim.sessions[0].campaign.joint_positions[:3]
    settings = UncertaintySettings(sources=("between_session",), between_session=between)
    result = evaluate_uncertainty(
        model, sim.sessions[0].campaign, test_q, uncertainty=settings, calibration=cal, trials=20000, frame="base"
    )
    params = cal.estimate.copy()
    b0 = cal.model.layout.base_index
    params[b0 : b0 + 6] = 0.0
    g = effect_jacobian(cal.model.layout, params, test_q, between.names)
    for k, pose in enumerate(result.poses):
        expected = g[k] @ between.covariance @ g[k].T
        np.testing.assert_allclose(np.sqrt(np.diag(pose.covariance)), np.sqrt(np.diag(expected)), rtol=0.03)
    # Without a component the source adds nothing (so "all" stays valid).
    plain = evaluate_uncertainty(
        model,
        sim.sessions[0].campaign,
        test_q,
        uncertainty=UncertaintySettings(sources=("between_session",)),
        calibration=cal,
        trials=1000,
        frame="base",
    )
    assert np.all(np.abs(plain.poses[0].covariance) < 1e-24)


UR10_CSV = Path(__file__).resolve().parents[2] / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv"


@pytest.fixture(scope="module")
def real_reference():
    """A calibration of 53 poses of the real UR10 series with its validated error level."""
    from robocal_uncertainty.app.verification import calibrate_session
    from robocal_uncertainty.core import EncoderNoise, TrackerNoise
    from robocal_uncertainty.importers import read_tracker_csv

    model = load_robot_model(DATA / "ur10.yaml")
    campaign = read_tracker_csv(UR10_CSV)
    order = np.random.default_rng(5).permutation(campaign.n_poses)
    train = campaign.subset(np.sort(order[:53]))
    cal = calibrate_session(model, train, tracker_noise=TrackerNoise(), encoder_noise=EncoderNoise())
    assert cal.state is not None and cal.state.validated_level is not None
    return cal, train, campaign, order


def _distorted(campaign, amplitude):
    """The campaign with an extra error from pose to pose (seeded) that no session effect holds."""
    extra = amplitude * np.random.default_rng(3).standard_normal(campaign.points.shape)
    return dataclasses.replace(campaign, points=campaign.points + extra)


def test_a_session_given_twice_counts_once(real_reference) -> None:
    cal, train, campaign, order = real_reference
    later = campaign.subset(np.sort(order[53:153]))
    # The reference campaign again under another name, and one later session given twice.
    with pytest.raises(ConfigError, match="repeats the reference calibration's campaign"):
        estimate_between_sessions(cal.result.model, cal.state, [train], reference_campaign=train)
    with pytest.raises(ConfigError, match="later session 2 repeats later session 1"):
        estimate_between_sessions(cal.result.model, cal.state, [later, dataclasses.replace(later)])


def test_two_disagreeing_sessions_never_give_a_zero_component(real_reference) -> None:
    """A later session whose errors are larger than the calibration's validated level in a way
    no joint offset or length scale holds: neither the level spread nor the effects' component
    comes out zero."""
    cal, train, campaign, order = real_reference
    # The calibration's own poses measured again with 0.5 mm more error from pose to pose: the
    # robot did not move (the effects are near zero), the session's errors are larger.
    later = _distorted(train, 0.5e-3)
    between = estimate_between_sessions(cal.result.model, cal.state, [later], reference_campaign=train)
    assert between.level_p_values.size == 1 and between.level_p_values[0] < 0.05
    assert between.level_ratios[0] > 1.5
    assert between.level_log_std is not None and between.level_log_std > 0.3
    assert between.group_std["joint_offsets"] > 0.0
    assert np.all(np.diag(between.covariance) > 0.0)
    # An undistorted later session of the same series agrees: no spread forced on it.
    same = estimate_between_sessions(
        cal.result.model, cal.state, [campaign.subset(np.sort(order[53:253]))], reference_campaign=train
    )
    assert same.level_p_values[0] >= 0.05 and same.level_ratios[0] < 1.3
