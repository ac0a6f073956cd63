"""Prismatic joints are in metres: joint-limit messages, --degrees, and the encoder noise.

The rail arm (test/data/urdf/rail_arm.urdf): rail (prismatic, -1.0..1.5 m), shoulder, elbow
(revolute), telescope (prismatic, 0..0.25 m), wrist_roll (continuous). A reading error of a
linear axis is a length (``EncoderNoise.linear_half_width``, m), not the revolute half-width
taken as metres (0.005 deg = 8.7e-5 "m")."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.cli import main
from robocal_uncertainty.core import EncoderNoise, TrackerNoise, check_joint_limits, identify
from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.kinematics import forward_points, forward_points_and_jacobian
from robocal_uncertainty.core.measurement import joint_columns
from robocal_uncertainty.core.urdf_model import load_urdf, robot_model_from_urdf
from robocal_uncertainty.errors import InputError
from robocal_uncertainty.uncertainty.model_adequacy import pose_noise_covariances
from robocal_uncertainty.uncertainty.sources import SOURCE_REGISTRY, TrialContext, UncertaintySettings

RAIL_ARM = Path(__file__).resolve().parents[1] / "data" / "urdf" / "rail_arm.urdf"
PRISMATIC = (True, False, False, True, False)


@pytest.fixture(scope="module")
def rail_arm():
    model = robot_model_from_urdf(load_urdf(RAIL_ARM), tool_point=(0.0, 0.0, 0.0))
    assert model.prismatic == PRISMATIC
    return model


def test_limit_messages_state_metres_for_a_prismatic_joint(rail_arm) -> None:
    with pytest.raises(InputError) as info:
        check_joint_limits(rail_arm, [2.0, 0.1, 0.1, 0.1, 0.0], what="pose")
    message = str(info.value)
    assert "prismatic joint rail = 2 m (2000 mm) is outside its limits [-1000, 1500] mm" in message
    assert "rad" not in message and "deg" not in message
    # A revolute joint keeps rad/deg; the degrees hint converts only the revolute readings.
    with pytest.raises(InputError) as info:
        check_joint_limits(rail_arm, [0.5, 100.0, 10.0, 0.1, 0.0], what="pose")
    assert "joint shoulder = 100 rad" in str(info.value) and str(info.value).endswith("given as radians")


def test_degrees_option_leaves_prismatic_values_in_metres(capsys: pytest.CaptureFixture[str]) -> None:
    args = ["fk", "--robot", str(RAIL_ARM), "--tool-point", "0", "0", "0"]
    assert main([*args, "--joints", "0.5", "10", "-20", "0.1", "30", "--degrees"]) == 0
    in_degrees = capsys.readouterr().out
    radians = [0.5, np.radians(10.0), np.radians(-20.0), 0.1, np.radians(30.0)]
    assert main([*args, "--joints", *(repr(float(v)) for v in radians)]) == 0
    assert capsys.readouterr().out == in_degrees  # 0.5 m and 0.1 m stayed metres


def test_encoder_noise_per_joint_type(rail_arm) -> None:
    noise = EncoderNoise(half_width=float(np.radians(0.005)), linear_half_width=2e-6)
    widths = noise.half_widths(rail_arm.prismatic)
    assert widths.tolist() == [2e-6, np.radians(0.005), np.radians(0.005), 2e-6, np.radians(0.005)]
    draws = noise.sample_joints(np.random.default_rng(0), (200_000, 5), rail_arm.prismatic)
    np.testing.assert_allclose(np.abs(draws).max(axis=0), widths, rtol=1e-4)
    np.testing.assert_allclose(draws.std(axis=0), widths / np.sqrt(3.0), rtol=0.01)
    # Without a prismatic joint: the same draws as before (the revolute path is unchanged).
    revolute = (False,) * 5
    a = noise.sample_joints(np.random.default_rng(1), (4, 5), revolute)
    assert np.array_equal(a, noise.sample(np.random.default_rng(1), (4, 5)))


def test_noise_covariance_and_monte_carlo_source_use_metres(rail_arm) -> None:
    rng = np.random.default_rng(2)
    lo, hi = rail_arm.joint_limits[:, 0] * 0.8, rail_arm.joint_limits[:, 1] * 0.8
    q = rng.uniform(lo, hi, size=(30, 5))
    q[:, 3] = rng.uniform(0.02, 0.23, size=30)
    p = rail_arm.parameter_vector()
    campaign = Campaign(
        joint_names=rail_arm.joint_names, joint_positions=q, points=forward_points(rail_arm, p, q), frame="base"
    )
    calibration = identify(rail_arm, campaign)
    noise = EncoderNoise(half_width=float(np.radians(0.005)), linear_half_width=2e-6)
    cov = pose_noise_covariances(calibration, q, TrackerNoise(a=0.0), noise, np.ones(30))
    _, jac = forward_points_and_jacobian(rail_arm, calibration.estimate, q)
    jq = jac[:, :, joint_columns(rail_arm.layout)]
    variances = np.array([2e-6, np.radians(0.005), np.radians(0.005), 2e-6, np.radians(0.005)]) ** 2 / 3.0
    expected = sum(variances[j] * jq[:, :, j, None] * jq[:, :, j][:, None, :] for j in range(5))
    np.testing.assert_allclose(cov, expected + 0.0, rtol=1e-12, atol=1e-24)
    # The Monte Carlo source: the test configuration's joint draws per joint type.
    settings = UncertaintySettings(encoder_noise=noise)
    ctx = TrialContext(
        n_poses=30,
        n_joints=5,
        n_test=1,
        measurement_dimension=3,
        distances=np.ones(30),
        model_errors=np.zeros((30, 3)),
        lambda_star=0.0,
        lambda_range=None,
        min_poses=10,
        subset_size=20,
        prismatic=rail_arm.prismatic,
    )
    source = SOURCE_REGISTRY["encoder"].build(settings, ctx)
    draws = source.draw(np.random.default_rng(3), 50_000)  # segments: 30 poses x 5 joints, then the test's 5
    assert draws.shape == (50_000, 30 * 5 + 5)
    test_joints = draws[:, 30 * 5 :]
    np.testing.assert_allclose(np.abs(test_joints).max(axis=0), noise.half_widths(rail_arm.prismatic), rtol=1e-3)
