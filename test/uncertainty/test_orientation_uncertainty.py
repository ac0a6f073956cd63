"""Tool orientation uncertainty from a point-only campaign: positions unchanged bit for bit,
the undetermined rotation named, agreement with the GUM and with an independent linearisation."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import SimulationSettings, load_robot_model, simulate_campaign
from robocal_uncertainty.core.kinematics import forward_poses
from robocal_uncertainty.core.rotation import quaternion_to_matrix, rotation_log
from robocal_uncertainty.uncertainty import UncertaintySettings, evaluate_uncertainty

ROOT = Path(__file__).resolve().parents[2]
TEST_JOINTS = np.radians([[-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451], [10, -200, -90, -80, -50, 30]])
NOISE = UncertaintySettings(sources=("tracker", "encoder"))


@pytest.fixture(scope="module")
def on_axis():
    """Paper arm, tool point at the flange centre (on joint 6's axis): joint6.theta unseen."""
    model = load_robot_model(ROOT / "config/paper_arm.yaml")
    sim = simulate_campaign(model, SimulationSettings(), seed=11)
    return model, sim, evaluate_uncertainty(model, sim.campaign, TEST_JOINTS, uncertainty=NOISE, trials=4000, seed=3)


@pytest.fixture(scope="module")
def off_axis():
    """The same arm with a tool point 80 mm off joint 6's axis."""
    model = load_robot_model(ROOT / "config/paper_arm.yaml")
    model = dataclasses.replace(model, tool_point=np.array([0.08, 0.0, 0.05]))
    sim = simulate_campaign(model, SimulationSettings(), seed=12)
    return model, sim, evaluate_uncertainty(model, sim.campaign, TEST_JOINTS, uncertainty=NOISE, trials=4000, seed=4)


def test_positions_and_parameters_are_bit_identical_without_orientation(on_axis) -> None:
    model, sim, with_rot = on_axis
    without = evaluate_uncertainty(
        model, sim.campaign, TEST_JOINTS, uncertainty=NOISE, trials=4000, seed=3, orientation=False
    )
    np.testing.assert_array_equal(with_rot.samples, without.samples)
    for a, b in zip(with_rot.poses, without.poses):
        np.testing.assert_array_equal(a.covariance, b.covariance)
        np.testing.assert_array_equal(a.gum.covariance, b.gum.covariance)
        assert a.axes == b.axes
        assert b.orientation is None
        assert a.orientation is not None


def test_point_campaign_on_tool_axis_leaves_every_rotation_undetermined(on_axis) -> None:
    """Points on joint 6's axis see neither the rotation about it nor the flange tilt of the
    joint6.a / joint6.alpha errors the calibration holds at nominal: nothing is stated."""
    _, _, result = on_axis
    for pose in result.poses:
        o = pose.orientation
        assert o.undetermined_directions.shape == (3, 3)
        np.testing.assert_allclose(o.undetermined_directions @ o.undetermined_directions.T, np.eye(3), atol=1e-12)
        assert o.determined == (False, False, False)
        ros = o.ros_covariance(pose.covariance)
        assert ros.shape == (6, 6)
        np.testing.assert_allclose(ros, ros.T)
        assert np.all(np.linalg.eigvalsh(ros[3:, 3:]) > 1e5)
        np.testing.assert_array_equal(ros[:3, :3], pose.covariance)


def test_mean_rotation_is_a_rotation_and_its_quaternion(on_axis) -> None:
    _, _, result = on_axis
    for pose in result.poses:
        o = pose.orientation
        np.testing.assert_allclose(o.mean_rotation @ o.mean_rotation.T, np.eye(3), atol=1e-14)
        np.testing.assert_allclose(quaternion_to_matrix(o.mean_quaternion), o.mean_rotation, atol=1e-14)
        assert abs(np.linalg.det(o.mean_rotation) - 1.0) < 1e-14
        # Zero-mean noise: the mean orientation is the calibrated one to far below u.
        offset = rotation_log(o.mean_rotation @ o.calibrated_rotation.T)
        assert np.all(np.abs(offset) < 0.1 * np.sqrt(np.diag(o.covariance)))
        # Deviations are about the mean: their own mean is ~0 (second order).
        assert all(abs(a.estimate) < 0.05 * a.standard_uncertainty for a in o.axes)
        assert pose.pose_covariance.shape == (6, 6)
        np.testing.assert_array_equal(pose.pose_covariance[:3, :3], pose.covariance)
        np.testing.assert_array_equal(pose.pose_covariance[3:, 3:], o.covariance)


def test_points_never_fix_the_rotation_about_joint_6_even_off_axis(off_axis) -> None:
    """With the tool point free, a joint-6 offset error and a tool point turned about joint 6's
    axis move every measured point alike (joint6.theta = 0.08 * tool.y): the flange's rotation
    about that axis is undetermined by points wherever the point is."""
    _, _, result = off_axis
    assert any(dep.startswith("joint6.theta") for dep in result.calibration.dependencies)
    for pose in result.poses:
        o = pose.orientation
        assert o.undetermined_directions.shape == (1, 3)
        assert abs(abs(float(o.undetermined_directions[0] @ o.mean_rotation[:, 2])) - 1.0) < 1e-6
        # Tens of microradians from a 30 um tracker: physically sized (not zero, not huge).
        u = np.array([a.standard_uncertainty for a in o.axes])
        assert np.all((u > 1e-6) & (u < 1e-3))


@pytest.mark.parametrize("case", ["on_axis", "off_axis"])
def test_rotation_uncertainty_agrees_with_the_gum(case: str, request) -> None:
    _, _, result = request.getfixturevalue(case)
    for pose in result.poses:
        o = pose.orientation
        u_mc = np.array([a.standard_uncertainty for a in o.axes])
        np.testing.assert_allclose(o.gum.standard_uncertainty, u_mc, rtol=0.05)
        assert o.gum.applicable
        np.testing.assert_array_equal(o.gum.estimate, np.zeros(3))


def test_rotation_covariance_agrees_with_an_independent_linearisation(off_axis) -> None:
    """Finite differences of the orientation in the parameters, propagated with the Monte Carlo
    parameter covariance (a reference built from neither the angular Jacobian nor the trials'
    rotation columns); tracker noise only, so the test joints are exact."""
    model, sim, _ = off_axis
    result = evaluate_uncertainty(
        model, sim.campaign, TEST_JOINTS, uncertainty=UncertaintySettings(sources=("tracker",)), trials=4000, seed=6
    )
    layout = model.layout
    est = np.array([layout.index(n) for n in result.parameter_names])
    p0 = result.calibration.estimate
    n_test = TEST_JOINTS.shape[0]
    params = result.samples[:, 3 * n_test :]
    cov_p = np.cov(params, rowvar=False)
    _, r0 = forward_poses(layout, p0, TEST_JOINTS)
    h = 1e-7
    g = np.empty((n_test, 3, est.size))
    for c, k in enumerate(est):
        dp = np.zeros(p0.size)
        dp[k] = h
        rp = forward_poses(layout, p0 + dp, TEST_JOINTS)[1]
        rm = forward_poses(layout, p0 - dp, TEST_JOINTS)[1]
        g[:, :, c] = (rotation_log(rp @ np.swapaxes(r0, -1, -2)) - rotation_log(rm @ np.swapaxes(r0, -1, -2))) / (2 * h)
    for i, pose in enumerate(result.poses):
        want = g[i] @ cov_p @ g[i].T
        np.testing.assert_allclose(pose.orientation.covariance, want, rtol=0.02, atol=1e-3 * np.max(np.diag(want)))


@pytest.mark.parametrize("frame", ["measurement", "base"])
@pytest.mark.parametrize(("orientation_std", "tool_point", "expected"), [(1e-4, None, 0), (None, (0.08, 0.0, 0.05), 1)])
def test_undetermined_rotations_do_not_depend_on_the_output_frame(
    frame: str, orientation_std: float | None, tool_point: tuple[float, float, float] | None, expected: int
) -> None:
    """A tracker-frame campaign (base identified) stated in the tracker or the robot base frame:
    6-DOF data determine every rotation, points with an off-axis tool all but the rotation about
    joint 6's axis. In the base frame the joint-1 parameters the base absorbs (joint1.alpha =
    base.roll, ...) define the frame; they once came out as two extra undetermined rotations."""
    model = load_robot_model(ROOT / "config/ur10.yaml")
    if tool_point is not None:
        model = dataclasses.replace(model, tool_point=np.asarray(tool_point))
    settings = SimulationSettings(frame="tracker", n_poses=30, orientation_std=orientation_std)
    sim = simulate_campaign(model, settings, seed=0)
    q = np.radians([[10.0, -60, 40, -30, 50, 20], [-40, -100, 70, 10, -30, 60]])
    result = evaluate_uncertainty(model, sim.campaign, q, uncertainty=NOISE, trials=200, seed=1, frame=frame)
    for pose in result.poses:
        assert pose.orientation.undetermined_directions.shape == (expected, 3)
        if expected:
            tool_z = pose.orientation.mean_rotation[:, 2]
            assert abs(abs(float(pose.orientation.undetermined_directions[0] @ tool_z)) - 1.0) < 1e-5
