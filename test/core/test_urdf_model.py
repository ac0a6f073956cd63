"""URDF chains to modified-DH models: forward kinematics against pinocchio's URDF loader, and
one-line errors for URDFs that are not a serial arm."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core.identification import identify
from robocal_uncertainty.core.kinematics import forward_points, forward_points_and_jacobian, forward_poses
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model, resolve_robot_config
from robocal_uncertainty.core.urdf_model import load_urdf, parse_urdf, robot_model_from_urdf, urdf_chain
from robocal_uncertainty.errors import ConfigError

pin = pytest.importorskip("pinocchio")

URDF_DIR = Path(__file__).resolve().parents[1] / "data" / "urdf"
POINT = np.array([0.013, -0.021, 0.034])


def pinocchio_tip(path: Path, base: str, tip: str, names: tuple[str, ...], q: np.ndarray) -> list[object]:
    """Base link <- tip link by pinocchio at each row of `q` (columns in the order of `names`)."""
    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    base_id, tip_id = model.getFrameId(base), model.getFrameId(tip)
    out = []
    for row in q:
        config = pin.neutral(model)
        for value, name in zip(row, names):
            joint = model.joints[model.getJointId(name)]
            if joint.nq == 2:  # continuous joint: cos, sin
                config[joint.idx_q : joint.idx_q + 2] = np.cos(value), np.sin(value)
            else:
                config[joint.idx_q] = value
        pin.framesForwardKinematics(model, data, config)
        out.append(data.oMf[base_id].inverse() * data.oMf[tip_id])
    return out


@pytest.mark.parametrize(
    ("urdf", "base", "tip", "prismatic"),
    [
        ("ur10.urdf", None, None, 0),
        ("ur10.urdf", "base_link_inertia", "tool0", 0),
        ("panda_arm.urdf", None, None, 0),
        ("rail_arm.urdf", None, None, 2),
        ("rail_arm.urdf", "carriage", "wrist", 1),
    ],
)
def test_forward_kinematics_equal_pinocchio(urdf: str, base: str | None, tip: str | None, prismatic: int) -> None:
    path = URDF_DIR / urdf
    robot = load_urdf(path)
    model = robot_model_from_urdf(robot, base, tip, tool_point=POINT).with_tool_rotation()
    chain = urdf_chain(robot, base, tip)
    assert sum(model.prismatic) == prismatic
    rng = np.random.default_rng(7)
    q = rng.uniform(model.joint_limits[:, 0], model.joint_limits[:, 1], size=(200, model.n_joints))
    points, rotations = forward_poses(model, model.parameter_vector(), q)
    ref = pinocchio_tip(path, chain.base_link, chain.tip_link, model.joint_names, q)
    ref_points = np.array([m.rotation @ POINT + m.translation for m in ref])
    angle = np.array([np.linalg.norm(pin.log3(m.rotation.T @ r)) for m, r in zip(ref, rotations)])
    # Measured: 6.7e-16 m and 1.3e-15 rad at most over these chains.
    assert np.abs(points - ref_points).max() < 1e-12
    assert angle.max() < 1e-12


def test_default_chain_ends() -> None:
    # ur10: base_link's branches (base, base_link_inertia) and wrist_3_link's (ft_frame, flange) hold no
    # movable joint beyond the arm: the chain stops at wrist_3_link. rail_arm: the camera branch is skipped.
    assert urdf_chain(load_urdf(URDF_DIR / "ur10.urdf")).tip_link == "wrist_3_link"
    rail = urdf_chain(load_urdf(URDF_DIR / "rail_arm.urdf"))
    assert (rail.base_link, rail.tip_link) == ("floor", "probe")
    assert [j.name for j in rail.movable] == ["rail", "shoulder", "elbow", "telescope", "wrist_roll"]


def test_joint_limits_and_parallel_axes() -> None:
    model = robot_model_from_urdf(load_urdf(URDF_DIR / "rail_arm.urdf"))
    np.testing.assert_array_equal(model.joint_limits[0], [-1.0, 1.5])  # prismatic rail [m]
    np.testing.assert_allclose(model.joint_limits[-1], [-2 * np.pi, 2 * np.pi])  # continuous
    # shoulder turns about y, elbow about -y (its origin turns about y): anti-parallel, a Hayati row.
    assert model.has_beta == (False, False, True, False, False)
    ur = robot_model_from_urdf(load_urdf(URDF_DIR / "ur10.urdf"))
    assert ur.has_beta == (False, False, True, True, False, False)  # axes 2-3-4 parallel: Hayati rows


def test_ur10_urdf_equals_shipped_dh_model() -> None:
    """The URDF built from the published DH values and the shipped DH YAML are the same robot."""
    urdf = robot_model_from_urdf(load_urdf(URDF_DIR / "ur10.urdf"), "base_link_inertia", "wrist_3_link")
    dh = load_robot_model(resolve_robot_config("ur10"))
    rng = np.random.default_rng(3)
    q = rng.uniform(-np.pi, np.pi, size=(100, 6))
    p_dh = dh.parameter_vector()
    p_dh[dh.layout.tool_index : dh.layout.tool_index + 3] = 0.0
    np.testing.assert_allclose(
        forward_points(urdf, urdf.parameter_vector(), q), forward_points(dh, p_dh, q), rtol=0, atol=1e-12
    )


def test_prismatic_jacobian_matches_finite_differences() -> None:
    model = robot_model_from_urdf(load_urdf(URDF_DIR / "rail_arm.urdf"), tool_point=POINT)
    p = model.parameter_vector()
    q = np.random.default_rng(1).uniform(model.joint_limits[:, 0], model.joint_limits[:, 1], size=(5, model.n_joints))
    _, jac = forward_points_and_jacobian(model, p, q)
    h = 1e-6
    for k in range(p.size):
        dp = np.zeros(p.size)
        dp[k] = h
        fd = (forward_points(model, p + dp, q) - forward_points(model, p - dp, q)) / (2 * h)
        np.testing.assert_allclose(jac[..., k], fd, rtol=0, atol=1e-8)


def perturbed_urdf(path: Path, rng: np.random.Generator, size: float) -> str:
    """The URDF with every joint origin (fixed ones too) moved by about `size` m / rad in all 6 values."""
    import xml.etree.ElementTree as ET

    root = ET.fromstring(path.read_text())
    for joint in root.findall("joint"):
        origin = joint.find("origin")
        if origin is None:
            origin = ET.SubElement(joint, "origin")
        for key in ("xyz", "rpy"):
            values = np.array([float(v) for v in origin.get(key, "0 0 0").split()]) + rng.normal(0.0, size, 3)
            origin.set(key, " ".join(repr(float(v)) for v in values))
    return ET.tostring(root, encoding="unicode")


@pytest.mark.parametrize("urdf", ["rail_arm.urdf", "panda_arm.urdf", "ur10.urdf"])
def test_every_origin_error_is_representable(urdf: str, tmp_path: Path) -> None:
    """Points in the base link, simulated by pinocchio on the URDF with every joint origin perturbed
    (1 mm / 1 mrad in all six values): identification from the nominal URDF fits them to round-off,
    so every identifiable origin error is representable by the model's parameters (mount included)."""
    from robocal_uncertainty.core.campaign import Campaign

    path = URDF_DIR / urdf
    model = robot_model_from_urdf(load_urdf(path), tool_point=POINT)
    chain = urdf_chain(load_urdf(path))
    rng = np.random.default_rng(11)
    truth = tmp_path / urdf
    truth.write_text(perturbed_urdf(path, rng, 1e-3))
    q = rng.uniform(model.joint_limits[:, 0], model.joint_limits[:, 1], size=(120, model.n_joints))
    frames = pinocchio_tip(truth, chain.base_link, chain.tip_link, model.joint_names, q)
    points = np.array([m.rotation @ POINT + m.translation for m in frames])
    campaign = Campaign(joint_names=model.joint_names, joint_positions=q, points=points, frame="base")
    result = identify(model, campaign, lambda_=0.0)
    assert result.rms_before > 1e-3
    # Measured: 4.2e-16 m at most; with the mount parameters left out, 1.4e-5 to 2.2e-3 m.
    assert result.rms_after < 1e-9
    # The first row alone cannot move the first axis sideways: the mount carries it.
    assert any(name.startswith("mount.") for name, kept in zip(result.parameter_names, result.estimated) if kept)


MINIMAL = """<robot name="r">
  <link name="a"/><link name="b"/><link name="c"/>
  <joint name="j1" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1"/></joint>
  <joint name="j2" type="revolute"><parent link="b"/><child link="c"/><origin xyz="0.3 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1"/></joint>
  {extra}
</robot>"""


@pytest.mark.parametrize(
    ("extra", "base", "tip", "match"),
    [
        (
            '<joint name="back" type="fixed"><parent link="c"/><child link="b"/></joint>',
            None,
            None,
            "link 'b' is the child of joints 'j1' and 'back': a kinematic loop",
        ),
        (
            '<link name="world"/><joint name="float" type="floating"><parent link="world"/><child link="a"/></joint>',
            None,
            None,
            "joint 'float' between 'world' and 'c' is floating: a floating base is not a serial arm; "
            "give --base-link a",
        ),
        (
            '<joint name="j3" type="fixed"><parent link="c"/><child link="gripper"/></joint>',
            None,
            None,
            "joint 'j3' names link 'gripper', which the URDF does not define",
        ),
        ("", "c", "b", "tip link 'b' is not downstream of base link 'c'"),
        ("", None, "hand", "--tip-link 'hand' is not a link of robot 'r'"),
        (
            '<link name="d"/><joint name="j3" type="revolute"><parent link="c"/><child link="d"/>'
            '<limit lower="-1" upper="1"/><mimic joint="j2"/></joint>',
            None,
            None,
            "joint 'j3' mimics joint 'j2': coupled joints are not supported",
        ),
        (
            '<link name="d"/><joint name="j3" type="revolute"><parent link="c"/><child link="d"/></joint>',
            None,
            None,
            "revolute joint 'j3' has no <limit lower=... upper=...>",
        ),
        ('<xacro:property name="x" value="1"/>', None, None, "is not valid XML"),
    ],
)
def test_careless_urdf_one_line_errors(extra: str, base: str | None, tip: str | None, match: str) -> None:
    with pytest.raises(ConfigError) as err:
        robot_model_from_urdf(parse_urdf(MINIMAL.format(extra=extra), where="arm.urdf"), base, tip)
    message = str(err.value)
    assert match in message
    assert "\n" not in message
    assert message.startswith("arm.urdf")


def test_cycle_without_two_parents_is_a_loop() -> None:
    text = """<robot name="r"><link name="a"/><link name="b"/>
      <joint name="ab" type="fixed"><parent link="a"/><child link="b"/></joint>
      <joint name="ba" type="fixed"><parent link="b"/><child link="a"/></joint></robot>"""
    with pytest.raises(ConfigError, match="closes a kinematic loop"):
        parse_urdf(text, where="loop.urdf")


def test_xacro_namespace_is_refused() -> None:
    text = (
        '<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">'
        '<link name="a"/><xacro:include filename="x"/></robot>'
    )
    with pytest.raises(ConfigError, match=r"expand it first \(xacro robot.urdf.xacro > robot.urdf\)"):
        parse_urdf(text, where="r.urdf.xacro")
