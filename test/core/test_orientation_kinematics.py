"""Tool orientation: forward kinematics against pinocchio and a plain matrix product, the
angular Jacobian against central differences, and the rotation helpers."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core.kinematics import forward_points, forward_poses, forward_poses_and_jacobian
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model
from robocal_uncertainty.core.robot_model import RobotModel, rpy_to_matrix
from robocal_uncertainty.core.rotation import (
    chordal_mean,
    euler_to_matrix,
    quaternion_from_matrix,
    quaternion_to_matrix,
    rotation_exp,
    rotation_log,
)
from robocal_uncertainty.errors import InputError

REPO = Path(__file__).resolve().parents[2]
ROBOTS = [REPO / "config" / "paper_arm.yaml", REPO / "config" / "ur10.yaml"]


def _h(rot: np.ndarray | None = None, xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    out = np.eye(4)
    if rot is not None:
        out[:3, :3] = rot
    out[:3, 3] = xyz
    return out


def _axis(axis: int, t: float) -> np.ndarray:
    v = np.zeros(3)
    v[axis] = t
    return rotation_exp(v)


def perturbed(model: RobotModel, rng: np.random.Generator) -> RobotModel:
    """Random geometry errors, Hayati betas, a far-away base and a tool point."""
    n = model.n_joints
    return dataclasses.replace(
        model,
        alpha=model.alpha + rng.uniform(-0.02, 0.02, n),
        a=model.a + rng.uniform(-0.01, 0.01, n),
        theta=model.theta + rng.uniform(-0.02, 0.02, n),
        d=model.d + rng.uniform(-0.01, 0.01, n),
        beta=rng.uniform(-0.02, 0.02, n),
        tool_point=rng.uniform(-0.15, 0.15, 3),
        base_xyz=rng.uniform(-2.0, 2.0, 3),
        base_rpy=rng.uniform(-np.pi, np.pi, 3) * np.array([1.0, 0.45, 1.0]),
    )


def product_pose(model: RobotModel, q: np.ndarray) -> np.ndarray:
    """world_T_tool as one 4x4 product per documented row (no package kinematics)."""
    t = _h(rpy_to_matrix(model.base_rpy), tuple(model.base_xyz))
    for i in range(model.n_joints):
        beta = model.beta[i] if model.has_beta[i] else 0.0
        t = (
            t
            @ _h(_axis(0, model.alpha[i]))
            @ _h(xyz=(model.a[i], 0.0, 0.0))
            @ _h(_axis(1, beta))
            @ _h(_axis(2, q[i] + model.theta[i]))
            @ _h(xyz=(0.0, 0.0, model.d[i]))
        )
    return t @ _h(xyz=tuple(model.tool_point))


@pytest.mark.parametrize("path", ROBOTS, ids=["paper_arm", "ur10"])
def test_forward_poses_equal_forward_points_and_a_plain_product(path: Path) -> None:
    rng = np.random.default_rng(3)
    model = perturbed(load_robot_model(path), rng)
    q = rng.uniform(-np.pi, np.pi, (25, model.n_joints))
    points, rotations = forward_poses(model, model.parameter_vector(), q)
    assert points.shape == (25, 3)
    assert rotations.shape == (25, 3, 3)
    np.testing.assert_array_equal(points, forward_points(model, model.parameter_vector(), q))
    want = np.array([product_pose(model, qi) for qi in q])
    np.testing.assert_allclose(rotations, want[:, :3, :3], rtol=0, atol=1e-13)
    np.testing.assert_allclose(points, want[:, :3, 3], rtol=0, atol=1e-12)


@pytest.mark.parametrize("path", ROBOTS, ids=["paper_arm", "ur10"])
def test_tool_orientation_matches_pinocchio(path: Path, record_property) -> None:
    pin = pytest.importorskip(
        "pinocchio", reason="the pinocchio extra is not installed (its wheels need numpy >= 1.26)"
    )
    rng = np.random.default_rng(17 + len(path.name))
    nominal = load_robot_model(path)
    worst = 0.0
    for _ in range(4):
        model = perturbed(nominal, rng)
        pmodel = pin.Model()
        parent = 0
        for i in range(model.n_joints):
            beta = model.beta[i] if model.has_beta[i] else 0.0
            before = (
                _h(rpy_to_matrix(model.base_rpy), tuple(model.base_xyz)) if i == 0 else _h(xyz=(0, 0, model.d[i - 1]))
            )
            placement = (
                before
                @ _h(_axis(0, model.alpha[i]))
                @ _h(xyz=(model.a[i], 0.0, 0.0))
                @ _h(_axis(1, beta))
                @ _h(_axis(2, model.theta[i]))
            )
            se3 = pin.SE3(np.ascontiguousarray(placement[:3, :3]), np.ascontiguousarray(placement[:3, 3]))
            parent = pmodel.addJoint(parent, pin.JointModelRZ(), se3, f"j{i + 1}")
        tool = pin.SE3(np.eye(3), np.array([0.0, 0.0, model.d[-1]]) + model.tool_point)
        data = pmodel.createData()
        q = rng.uniform(nominal.joint_limits[:, 0], nominal.joint_limits[:, 1], (30, model.n_joints))
        points, rotations = forward_poses(model, model.parameter_vector(), q)
        for k, qk in enumerate(q):
            pin.forwardKinematics(pmodel, data, np.ascontiguousarray(qk))
            pose = data.oMi[parent] * tool
            worst = max(worst, float(np.max(np.abs(rotations[k] - pose.rotation))))
            assert np.max(np.abs(points[k] - pose.translation)) < 1e-9
    record_property("pinocchio_max_rotation_error", worst)
    assert worst < 1e-12


@pytest.mark.parametrize("path", ROBOTS, ids=["paper_arm", "ur10"])
def test_angular_jacobian_matches_central_differences(path: Path) -> None:
    rng = np.random.default_rng(5)
    model = perturbed(load_robot_model(path), rng)
    p = model.parameter_vector()
    q = rng.uniform(-np.pi, np.pi, (7, model.n_joints))
    points, rotations, jac = forward_poses_and_jacobian(model, p, q)
    assert jac.shape == (7, 6, p.size)
    np.testing.assert_array_equal(points, forward_points(model, p, q))
    h = 1e-6
    for k in range(p.size):
        dp = np.zeros(p.size)
        dp[k] = h
        rp = forward_poses(model, p + dp, q)[1]
        rm = forward_poses(model, p - dp, q)[1]
        # World-frame (fixed-axis) angular rate: log(R(p+h) R(p)^T) / h.
        w = (rotation_log(rp @ np.swapaxes(rotations, -1, -2)) - rotation_log(rm @ np.swapaxes(rotations, -1, -2))) / (
            2 * h
        )
        np.testing.assert_allclose(jac[:, 3:, k], w, rtol=0, atol=1e-8)


def test_rotation_helpers_round_trip() -> None:
    rng = np.random.default_rng(0)
    v = rng.normal(0.0, 1.5, (2000, 3))
    r = rotation_exp(v)
    np.testing.assert_allclose(r @ np.swapaxes(r, -1, -2), np.broadcast_to(np.eye(3), r.shape), atol=1e-14)
    np.testing.assert_allclose(rotation_exp(rotation_log(r)), r, atol=1e-13)
    tiny = rng.normal(0.0, 1e-9, (10, 3))
    np.testing.assert_allclose(rotation_log(rotation_exp(tiny)), tiny, rtol=1e-12, atol=0)
    near_pi = rotation_exp(np.array([[0.0, 0.0, np.pi - 1e-9], [np.pi - 1e-7, 0.0, 0.0]]))
    np.testing.assert_allclose(rotation_exp(rotation_log(near_pi)), near_pi, atol=1e-14)
    q = quaternion_from_matrix(r)
    assert np.all(q[:, 3] >= 0)
    np.testing.assert_allclose(quaternion_to_matrix(q), r, atol=1e-13)
    np.testing.assert_allclose(
        euler_to_matrix(np.array([0.1, -0.2, 0.3]), "extrinsic_xyz"), rpy_to_matrix(np.array([0.1, -0.2, 0.3]))
    )


def test_chordal_mean_of_a_symmetric_spread_is_the_centre() -> None:
    rng = np.random.default_rng(1)
    centre = rotation_exp(np.array([0.3, -1.0, 2.0]))
    d = rng.normal(0.0, 0.05, (500, 3))
    samples = rotation_exp(np.concatenate((d, -d))) @ centre
    np.testing.assert_allclose(chordal_mean(samples), centre, atol=1e-14)
    # Not the mean of Euler angles: a spread across the +-pi yaw seam still averages right.
    seam = rotation_exp(np.array([[0.0, 0.0, np.pi - 0.01], [0.0, 0.0, -np.pi + 0.01]]))
    np.testing.assert_allclose(chordal_mean(seam), rotation_exp(np.array([0.0, 0.0, np.pi])), atol=1e-12)


@pytest.mark.parametrize(
    ("quat", "match"),
    [
        ([0.0, 0.0, 0.0, 2.0], "not a unit quaternion: norm 2"),
        ([np.nan, 0.0, 0.0, 1.0], "NaN or inf"),
        ([0.0, 0.0, 1.0], "4 components"),
    ],
)
def test_bad_quaternions_give_one_line_errors(quat: list[float], match: str) -> None:
    with pytest.raises(InputError, match=match):
        quaternion_to_matrix(np.array(quat), name="tracker orientation")


def test_rotation_helpers_match_scipy() -> None:
    """exp, log, quaternions and every Euler convention against scipy's Rotation (independent code),
    over uniform random rotations and angles within 1e-9 rad of 0 and of pi."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(7)
    axes = rng.normal(size=(4000, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate(
        (
            rng.uniform(0.0, np.pi, 1000),
            rng.uniform(0.0, 1e-9, 1000),
            np.pi - rng.uniform(1e-12, 1e-9, 1000),
            np.pi - rng.uniform(0.0, 0.2, 1000),
        )
    )
    v = np.concatenate((Rotation.random(1000, random_state=3).as_rotvec(), axes * angles[:, None]))
    reference = Rotation.from_rotvec(v)
    matrices = reference.as_matrix()
    np.testing.assert_allclose(rotation_exp(v), matrices, rtol=0, atol=5e-15)
    log = rotation_log(matrices)
    expected = reference.as_rotvec()
    # At pi, v and -v are the same rotation: compare to whichever sign scipy chose.
    flipped = np.linalg.norm(expected, axis=1) > np.pi - 1e-6
    sign = np.where(flipped & (np.sum(log * expected, axis=1) < 0), -1.0, 1.0)
    np.testing.assert_allclose(log, sign[:, None] * expected, rtol=0, atol=5e-15)
    assert np.all(np.linalg.norm(log, axis=1) <= np.pi + 1e-15)
    quat = quaternion_from_matrix(matrices)
    expected_q = reference.as_quat()
    expected_q *= np.where(expected_q[:, 3:] < 0, -1.0, 1.0)
    assert np.all(quat[:, 3] >= 0)
    # w = 0 exactly at pi leaves the sign free; elsewhere it is fixed by w >= 0.
    q_sign = np.where((expected_q[:, 3] < 1e-8) & (np.sum(quat * expected_q, axis=1) < 0), -1.0, 1.0)
    np.testing.assert_allclose(quat, q_sign[:, None] * expected_q, rtol=0, atol=5e-15)
    np.testing.assert_allclose(quaternion_to_matrix(reference.as_quat()), matrices, rtol=0, atol=5e-15)
    euler = rng.uniform(-np.pi, np.pi, (1000, 3))
    for convention, seq in (
        ("intrinsic_xyz", "XYZ"),
        ("extrinsic_xyz", "xyz"),
        ("intrinsic_zyx", "ZYX"),
        ("intrinsic_zyz", "ZYZ"),
    ):
        np.testing.assert_allclose(
            euler_to_matrix(euler, convention), Rotation.from_euler(seq, euler).as_matrix(), rtol=0, atol=5e-15
        )
    spread = Rotation.from_rotvec(rng.normal(0.0, 0.3, (50, 3))) * Rotation.from_rotvec([0.3, -1.0, 2.0])
    np.testing.assert_allclose(chordal_mean(spread.as_matrix()), spread.mean().as_matrix(), rtol=0, atol=1e-14)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: rotation_exp(np.zeros(2)), r"rotation vector must have shape \(\.\.\., 3\)"),
        (lambda: rotation_log(np.eye(2)), r"rotation must have shape \(\.\.\., 3, 3\)"),
        (lambda: euler_to_matrix(np.zeros(2), "intrinsic_xyz"), r"Euler angles must have shape"),
    ],
)
def test_rotation_helpers_reject_wrong_shapes(call, match: str) -> None:
    with pytest.raises(InputError, match=match):
        call()
