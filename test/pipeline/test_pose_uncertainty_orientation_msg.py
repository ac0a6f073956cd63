"""PoseUncertainty messages carry the orientation; pose_with_covariance gives the full 6x6
(ROS convention, rad^2) with a huge variance only along undetermined rotations. ROS-free:
rosbags typestore."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.bagio.messages import (
    POSE_UNCERTAINTY,
    decode_message,
    encode_message,
    pose_with_covariance,
    uncertainty_to_msgs,
)
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model
from robocal_uncertainty.core.simulation import SimulationSettings, simulate_campaign
from robocal_uncertainty.uncertainty.calibration import evaluate_uncertainty
from robocal_uncertainty.uncertainty.sources import UncertaintySettings

UR10 = Path(__file__).resolve().parents[2] / "config" / "ur10.yaml"
Q = np.array([[0.3, -1.2, 1.1, 0.2, 0.5, 0.1]])


@pytest.fixture(scope="module", params=[None, 1e-4], ids=["points", "poses"])
def result(request: pytest.FixtureRequest):  # type: ignore[no-untyped-def]
    model = load_robot_model(UR10)
    sim = simulate_campaign(model, SimulationSettings(frame="tracker", orientation_std=request.param), seed=3)
    sources = ("tracker", "encoder") if request.param is None else ("tracker", "tracker_orientation", "encoder")
    return evaluate_uncertainty(
        model, sim.campaign, Q, uncertainty=UncertaintySettings(sources=sources), trials=400, block_size=400
    )


def test_message_roundtrip_carries_the_orientation(result) -> None:  # type: ignore[no-untyped-def]
    (message,) = uncertainty_to_msgs(result, stamp_ns=5)
    back = decode_message(encode_message(message, POSE_UNCERTAINTY), POSE_UNCERTAINTY)
    orientation = result.poses[0].orientation
    # A statement about the orientation only where a rotation is determined (points on
    # joint 6's axis determine none: has_orientation false, u NaN, covariance the huge variance).
    assert back.has_orientation == bool(np.any(orientation.determined))
    assert back.has_orientation == result.calibration.measurement.measures_orientation
    q = back.mean_orientation
    np.testing.assert_array_equal([q.x, q.y, q.z, q.w], orientation.mean_quaternion)
    np.testing.assert_array_equal(back.orientation_undetermined, ~np.array(orientation.determined))
    u = np.asarray(back.orientation_standard_uncertainty)
    assert np.isnan(u[~np.array(orientation.determined)]).all()
    assert np.isfinite(u[np.array(orientation.determined)]).all()
    rotation_block = pose_with_covariance(result.poses[0])[2][3:, 3:]
    np.testing.assert_array_equal(np.asarray(back.orientation_covariance), rotation_block.reshape(-1))
    if back.has_orientation:
        np.testing.assert_array_equal(np.asarray(back.orientation_covariance), orientation.covariance.reshape(-1))
    else:
        np.testing.assert_array_equal(np.asarray(back.orientation_covariance), (1e6 * np.eye(3)).reshape(-1))
    np.testing.assert_array_equal(
        np.asarray(back.pose_covariance).reshape(6, 6), pose_with_covariance(result.poses[0])[2]
    )


def test_pose_with_covariance_is_huge_only_where_undetermined(result) -> None:  # type: ignore[no-untyped-def]
    pose = result.poses[0]
    position, quaternion, cov = pose_with_covariance(pose, undetermined_variance=1e6)
    np.testing.assert_array_equal(position, pose.mean)
    np.testing.assert_array_equal(quaternion, pose.orientation.mean_quaternion)
    np.testing.assert_array_equal(cov[:3, :3], pose.covariance)
    rot = cov[3:, 3:]
    directions = pose.orientation.undetermined_directions.reshape(-1, 3)
    if result.calibration.measurement.measures_orientation:
        # 6-DOF data determine every rotation: no huge variance, the Monte Carlo covariance.
        assert directions.shape[0] == 0
        assert rot.max() < 1e-6
        np.testing.assert_allclose(cov, pose.orientation.pose_covariance)
    else:
        # Points with the tool point on joint 6's axis: no rotation is determined, every
        # rotation direction gets the huge variance.
        assert directions.shape[0] == 3
        for u in directions:
            assert u @ rot @ u == pytest.approx(1e6, rel=1e-6)
        # Exactly the stated variance, uncorrelated (was 1e6 + 2e-10 with 1e-10 cross terms).
        np.testing.assert_array_equal(rot, 1e6 * np.eye(3))
        np.testing.assert_array_equal(cov[:3, 3:], 0.0)
        np.testing.assert_array_equal(cov[3:, :3], 0.0)
