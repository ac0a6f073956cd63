"""The model error as a field correlated over the configurations: distance, covariances, estimate, file."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import EncoderNoise, TrackerNoise, identify, load_robot_model
from robocal_uncertainty.core.calibration_file import read_calibration, read_session_state, write_calibration
from robocal_uncertainty.core.model_error_field import ModelErrorField, chordal_distance
from robocal_uncertainty.core.simulation import SessionSimulationSettings, simulate_sessions
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.importers import read_tracker_csv
from robocal_uncertainty.report.verification_report import verification_lines
from robocal_uncertainty.uncertainty.model_adequacy import pose_noise_covariances
from robocal_uncertainty.uncertainty.sessions.field import campaign_distances, estimate_model_error_field
from robocal_uncertainty.uncertainty.sessions.state import session_state
from robocal_uncertainty.uncertainty.sessions.verification import verify_session

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def ur10_series():
    model = load_robot_model(ROOT / "robocal_uncertainty" / "data" / "ur10.yaml")
    campaign = read_tracker_csv(ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv")
    train = campaign.reorder_joints(model.joint_names).subset(np.random.default_rng(7).permutation(632)[:53])
    cal = identify(model, train)
    state, adequacy = session_state(cal, train, TrackerNoise(), EncoderNoise())
    return model, campaign, train, cal, state, adequacy


def test_chordal_distance_is_periodic_and_euclidean_for_small_steps() -> None:
    rng = np.random.default_rng(0)
    q = rng.uniform(-3, 3, size=(5, 6))
    np.testing.assert_allclose(np.diag(chordal_distance(q, q + 2 * np.pi)), 0.0, atol=1e-6)
    dq = rng.normal(scale=1e-3, size=(5, 6))
    d = np.diag(chordal_distance(q, q + dq))
    np.testing.assert_allclose(d, np.linalg.norm(dq, axis=1), rtol=1e-5)
    # Exactly 2 |sin(dq / 2)| per joint (independent formula).
    ref = np.sqrt(np.sum((2 * np.sin((q[:, None] - q[None]) / 2)) ** 2, axis=2))
    np.testing.assert_allclose(chordal_distance(q, q), ref, atol=1e-7)


def test_prediction_covariance_matches_sampled_fields() -> None:
    """``K_cc - J G K_tc - (J G K_tc)^T + J G K_tt G^T J^T`` against the covariance of sampled
    ``e_c - J G e_t`` (fields drawn jointly at calibration and check poses)."""
    rng = np.random.default_rng(1)
    q_t, q_c = rng.uniform(-1, 1, size=(6, 2)), rng.uniform(-1, 1, size=(3, 2))
    k = 4
    gain = rng.normal(size=(k, 18))
    jac = rng.normal(size=(9, k))
    names = ("a", "b", "c", "d")
    per_pose = np.array([[2.0, 0.3, 0.0], [0.3, 1.0, 0.2], [0.0, 0.2, 1.5]])
    rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    fld = ModelErrorField(0.8, 0.7, q_t, names, gain)
    q_all = np.concatenate((q_t, q_c))
    joint = fld.covariance(q_all, per_pose)  # base frame, all poses
    e = rng.multivariate_normal(np.zeros(27), joint, size=200000)
    e_t, e_c = e[:, :18], e[:, 18:]
    e_c_meas = (e_c.reshape(-1, 3, 3) @ rot.T).reshape(-1, 9)
    pred = e_c_meas - e_t @ gain.T @ jac.T
    sampled = np.cov(pred.T)
    stated = fld.prediction_covariance(q_c, per_pose, rot, jac, names)
    jg = jac @ gain
    stated = stated + jg @ fld.covariance(q_t, per_pose) @ jg.T
    scale = np.sqrt(np.outer(np.diag(stated), np.diag(stated)))
    np.testing.assert_allclose(sampled / scale, stated / scale, atol=0.02)


def test_simulated_campaigns_have_no_correlated_model_error() -> None:
    """Simulated sessions carry noise only: the field's estimate is near zero (UR10 series: ~250 um)."""
    model = dataclasses.replace(load_robot_model(ROOT / "robocal_uncertainty" / "data" / "ur10.yaml"), base_known=False)
    settings = SessionSimulationSettings(
        n_sessions=1, n_poses=53, tool_remount_std=0.0, joint_offset_std=0.0, temperature_std=0.0
    )
    sizes = []
    for seed in range(4):
        session = simulate_sessions(model, settings, seed=seed).sessions[0]
        cal = identify(model, session.campaign)
        campaign = session.campaign.reorder_joints(model.joint_names)
        q = campaign.joint_positions
        tracker, encoder = session.settings.tracker_noise, session.settings.encoder_noise
        noise = pose_noise_covariances(cal, q, tracker, encoder, campaign_distances(campaign, cal))
        fld, scale = estimate_model_error_field(cal, q, noise, np.eye(3))
        noise_var = float(np.mean(np.trace(noise, axis1=1, axis2=2))) / 3.0
        sizes.append(scale / noise_var)
        assert fld.log_likelihood - fld.independent_log_likelihood < 2.0  # no evidence of correlation
    print("field variance / noise variance on simulated campaigns:", np.round(sizes, 4))
    assert max(sizes) < 0.1  # measured 0.0000-0.06 (u < 9 um against 36 um of noise)


def test_ur10_model_error_is_correlated_and_recorded(ur10_series, tmp_path: Path) -> None:
    model, campaign, train, cal, state, adequacy = ur10_series
    fld = state.model_error_field
    assert not adequacy.adequate and fld is not None
    # The likelihood prefers the correlated field by far; length about a quarter to 2 rad.
    assert fld.log_likelihood - fld.independent_log_likelihood > 3.0
    assert 0.1 < fld.length_scale < 3.0 and fld.correlated_fraction > 0.5
    assert 1.0 <= fld.dof < 3 * 53
    u = np.sqrt(np.diag(state.model_error_covariance))
    assert np.all((u > 1e-4) & (u < 1e-3))  # 0.1-1 mm: the residuals are ~0.2 mm per axis
    # The gain is the first-order response of the estimates to a point error (finite difference).
    i = fld.gain_names.index("joint3.a")
    base = cal.estimate.copy()
    moved = train.points.copy()
    b0 = cal.model.layout.base_index
    from robocal_uncertainty.core.robot_model import rpy_to_matrix

    r_wb = rpy_to_matrix(cal.estimate[b0 + 3 : b0 + 6])
    step = np.array([0.0, 0.0, 1e-5])
    moved[4] = moved[4] + r_wb @ step
    refit = identify(model, dataclasses.replace(train, points=moved), lambda_=cal.lambda_)
    names = list(cal.parameter_names)
    numeric = (refit.estimate[names.index("joint3.a")] - base[names.index("joint3.a")]) / 1e-5
    assert fld.gain[i, 3 * 4 + 2] == pytest.approx(numeric, rel=0.05, abs=1e-4)
    # The parameter covariance with the correlated field exceeds the independent one's.
    alone, _ = session_state(cal, train, TrackerNoise(), EncoderNoise(), correlated=False)
    j = state.covariance_names.index("joint3.a")
    assert state.parameter_covariance[j, j] > alone.parameter_covariance[j, j]
    # Written (format 3) and read back; a version 2 file reads with an independent model error.
    path = tmp_path / "cal.json"
    write_calibration(path, cal, robot="ur10", session=state)
    data = read_calibration(path)
    back = read_session_state(data)
    assert back is not None and back.model_error_field is not None
    np.testing.assert_allclose(back.model_error_field.gain, fld.gain)
    np.testing.assert_allclose(back.model_error_field.joint_positions, fld.joint_positions)
    assert back.model_error_field.length_scale == fld.length_scale and back.model_error_dof == state.model_error_dof
    v2 = json.loads(path.read_text())
    v2["format"] = "robocal_uncertainty/calibration/2"
    del v2["model_error"]["field"]
    old = read_session_state(v2)
    assert old is not None and old.model_error_field is None
    # A check of 10 other poses uses the field (consistent: p = 0.83) and the report says so.
    model_cal = cal.model
    check = campaign.subset(np.random.default_rng(7).permutation(632)[53:63])
    with_field = verify_session(model_cal, state, check, null_trials=2000)
    without = verify_session(model_cal, alone, check, null_trials=2000)
    assert with_field.model_error_length_scale == fld.length_scale and without.model_error_length_scale is None
    assert with_field.consistent
    assert any("correlated between the poses" in line for line in verification_lines(with_field, scope="x"))
    broken = json.loads(path.read_text())
    broken["model_error"]["field"]["gain"]["matrix"] = [[1.0]]
    with pytest.raises(ConfigError, match=r"model_error\.field must hold"):
        read_session_state(broken, where="calibration x.json")
