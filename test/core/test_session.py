"""Sessions: simulated sessions know their truth; a check re-registers and tests against it."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import identify, load_robot_model
from robocal_uncertainty.core.calibration_file import (
    CALIBRATION_FORMAT,
    apply_calibration,
    read_calibration,
    read_session_state,
    write_calibration,
)
from robocal_uncertainty.core.kinematics import forward_points
from robocal_uncertainty.core.robot_model import rpy_to_matrix
from robocal_uncertainty.core.session import LENGTH_SCALE, effect_jacobian
from robocal_uncertainty.core.simulation import (
    SessionChange,
    SessionSimulationSettings,
    session_parameters,
    simulate_session,
    simulate_sessions,
)
from robocal_uncertainty.errors import ConfigError, IdentifiabilityError
from robocal_uncertainty.uncertainty.sessions.state import session_state
from robocal_uncertainty.uncertainty.sessions.tracker_move import tracker_move
from robocal_uncertainty.uncertainty.sessions.verification import verify_session

DATA = Path(__file__).resolve().parents[2] / "robocal_uncertainty" / "data"


@pytest.fixture(scope="module")
def ur10():
    return dataclasses.replace(load_robot_model(DATA / "ur10.yaml"), base_known=False)


@pytest.fixture(scope="module")
def still(ur10):
    """Two sessions where only the tracker moved, and the calibration of the first."""
    settings = SessionSimulationSettings(
        n_sessions=2, n_poses=(53, 12), tool_remount_std=0.0, joint_offset_std=0.0, temperature_std=0.0
    )
    sim = simulate_sessions(ur10, settings, seed=3)
    first = sim.sessions[0]
    cal = identify(ur10, first.campaign)
    state, _ = session_state(cal, first.campaign, first.settings.tracker_noise, first.settings.encoder_noise)
    return sim, cal, state


def test_session_parameters_apply_every_change(ur10) -> None:
    robot = ur10.parameter_vector()
    change = SessionChange(
        tracker_xyz=(2.0, 0.5, 0.1),
        tracker_rpy=(0.01, -0.02, 3.0),
        tool_offset=(1e-4, -2e-4, 3e-4),
        joint_offset_drift=tuple(np.arange(6) * 1e-5),
        temperature_delta=2.0,
    )
    p = session_parameters(ur10, robot, change, expansion=23e-6)
    layout = ur10.layout
    for j, idx in enumerate(layout.joint_slices()):
        assert p[idx["theta"]] == pytest.approx(robot[idx["theta"]] + j * 1e-5, abs=1e-15)
        assert p[idx["a"]] == pytest.approx(robot[idx["a"]] * (1 + 46e-6), rel=1e-12, abs=1e-15)
        assert p[idx["alpha"]] == robot[idx["alpha"]]
    t0 = layout.tool_index
    np.testing.assert_allclose(p[t0 : t0 + 3], robot[t0 : t0 + 3] + np.array([1e-4, -2e-4, 3e-4]), atol=1e-15)
    # The base is world_T_base of the tracker frame: the tracker origin maps to the tracker position.
    b0 = layout.base_index
    r_wb = rpy_to_matrix(p[b0 + 3 : b0 + 6])
    np.testing.assert_allclose(r_wb.T @ (np.zeros(3) - p[b0 : b0 + 3]), change.tracker_xyz, atol=1e-12)


def test_first_session_is_the_reference_and_points_match_the_truth(ur10) -> None:
    sim = simulate_sessions(ur10, SessionSimulationSettings(n_sessions=3, n_poses=20), seed=1)
    assert sim.changes[0].temperature_delta == 0.0 and not any(sim.changes[0].joint_offset_drift)
    assert all(c.temperature_delta != 0.0 for c in sim.changes[1:])
    for session in sim.sessions:
        truth = session.true_model
        exact = forward_points(ur10.layout, truth.parameter_vector(), session.true_joint_positions)
        np.testing.assert_allclose(session.true_points, exact)
        # Measured points: truth + tracker noise (<= 5 um) + encoder noise (<= 0.005 deg at < 1.5 m reach).
        assert np.max(np.abs(session.campaign.points - exact)) < 5e-6 + np.radians(0.005) * 6 * 1.5
    assert len({c.tracker_xyz for c in sim.changes}) == 3


def test_unchanged_robot_is_consistent_and_the_tracker_move_is_recovered(ur10, still) -> None:
    sim, cal, state = still
    check = sim.sessions[1]
    result = verify_session(cal.model, state, check.campaign, null_trials=2000)
    assert result.consistent, result.verdict
    assert result.dof == 3 * 12 - 6
    # The true move of the tracker from the truth of both sessions. The calibration's base frame
    # is the true one turned and shifted by the first joint's unidentifiable errors (its offset
    # acts as the base yaw), so the move's components are in a slightly turned frame: compare
    # what no frame changes, the distance and the angle.
    c1, c2 = sim.changes
    true_translation = np.subtract(c2.tracker_xyz, c1.tracker_xyz)
    move = result.move
    assert move is not None
    assert abs(move.distance - np.linalg.norm(true_translation)) < 4.0 * move.distance_std
    true_rotation = rpy_to_matrix(np.asarray(c2.tracker_rpy)) @ rpy_to_matrix(np.asarray(c1.tracker_rpy)).T
    angle = np.degrees(np.arccos(np.clip((np.trace(true_rotation) - 1) / 2, -1, 1))) * np.pi / 180
    assert abs(move.angle - angle) < 4.0 * move.angle_std + 1e-9
    # A move of metres is stated to tens of micrometres.
    assert move.distance > 0.5 and move.distance_std < 2e-4


def test_tracker_move_of_identical_registrations_is_zero() -> None:
    reg = np.array([1.0, -2.0, 0.3, 0.1, -0.2, 2.5])
    cov = np.diag([1e-10] * 3 + [1e-8] * 3)
    move = tracker_move(reg, cov, reg, cov)
    assert move.distance == pytest.approx(0.0, abs=1e-12) and move.angle == pytest.approx(0.0, abs=1e-12)
    # Two independent registrations of equal uncertainty: the variance of the difference doubles.
    one = tracker_move(reg, cov, reg, np.zeros((6, 6)))
    np.testing.assert_allclose(move.rotation_std**2, 2 * one.rotation_std**2, rtol=1e-6)
    np.testing.assert_allclose(move.translation_std**2, 2 * one.translation_std**2, rtol=1e-6)
    # The rotation part is the rpy covariance seen as rotation vectors: the same total size near rpy = 0.
    small = tracker_move(np.zeros(6), cov, np.zeros(6), np.zeros((6, 6)))
    np.testing.assert_allclose(small.rotation_std, 1e-4, rtol=1e-6)


def test_joint_offset_drift_is_detected_and_named(ur10, still) -> None:
    sim, cal, state = still
    drift = SessionChange(
        tracker_xyz=sim.changes[1].tracker_xyz,
        tracker_rpy=sim.changes[1].tracker_rpy,
        joint_offset_drift=(0.0, float(np.radians(0.02)), 0.0, 0.0, 0.0, 0.0),
    )
    session = simulate_session(
        ur10,
        sim.robot_parameters,
        drift,
        dataclasses.replace(sim.sessions[1].settings, n_poses=12),
        rng=np.random.default_rng(5),
    )
    result = verify_session(
        cal.model,
        state,
        session.campaign,
        null_trials=2000,
        effects=("joint2.theta", "joint3.theta", "joint4.theta", "joint5.theta", LENGTH_SCALE),
    )
    assert not result.consistent and result.verdict.startswith("drifted")
    assert result.excess_std > 0.0
    assert result.effects is not None and result.effects_covariance is not None
    std = np.sqrt(np.diag(result.effects_covariance))
    assert abs(result.effects[0] - np.radians(0.02)) < 4 * std[0]
    assert np.argmax(np.abs(result.effects[:4] / std[:4])) == 0


def test_retool_re_registers_the_tool_point(ur10, still) -> None:
    sim, cal, state = still
    change = dataclasses.replace(sim.changes[1], tool_offset=(3e-4, -2e-4, 5e-4))
    session = simulate_session(
        ur10, sim.robot_parameters, change, sim.sessions[1].settings, rng=np.random.default_rng(9)
    )
    without = verify_session(cal.model, state, session.campaign, null_trials=1000)
    assert not without.consistent
    result = verify_session(cal.model, state, session.campaign, retool=True, null_trials=1000)
    assert result.dof == 3 * 12 - 9
    assert result.consistent, result.verdict
    assert result.tool_change is not None and result.tool_change_std is not None
    np.testing.assert_array_less(np.abs(result.tool_change - change.tool_offset), 4 * result.tool_change_std)


def test_too_small_and_degenerate_checks_are_refused(still) -> None:
    sim, cal, state = still
    check = sim.sessions[1].campaign
    with pytest.raises(IdentifiabilityError) as err:
        verify_session(cal.model, state, check.subset([0, 1, 2]))
    assert "check campaign too small: 3 poses" in str(err.value) and "\n" not in str(err.value)
    same = check.subset([0] * 8)
    with pytest.raises(IdentifiabilityError) as err:
        verify_session(cal.model, state, same)
    assert str(err.value).startswith("7 check pose(s) repeat another exactly and count once: check campaign too small")
    with pytest.raises(ConfigError):
        verify_session(cal.model, state, check, significance=1.5)


def test_null_distribution_depends_on_the_seed_only(still) -> None:
    sim, cal, state = still
    a = verify_session(cal.model, state, sim.sessions[1].campaign, null_trials=5000, seed=4)
    b = verify_session(cal.model, state, sim.sessions[1].campaign, null_trials=5000, seed=4)
    assert a.p_value == b.p_value
    # Uniform tracker and encoder noise: the Monte Carlo p and the chi-square p agree roughly.
    assert abs(a.p_value - a.p_value_chi2) < 0.15


def test_effect_jacobian_by_finite_differences(ur10) -> None:
    p = ur10.parameter_vector()
    q = np.random.default_rng(0).uniform(-2, 2, size=(4, 6))
    names = ("joint2.theta", LENGTH_SCALE)
    g = effect_jacobian(ur10.layout, p, q, names)
    h = 1e-7
    layout = ur10.layout
    lengths = [idx[k] for idx in layout.joint_slices() for k in ("a", "d")]
    scaled = p.copy()
    scaled[lengths] *= 1 + h
    numeric = (forward_points(layout, scaled, q) - forward_points(layout, p, q)) / h
    np.testing.assert_allclose(g[:, :, 1], numeric, atol=1e-6)
    shifted = p.copy()
    shifted[layout.index("joint2.theta")] += h
    np.testing.assert_allclose(
        g[:, :, 0], (forward_points(layout, shifted, q) - forward_points(layout, p, q)) / h, atol=1e-6
    )
    with pytest.raises(ConfigError):
        effect_jacobian(layout, p, q, ("joint9.theta",))


def test_calibration_file_carries_the_session_and_reads_version_1(ur10, still, tmp_path: Path) -> None:
    _, cal, state = still
    path = tmp_path / "cal.json"
    write_calibration(path, cal, robot="ur10", session=state)
    data = read_calibration(path)
    assert data["format"] == CALIBRATION_FORMAT == "robocal_uncertainty/calibration/3"
    assert data["scope"] == "session" and data["between_session"] is None
    assert data["determined"] == [n for n, e in zip(cal.parameter_names, cal.estimated) if e]
    back = read_session_state(data)
    assert back is not None
    np.testing.assert_allclose(back.parameter_covariance, state.parameter_covariance)
    np.testing.assert_allclose(back.registration, state.registration)
    np.testing.assert_allclose(back.registration_covariance, state.registration_covariance)
    assert back.covariance_names == state.covariance_names
    assert back.tracker_noise == state.tracker_noise and back.encoder_noise == state.encoder_noise
    # The registration covariance is the base block of the parameter covariance.
    assert np.all(np.diag(back.registration_covariance) > 0)
    # Version 1: still applied, no session record.
    old = json.loads(path.read_text())
    old = {k: v for k, v in old.items() if k not in ("session", "parameter_covariance", "noise", "model_error")}
    old["format"] = "robocal_uncertainty/calibration/1"
    v1 = tmp_path / "v1.json"
    v1.write_text(json.dumps(old))
    data1 = read_calibration(v1)
    assert read_session_state(data1) is None
    np.testing.assert_array_equal(
        apply_calibration(ur10, data1).parameter_vector(), apply_calibration(ur10, data).parameter_vector()
    )
    broken = dict(data)
    broken["parameter_covariance"] = {"names": ["a", "b"], "matrix": [[1.0]]}
    with pytest.raises(ConfigError) as err:
        read_session_state(broken, where="calibration x.json")
    assert "parameter_covariance.matrix must be a finite 2x2 matrix" in str(err.value)


def test_a_repeated_check_pose_counts_once(still) -> None:
    """The same pose and measurement twice is one observation: the test is the one without it."""
    sim, cal, state = still
    check = sim.sessions[1].campaign.subset(list(range(10)))
    doubled = sim.sessions[1].campaign.subset([*range(10), 3, 7])
    once = verify_session(cal.model, state, check, null_trials=500)
    twice = verify_session(cal.model, state, doubled, null_trials=500)
    assert twice.duplicates == 2 and once.duplicates == 0
    assert twice.n_poses == 10 and twice.dof == once.dof
    assert twice.chi2 == pytest.approx(once.chi2, rel=1e-9)
    assert twice.p_value == once.p_value
    assert any("counted once" in w for w in twice.warnings)
