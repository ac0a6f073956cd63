"""Diagnostics status rules and RViz marker geometry, ROS-free (the nodes copy them into
diagnostic_msgs/DiagnosticArray and visualization_msgs/MarkerArray)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from pipeline_data import SEED, TEST_JOINTS
from scipy.spatial.transform import Rotation

from robocal_uncertainty.core import RobotModel, SimulationSettings, simulate_campaign
from robocal_uncertainty.errors import ConfigError, InputError
from robocal_uncertainty.pipeline import DROP_CAUSES
from robocal_uncertainty.pipeline.diagnostics import (
    DiagnosticLevel,
    DiagnosticThresholds,
    calibration_status,
    collector_status,
    uncertainty_status,
    verification_status,
)
from robocal_uncertainty.pipeline.markers import (
    ellipsoid_axes,
    quaternion_from_matrix,
    uncertainty_markers,
    visibility_scale,
)
from robocal_uncertainty.uncertainty import CalibrationUncertainty, UncertaintySettings, evaluate_uncertainty

S = 1_000_000_000
NOW = 1_700_000_100 * S


def _collector(**overrides):
    kwargs = {
        "name": "collector_node: static-pose collector",
        "hardware_id": "paper_arm",
        "now_ns": NOW,
        "samples": 12,
        "received": {"joint_states": 10_000, "tracker_points": 40_000},
        "dropped": dict.fromkeys(DROP_CAUSES, 0),
        "rejected_dwells": 0,
        "record_failures": 0,
        "last_sample_ns": NOW - 3 * S,
        "last_input_ns": {"joint_states": NOW - S // 100, "tracker_points": NOW - S // 500},
        "static": True,
    }
    kwargs.update(overrides)
    return collector_status(**kwargs)


def test_collector_ok_lists_the_key_values() -> None:
    status = _collector()
    assert status.level == DiagnosticLevel.OK and status.message == "ok"
    assert status.value("samples") == "12"
    assert float(status.value("time_since_last_sample_s")) == pytest.approx(3.0)
    for cause in DROP_CAUSES:
        assert status.value(f"dropped.{cause}") == "0"
    assert status.value("received.tracker_points") == "40000"


def test_collector_warns_on_drops_silence_and_no_input_and_errs_on_record_failures() -> None:
    dropped = dict.fromkeys(DROP_CAUSES, 0) | {"nan": 400, "wrong_frame": 200}
    status = _collector(dropped=dropped)
    assert status.level == DiagnosticLevel.WARN
    assert "600 of 50000 messages dropped (nan 400, wrong_frame 200)" in status.message
    assert status.value("dropped.nan") == "400" and status.value("dropped_total") == "600"
    assert _collector(dropped=dict.fromkeys(DROP_CAUSES, 0) | {"nan": 400}).level == DiagnosticLevel.OK  # 0.8 %
    silent = _collector(last_input_ns={"joint_states": NOW, "tracker_points": NOW - 5 * S})
    assert silent.level == DiagnosticLevel.WARN and "tracker_points silent for 5.0 s" in silent.message
    waiting = _collector(last_input_ns={"joint_states": None, "tracker_points": None}, last_sample_ns=None)
    assert waiting.level == DiagnosticLevel.WARN and "no joint_states received yet" in waiting.message
    assert waiting.value("time_since_last_sample_s") == "n/a"
    failing = _collector(record_failures=2, dropped=dropped)
    assert failing.level == DiagnosticLevel.ERROR and failing.message == "2 sample(s) could not be recorded"


def _calibration(**overrides):
    kwargs = {
        "name": "calibration_node: identification",
        "hardware_id": "paper_arm",
        "now_ns": NOW,
        "samples": 30,
        "min_samples": 10,
        "last_calibration_ns": NOW - 2 * S,
        "condition_number": 150.0,
        "residual_rms_m": 8e-6,
        "lambda_": 0.01,
        "converged": True,
    }
    kwargs.update(overrides)
    return calibration_status(**kwargs)


def test_calibration_levels() -> None:
    ok = _calibration()
    assert ok.level == DiagnosticLevel.OK
    assert ok.value("condition_number") == "150" and ok.value("residual_rms_m") == "8e-06"
    assert float(ok.value("time_since_last_calibration_s")) == 2.0
    waiting = _calibration(
        samples=4, last_calibration_ns=None, condition_number=None, residual_rms_m=None, converged=None
    )
    assert waiting.level == DiagnosticLevel.WARN and waiting.message == "waiting for samples (4 of 10)"
    assert _calibration(condition_number=3e5).level == DiagnosticLevel.WARN
    high = _calibration(residual_rms_m=2.5e-4)
    assert high.level == DiagnosticLevel.WARN and "residual RMS 250.0 um > 100.0 um" in high.message
    assert _calibration(converged=False).level == DiagnosticLevel.ERROR
    failed = _calibration(error="too few poses", condition_number=3e5)
    assert failed.level == DiagnosticLevel.ERROR and failed.message == "calibration failed: too few poses"
    tight = DiagnosticThresholds(residual_rms_warn_m=5e-6)
    assert _calibration(thresholds=tight).level == DiagnosticLevel.WARN


def test_uncertainty_levels() -> None:
    base = {
        "name": "uncertainty_node: Monte Carlo",
        "hardware_id": "paper_arm",
        "now_ns": NOW,
        "state": "done",
        "samples": 30,
        "trials": 20_000,
        "converged": True,
        "max_standard_uncertainty_m": 1.2e-5,
        "last_evaluation_ns": NOW - S,
        "last_evaluation_s": 1.5,
    }
    ok = uncertainty_status(**base)
    assert ok.level == DiagnosticLevel.OK and ok.value("monte_carlo_converged") == "true"
    assert ok.value("last_evaluation_duration_s") == "1.5" and ok.value("trials") == "20000"
    assert uncertainty_status(**base | {"state": "running"}).message == "ok (re-evaluating)"
    assert uncertainty_status(**base | {"converged": False}).level == DiagnosticLevel.WARN
    none_yet = base | {"state": "waiting_for_samples", "trials": None, "converged": None, "last_evaluation_ns": None}
    assert uncertainty_status(**none_yet).level == DiagnosticLevel.WARN
    failed = uncertainty_status(**base | {"state": "failed", "error": "singular"})
    assert failed.level == DiagnosticLevel.ERROR and "singular" in failed.message


def test_verification_levels() -> None:
    base = {"name": "calibration_node: verify", "hardware_id": "ur10", "now_ns": NOW, "calibration": "cal.json"}
    none_yet = verification_status(**base, last_check_ns=None, consistent=None)
    assert none_yet.level == DiagnosticLevel.OK and none_yet.value("verdict") == "n/a"
    assert "call ~/verify" in none_yet.message
    checked = base | {"last_check_ns": NOW - 2 * S, "p_value": 0.42, "n_poses": 10, "tracker_move_m": 1.5}
    ok = verification_status(**checked, consistent=True, summary="consistent (p = 0.42 >= 0.05)")
    assert ok.level == DiagnosticLevel.OK and ok.message.startswith("consistent")
    assert ok.value("time_since_last_check_s") == "2" and ok.value("tracker_move_m") == "1.5"
    assert ok.value("check_poses") == "10" and ok.value("tracker_turn_rad") == "n/a"
    drifted = verification_status(**checked | {"p_value": 1e-4}, consistent=False, summary="drifted by about 0.1 mm")
    assert drifted.level == DiagnosticLevel.WARN and drifted.value("verdict") == "drifted"
    refused = verification_status(**base, last_check_ns=NOW, consistent=None, error="check campaign too small")
    assert refused.level == DiagnosticLevel.ERROR and refused.message == "verify refused: check campaign too small"


def test_bad_thresholds_raise() -> None:
    with pytest.raises(ConfigError, match="input_timeout_s"):
        DiagnosticThresholds(input_timeout_s=0.0)


# -- markers -------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def uncertainty(paper_arm: RobotModel) -> tuple[CalibrationUncertainty, object]:
    sim = simulate_campaign(paper_arm, SimulationSettings(n_poses=20), seed=3)
    result = evaluate_uncertainty(
        paper_arm, sim.campaign, TEST_JOINTS, uncertainty=UncertaintySettings(), trials=400, seed=SEED
    )
    return result, sim.campaign


@pytest.mark.parametrize("seed", range(5))
def test_quaternion_reproduces_the_rotation(seed: int) -> None:
    rotation = Rotation.random(random_state=seed).as_matrix()
    q = quaternion_from_matrix(rotation)
    np.testing.assert_allclose(Rotation.from_quat(q).as_matrix(), rotation, atol=1e-12)
    assert q[3] >= 0 and np.isclose(np.linalg.norm(q), 1.0)
    with pytest.raises(InputError, match="rotation"):
        quaternion_from_matrix(-rotation)


def test_ellipsoid_axes_reproduce_the_matrix() -> None:
    rng = np.random.default_rng(1)
    a = rng.normal(size=(3, 3)) * 1e-5
    covariance = a @ a.T
    semi, rotation = ellipsoid_axes(covariance, 2.8)
    assert np.all(np.diff(semi) <= 0) and np.isclose(np.linalg.det(rotation), 1.0)
    np.testing.assert_allclose(rotation @ np.diag((semi / 2.8) ** 2) @ rotation.T, covariance, atol=1e-24)


def test_visibility_scale_is_a_power_of_ten() -> None:
    assert visibility_scale(1e-5, target_m=0.05) == 1000.0
    assert visibility_scale(0.2) == 1.0
    assert visibility_scale(0.0) == 1.0


def test_region_markers_reproduce_each_jcgm102_region(uncertainty) -> None:
    result, campaign = uncertainty
    markers = uncertainty_markers(result, campaign_points=campaign.points, campaign_frame=campaign.frame)
    regions = [m for m in markers if m.namespace == "coverage_region"]
    labels = [m for m in markers if m.namespace == "coverage_label"]
    (points,) = [m for m in markers if m.namespace == "campaign_points"]
    assert len(regions) == len(labels) == len(result.poses) == 2
    assert {m.frame_id for m in markers} == {result.frame_id} == {"base_link"}
    magnification = None
    for marker, label, pose in zip(regions, labels, result.poses):
        assert marker.kind == "sphere" and label.kind == "text"
        np.testing.assert_array_equal(marker.position, pose.mean)
        rotation = Rotation.from_quat(marker.orientation).as_matrix()
        semi = marker.scale / 2.0
        largest = float(np.max(semi))
        if magnification is None:
            magnification = largest / (
                pose.region.coverage_factor * np.sqrt(np.linalg.eigvalsh(pose.region.covariance)[-1])
            )
        semi = semi / magnification
        # {y : y^T V^-1 y <= k^2}  <=>  R diag(semi^2) R^T = k^2 V
        shape = rotation @ np.diag(semi**2) @ rotation.T
        k = pose.region.coverage_factor
        np.testing.assert_allclose(shape, k**2 * pose.region.covariance, rtol=1e-9, atol=1e-9 * np.abs(shape).max())
        # A point on the drawn surface is on the region's boundary (Mahalanobis distance k).
        edge = pose.mean + rotation[:, 0] * semi[0]
        assert float(pose.region.mahalanobis(edge)) == pytest.approx(k, rel=1e-9)
        assert f"x{magnification:g}" in label.text and "95 % region" in label.text
    assert magnification == pytest.approx(visibility_scale(max(m.scale.max() / 2 / magnification for m in regions)))
    assert magnification >= 10 and np.log10(magnification) == pytest.approx(round(np.log10(magnification)))
    assert points.kind == "sphere_list"
    np.testing.assert_array_equal(points.points, campaign.points)


def test_a_fixed_scale_and_bad_points(uncertainty) -> None:
    result, _ = uncertainty
    (region, *_) = uncertainty_markers(result, scale=100.0)
    semi, _ = ellipsoid_axes(result.poses[0].region.covariance, result.poses[0].region.coverage_factor)
    np.testing.assert_allclose(np.sort(region.scale), np.sort(2 * semi * 100.0))
    with pytest.raises(InputError, match="scale"):
        uncertainty_markers(result, scale=-1.0)
    with pytest.raises(InputError, match="campaign_points"):
        uncertainty_markers(result, campaign_points=np.zeros((4, 2)))


def test_tracker_campaign_points_are_drawn_in_the_base_frame(paper_arm: RobotModel) -> None:
    model = dataclasses.replace(paper_arm, base_known=False)
    sim = simulate_campaign(model, SimulationSettings(n_poses=20, frame="tracker"), seed=4)
    result = evaluate_uncertainty(model, sim.campaign, TEST_JOINTS, trials=200, seed=SEED, frame="base")
    (points,) = [
        m
        for m in uncertainty_markers(result, campaign_points=sim.campaign.points, campaign_frame="tracker")
        if m.namespace == "campaign_points"
    ]
    assert points.frame_id == result.frame_id == model.base_frame_id
    world_t_base = result.calibration.model.world_T_base()
    back = points.points @ world_t_base[:3, :3].T + world_t_base[:3, 3]
    np.testing.assert_allclose(back, sim.campaign.points, atol=1e-12)
