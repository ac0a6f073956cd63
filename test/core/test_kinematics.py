"""Forward kinematics and Jacobian against independent references.

References used here never call the package's kinematics: plain 4x4 numpy products (modified
and standard DH), pinocchio's rigid-body chain, and central finite differences.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core.kinematics import (
    NearbyPoints,
    forward_points,
    forward_points_and_jacobian,
    forward_poses,
)
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model
from robocal_uncertainty.core.robot_model import RobotModel

REPO = Path(__file__).resolve().parents[2]
PAPER_YAML = REPO / "config" / "paper_arm.yaml"
UR10_YAML = REPO / "config" / "ur10.yaml"

# Seed paper, section 1: joint readings of the test pose [deg] and its flange position [mm].
PAPER_TEST_JOINTS_DEG = np.array([-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451])
SEED_POINT_MM = np.array([227.468, -98.454, 533.780])
SEED_POINT_EXACT_MM = np.array([227.46845944, -98.45429403, 533.77976111])
# Table 1 of the seed, rows (alpha_{i-1} [deg], a_{i-1} [mm], d_i [mm]), typed in here again.
SEED_TABLE1 = [
    (0.0, 0.0, 99.927),
    (90.0, 0.0, 106.950),
    (0.0, 428.052, 0.0),
    (0.0, 398.551, 0.0),
    (-90.0, 0.0, 93.160),
    (-90.0, 0.0, 81.910),
]


# --- independent homogeneous-matrix helpers --------------------------------------------


def rot_x(t: float) -> np.ndarray:
    c, s = np.cos(t), np.sin(t)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def rot_y(t: float) -> np.ndarray:
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def rot_z(t: float) -> np.ndarray:
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def trans(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    out = np.eye(4)
    out[:3, 3] = (x, y, z)
    return out


def base_matrix(xyz: np.ndarray, rpy: np.ndarray) -> np.ndarray:
    """world_T_base = Trans(xyz) Rz(yaw) Ry(pitch) Rx(roll) (URDF fixed-axis rpy)."""
    return trans(*xyz) @ rot_z(rpy[2]) @ rot_y(rpy[1]) @ rot_x(rpy[0])


def modified_dh_point(model: RobotModel, q: np.ndarray) -> np.ndarray:
    """Point from the documented chain, one 4x4 product per row (no package kinematics)."""
    t = base_matrix(model.base_xyz, model.base_rpy)
    for i in range(model.n_joints):
        beta = model.beta[i] if model.has_beta[i] else 0.0
        t = (
            t
            @ rot_x(model.alpha[i])
            @ trans(x=model.a[i])
            @ rot_y(beta)
            @ rot_z(q[i] + model.theta[i])
            @ trans(z=model.d[i])
        )
    return (t @ np.append(model.tool_point, 1.0))[:3]


def perturbed(model: RobotModel, rng: np.random.Generator, *, beta: bool) -> RobotModel:
    """Random geometry errors on every parameter, a far-away base and a tool point."""
    n = model.n_joints
    has_beta = model.has_beta if beta else (False,) * n
    return dataclasses.replace(
        model,
        alpha=model.alpha + rng.uniform(-0.02, 0.02, n),
        a=model.a + rng.uniform(-0.01, 0.01, n),
        theta=model.theta + rng.uniform(-0.02, 0.02, n),
        d=model.d + rng.uniform(-0.01, 0.01, n),
        beta=rng.uniform(-0.02, 0.02, n) if beta else np.zeros(n),
        has_beta=has_beta,
        tool_point=rng.uniform(-0.15, 0.15, 3),
        base_xyz=rng.uniform(-2.0, 2.0, 3),
        base_rpy=rng.uniform(-np.pi, np.pi, 3) * np.array([1.0, 0.45, 1.0]),
    )


# --- the robot paper's test pose --------------------------------------------------------


def test_seed_pose_independent_product_matches_paper() -> None:
    """The typed-in Table 1 as a plain product gives the seed's printed flange position."""
    q = np.radians(PAPER_TEST_JOINTS_DEG)
    t = np.eye(4)
    for (alpha, a, d), qi in zip(SEED_TABLE1, q):
        t = t @ rot_x(np.radians(alpha)) @ trans(x=a) @ rot_z(qi) @ trans(z=d)
    np.testing.assert_allclose(t[:3, 3], SEED_POINT_EXACT_MM, atol=5e-8)
    np.testing.assert_allclose(t[:3, 3], SEED_POINT_MM, atol=5e-4)


def test_seed_pose_forward_points_matches_paper_within_1um() -> None:
    model = load_robot_model(PAPER_YAML)
    q = np.radians(PAPER_TEST_JOINTS_DEG)[None, :]
    point_mm = forward_points(model, model.parameter_vector(), q)[0] * 1e3
    # Paper's printed value (3 decimals): within 1 um.
    assert np.max(np.abs(point_mm - SEED_POINT_MM)) < 1e-3
    # Exact product: the loader's unit conversion and the chain are both exact to round-off.
    np.testing.assert_allclose(point_mm, SEED_POINT_EXACT_MM, atol=1e-8)


def test_forward_points_matches_plain_matrix_product_with_beta_and_base() -> None:
    rng = np.random.default_rng(11)
    for path in (PAPER_YAML, UR10_YAML):
        model = perturbed(load_robot_model(path), rng, beta=True)
        q = rng.uniform(-np.pi, np.pi, (20, model.n_joints))
        got = forward_points(model, model.parameter_vector(), q)
        want = np.array([modified_dh_point(model, qi) for qi in q])
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


@pytest.mark.parametrize("spread", [1e-5, 2e-3, 0.1, 1.0], ids=["urad", "mrad", "0.1rad", "direct"])
def test_nearby_points_match_plain_matrix_product(spread: float) -> None:
    # Near the reference the angles come from a Taylor series about it; far from it (1 rad,
    # past the series' range) directly. Either way: the independent 4x4 product.
    rng = np.random.default_rng(12)
    for path in (PAPER_YAML, UR10_YAML):
        ref = perturbed(load_robot_model(path), rng, beta=True)
        q_ref = rng.uniform(-np.pi, np.pi, (15, ref.n_joints))
        near = NearbyPoints.at(ref.layout, ref.parameter_vector(), q_ref)
        params = ref.parameter_vector() + rng.uniform(-spread, spread, (4, ref.layout.size)) * 0.01
        theta = [idx["theta"] for idx in ref.layout.joint_slices()]
        params[:, theta] = ref.parameter_vector()[theta] + rng.uniform(-spread, spread, (4, len(theta)))
        q = q_ref + rng.uniform(-spread, spread, (4, *q_ref.shape))
        got = near(params, q)
        assert got.shape == (4, 15, 3)
        for t in range(4):
            model = ref.with_parameters(params[t])
            want = np.array([modified_dh_point(model, qi) for qi in q[t]])
            np.testing.assert_allclose(got[t], want, rtol=0, atol=1e-12)
        # And the package's own chain to a few ulps (it walks the frames the other way).
        np.testing.assert_allclose(got, forward_points(ref.layout, params, q), rtol=0, atol=5e-15)
        # Shared readings (no leading axis) broadcast like forward_points.
        np.testing.assert_allclose(near(params, q_ref), forward_points(ref.layout, params, q_ref), rtol=0, atol=5e-15)


def test_nearby_points_do_not_depend_on_the_batching() -> None:
    # The walk runs elementwise into preallocated arrays, with the reference cosines repeated
    # per trial up to a size and broadcast beyond: any split of the trials gives the same bits.
    rng = np.random.default_rng(14)
    ref = perturbed(load_robot_model(PAPER_YAML), rng, beta=True)
    q_ref = rng.uniform(-np.pi, np.pi, (53, ref.n_joints))
    near = NearbyPoints.at(ref.layout, ref.parameter_vector(), q_ref)
    params = ref.parameter_vector() + rng.uniform(-1e-5, 1e-5, (1500, ref.layout.size))
    q = q_ref + rng.uniform(-1e-4, 1e-4, (1500, *q_ref.shape))
    whole = near.poses(params, q)  # 1500 x 53 trial-poses: broadcast rows
    parts = [near.poses(params[i : i + 256], q[i : i + 256]) for i in range(0, 1500, 256)]  # repeated rows
    assert np.array_equal(whole, np.concatenate(parts))
    assert np.array_equal(near(params[:7], q[:7]), whole[:7, :, :3])


@pytest.mark.parametrize("spread", [1e-5, 0.1, 1.0], ids=["urad", "0.1rad", "direct"])
@pytest.mark.parametrize("tool_rotation", [False, True], ids=["flange", "tool_rotation"])
def test_nearby_poses_match_forward_poses(spread: float, tool_rotation: bool) -> None:
    # forward_poses is checked against independent references in test_orientation_kinematics.
    rng = np.random.default_rng(13)
    ref = perturbed(load_robot_model(PAPER_YAML), rng, beta=True)
    if tool_rotation:
        ref = ref.with_tool_rotation()
    layout = ref.layout
    p0 = ref.parameter_vector()
    if layout.tool_rotation_index is not None:
        p0[layout.tool_rotation_index : layout.tool_rotation_index + 3] = rng.uniform(-0.5, 0.5, 3)
    q_ref = rng.uniform(-np.pi, np.pi, (9, ref.n_joints))
    near = NearbyPoints.at(layout, p0, q_ref)
    params = p0 + rng.uniform(-spread, spread, (3, layout.size)) * 0.1
    q = q_ref + rng.uniform(-spread, spread, (3, *q_ref.shape))
    got = near.poses(params, q)
    points, rotations = forward_poses(layout, params, q)
    assert got.shape == (3, 9, 12)
    np.testing.assert_allclose(got[..., :3], points, rtol=0, atol=5e-15)
    np.testing.assert_allclose(got[..., 3:].reshape(3, 9, 3, 3), rotations, rtol=0, atol=5e-15)
    # The point part is the point walk's, bit for bit.
    assert np.array_equal(got[..., :3], near(params, q))


# --- pinocchio ---------------------------------------------------------------------------


def pinocchio_points(pin, model: RobotModel, q: np.ndarray) -> np.ndarray:
    """Measured points from a pinocchio chain built from the rows of `model`."""

    def se3(t: np.ndarray):
        return pin.SE3(np.ascontiguousarray(t[:3, :3]), np.ascontiguousarray(t[:3, 3]))

    pmodel = pin.Model()
    parent = 0
    for i in range(model.n_joints):
        beta = model.beta[i] if model.has_beta[i] else 0.0
        before = base_matrix(model.base_xyz, model.base_rpy) if i == 0 else trans(z=model.d[i - 1])
        placement = before @ rot_x(model.alpha[i]) @ trans(x=model.a[i]) @ rot_y(beta) @ rot_z(model.theta[i])
        parent = pmodel.addJoint(parent, pin.JointModelRZ(), se3(placement), f"j{i + 1}")
    final = se3(trans(z=model.d[-1]) @ trans(*model.tool_point))
    data = pmodel.createData()
    out = np.empty((q.shape[0], 3))
    for k, qk in enumerate(q):
        pin.forwardKinematics(pmodel, data, np.ascontiguousarray(qk))
        out[k] = (data.oMi[parent] * final).translation
    return out


@pytest.mark.parametrize("path", [PAPER_YAML, UR10_YAML], ids=["paper_arm", "ur10"])
@pytest.mark.parametrize("beta", [True, False], ids=["beta", "no_beta"])
def test_forward_points_match_pinocchio(path: Path, beta: bool, record_property) -> None:
    pin = pytest.importorskip(
        "pinocchio", reason="the pinocchio extra is not installed (its wheels need numpy >= 1.26)"
    )
    rng = np.random.default_rng(2024 + 7 * beta + len(path.name))
    nominal = load_robot_model(path)
    worst = 0.0
    for _ in range(4):
        model = perturbed(nominal, rng, beta=beta)
        assert sum(model.has_beta) == (2 if beta else 0)
        if beta:
            assert np.all(np.abs(model.beta[list(model.has_beta)]) > 0)
        q = rng.uniform(nominal.joint_limits[:, 0], nominal.joint_limits[:, 1], (30, model.n_joints))
        got = forward_points(model, model.parameter_vector(), q)
        want = pinocchio_points(pin, model, q)
        worst = max(worst, float(np.max(np.linalg.norm(got - want, axis=1))))
        # The chain must actually reach out: a base of metres and a non-trivial tool.
        assert np.min(np.linalg.norm(want, axis=1)) > 0.0
    record_property("pinocchio_max_error_m", worst)
    print(f"pinocchio max |FK difference| {path.stem} beta={beta}: {worst:.3e} m")
    assert worst < 1e-9


# --- standard DH conversion ------------------------------------------------------------


def test_ur10_standard_dh_conversion_is_exact() -> None:
    import yaml

    raw = yaml.safe_load(UR10_YAML.read_text(encoding="utf-8"))
    assert raw["convention"] == "standard_dh"
    assert raw["units"] == {"length": "m", "angle": "rad"}
    rows = [(float(j["alpha"]), float(j["a"]), float(j["d"]), float(j.get("theta", 0.0))) for j in raw["joints"]]
    tool = np.array(raw["tool_point"], dtype=float)
    model = load_robot_model(UR10_YAML)
    # The UR10 nominal geometry is public: a2 = -0.612, a3 = -0.5723, d1 = 0.1273.
    assert [r[1] for r in rows[1:3]] == [-0.612, -0.5723]
    rng = np.random.default_rng(5)
    q = rng.uniform(-np.pi, np.pi, (200, 6))
    q[0] = 0.0
    want = np.empty((q.shape[0], 3))
    for k, qk in enumerate(q):
        t = np.eye(4)
        for (alpha, a, d, theta), qi in zip(rows, qk):
            t = t @ rot_z(qi + theta) @ trans(z=d) @ trans(x=a) @ rot_x(alpha)
        want[k] = (t @ np.append(tool, 1.0))[:3]
    got = forward_points(model, model.parameter_vector(), q)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    # Zero pose of a UR10 (standard DH): arm stretched along -x, tool along -y.
    np.testing.assert_allclose(
        got[0],
        [-0.612 - 0.5723, -0.163941 - 0.0922 - 0.109, 0.1273 - 0.1157],
        atol=1e-12,
    )


# --- analytic Jacobian ------------------------------------------------------------------


@pytest.mark.parametrize("path", [PAPER_YAML, UR10_YAML], ids=["paper_arm", "ur10"])
def test_jacobian_matches_central_differences(path: Path, record_property) -> None:
    rng = np.random.default_rng(77)
    model = perturbed(load_robot_model(path), rng, beta=True)
    p = model.parameter_vector()
    names = model.layout.names
    assert p.shape == (model.layout.size,) == (len(names),)
    q = rng.uniform(model.joint_limits[:, 0], model.joint_limits[:, 1], (25, model.n_joints))
    points, jac = forward_points_and_jacobian(model, p, q)
    assert points.shape == (25, 3)
    assert jac.shape == (25, 3, p.size)
    np.testing.assert_allclose(points, forward_points(model, p, q), rtol=0, atol=1e-15)
    h = 1e-6
    worst = 0.0
    for k in range(p.size):
        dp = np.zeros(p.size)
        dp[k] = h
        fd = (forward_points(model, p + dp, q) - forward_points(model, p - dp, q)) / (2 * h)
        scale = float(np.max(np.abs(fd)))
        assert scale > 1e-3, f"{names[k]} does not move the point at all"
        rel = float(np.max(np.abs(jac[..., k] - fd))) / scale
        worst = max(worst, rel)
        assert rel < 1e-6, f"{names[k]}: relative Jacobian error {rel:.3e}"
    record_property("jacobian_max_relative_error", worst)
    print(f"Jacobian max relative error {path.stem}: {worst:.3e}")


@pytest.mark.parametrize("path", [PAPER_YAML, UR10_YAML], ids=["paper_arm", "ur10"])
def test_batched_shapes_equal_per_trial_calls(path: Path) -> None:
    rng = np.random.default_rng(3)
    nominal = load_robot_model(path)
    n_trials, n_poses = 4, 7
    params = np.stack([perturbed(nominal, rng, beta=True).parameter_vector() for _ in range(n_trials)])
    n_params = nominal.layout.size
    assert params.shape == (n_trials, n_params)
    q = rng.uniform(-np.pi, np.pi, (n_poses, 6))

    points = forward_points(nominal, params, q)
    points2, jac = forward_points_and_jacobian(nominal.layout, params, q)
    assert points.shape == (n_trials, n_poses, 3)
    assert points2.shape == (n_trials, n_poses, 3)
    assert jac.shape == (n_trials, n_poses, 3, n_params)
    for t in range(n_trials):
        pt, jt = forward_points_and_jacobian(nominal, params[t], q)
        np.testing.assert_array_equal(points[t], forward_points(nominal, params[t], q))
        np.testing.assert_allclose(points2[t], pt, rtol=0, atol=1e-15)
        np.testing.assert_allclose(jac[t], jt, rtol=0, atol=1e-14)

    # Per-trial joints (T, N, 6) broadcast against (T, n_params) the same way.
    q_trials = rng.uniform(-np.pi, np.pi, (n_trials, n_poses, 6))
    points3, jac3 = forward_points_and_jacobian(nominal, params, q_trials)
    assert points3.shape == (n_trials, n_poses, 3)
    assert jac3.shape == (n_trials, n_poses, 3, n_params)
    for t in range(n_trials):
        pt, jt = forward_points_and_jacobian(nominal, params[t], q_trials[t])
        np.testing.assert_allclose(points3[t], pt, rtol=0, atol=1e-15)
        np.testing.assert_allclose(jac3[t], jt, rtol=0, atol=1e-14)


def test_shape_errors_are_reported() -> None:
    model = load_robot_model(PAPER_YAML)
    p = model.parameter_vector()
    with pytest.raises(ValueError, match=r"params must have shape \(\.\.\., 35\)"):
        forward_points(model, p[:-1], np.zeros((2, 6)))
    with pytest.raises(ValueError, match=r"joint_positions must have shape \(\.\.\., n_poses, 6\)"):
        forward_points(model, p, np.zeros(6))
    with pytest.raises(ValueError, match=r"joint_positions must have shape"):
        forward_points_and_jacobian(model, p, np.zeros((3, 5)))
