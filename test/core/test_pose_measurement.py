"""6-DOF pose measurements: Jacobian against central differences, residual/perturb inverse,
identification of the tool rotation and base from simulated 6-DOF campaigns, point layout
unchanged."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core.identification import identify
from robocal_uncertainty.core.kinematics import forward_points, forward_points_and_jacobian, forward_poses
from robocal_uncertainty.core.pose_measurement import PoseMeasurement, pose_values, split_pose_values
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model
from robocal_uncertainty.core.robot_model import rpy_to_matrix
from robocal_uncertainty.core.rotation import rotation_log
from robocal_uncertainty.core.simulation import SimulationSettings, simulate_campaign
from robocal_uncertainty.errors import ConfigError

REPO = Path(__file__).resolve().parents[2]
UR10 = REPO / "config" / "ur10.yaml"
PAPER = REPO / "config" / "paper_arm.yaml"
MEAS = PoseMeasurement((1e-5, 2e-5, 3e-5), (1e-4, 2e-4, 3e-4))


@pytest.mark.parametrize("path", [UR10, PAPER])
def test_pose_jacobian_matches_central_differences(path: Path) -> None:
    model = dataclasses.replace(load_robot_model(path).with_tool_rotation(), tool_rpy=np.array([0.3, -0.2, 1.0]))
    rng = np.random.default_rng(1)
    p = model.parameter_vector() + rng.normal(0.0, 0.01, model.layout.size)
    q = rng.uniform(-3.0, 3.0, (5, model.n_joints))
    values, jac = MEAS.predict_and_jacobian(model.layout, p, q)
    h = 1e-7
    numeric = np.empty_like(jac)
    for k in range(p.size):
        dp = np.zeros(p.size)
        dp[k] = h
        plus = MEAS.residual(MEAS.predict(model.layout, p + dp, q), values)
        minus = MEAS.residual(MEAS.predict(model.layout, p - dp, q), values)
        numeric[..., k] = (plus - minus) / (2 * h)
    np.testing.assert_allclose(jac, numeric, atol=1e-7)
    # The tool rotation turns the frame but never moves the point.
    r0 = model.layout.tool_rotation_index
    assert r0 is not None
    assert np.all(jac[:, :3, r0 : r0 + 3] == 0.0)
    _, jac_points = forward_points_and_jacobian(model.layout, p, q)
    np.testing.assert_allclose(jac_points, jac[:, :3], atol=1e-12)


def test_tool_rotation_composes_on_the_flange() -> None:
    base = load_robot_model(UR10)
    rpy = np.array([0.1, 0.2, -0.3])
    model = dataclasses.replace(base.with_tool_rotation(), tool_rpy=rpy)
    q = np.random.default_rng(2).uniform(-3, 3, (4, 6))
    _, r_flange = forward_poses(base, base.parameter_vector(), q)
    points, r_tool = forward_poses(model, model.parameter_vector(), q)
    np.testing.assert_allclose(r_tool, r_flange @ rpy_to_matrix(rpy), atol=1e-14)
    np.testing.assert_array_equal(points, forward_points(base, base.parameter_vector(), q))
    assert model.with_parameters(model.parameter_vector()).tool_rpy.tolist() == rpy.tolist()


def test_residual_and_perturb_are_inverse() -> None:
    rng = np.random.default_rng(3)
    model = load_robot_model(UR10).with_tool_rotation()
    values = MEAS.predict(model.layout, model.parameter_vector(), rng.uniform(-3, 3, (7, 6)))
    errors = rng.normal(0.0, 1e-3, (7, 6))
    np.testing.assert_allclose(MEAS.residual(MEAS.perturb(values, errors), values), errors, atol=1e-15)
    pos, rot = split_pose_values(values)
    np.testing.assert_array_equal(pose_values(pos, rot), values)
    assert MEAS.dimension == 6
    assert MEAS.value_size == 12
    np.testing.assert_allclose(MEAS.weights, 1.0 / np.array([1e-5, 2e-5, 3e-5, 1e-4, 2e-4, 3e-4]))
    cov = MEAS.instrument_covariance(np.array([1e-5, 2e-5]))
    assert cov.shape == (2, 6, 6)
    assert np.all(cov[:, 3:, 3:] == 0.0)


def test_bad_std_is_one_line_error() -> None:
    with pytest.raises(ConfigError, match="rotation_std must be three positive"):
        PoseMeasurement((1e-5,) * 3, (0.0, 1e-4, 1e-4))


def test_point_layout_is_unchanged_without_tool_rotation() -> None:
    model = load_robot_model(UR10)
    assert "tool.rx" not in model.layout.names
    assert model.layout.base_index == model.layout.tool_index + 3
    names = model.with_tool_rotation().layout.names
    assert names[model.layout.tool_index + 3 : model.layout.tool_index + 6] == ("tool.rx", "tool.ry", "tool.rz")
    assert model.with_tool_rotation().layout.kinds[model.layout.tool_index + 3] == "angle"


def test_identify_recovers_tool_rotation_and_base_from_6dof_data() -> None:
    nominal = load_robot_model(UR10)
    settings = SimulationSettings(frame="tracker", orientation_std=1e-4)
    sim = simulate_campaign(nominal, settings, seed=3)
    assert sim.campaign.measurement.dimension == 6
    res = identify(nominal, sim.campaign)
    names = res.parameter_names
    assert "tool.rx" in names
    est = dict(zip(names, res.estimate, strict=True))
    std = dict(zip(names, res.linearized_std, strict=True))
    true = dict(zip(names, sim.true_model.parameter_vector(), strict=True))
    # rx, ry of the tool are identifiable on their own; rz only with joint 6's offset.
    assert res.estimated[names.index("tool.rx")]
    assert res.estimated[names.index("tool.ry")]
    for name in ("tool.rx", "tool.ry"):
        assert abs(est[name] - true[name]) < 4 * std[name], name
    assert "joint6.theta = 1 * tool.rz" in res.dependencies
    assert abs((est["tool.rz"] + est["joint6.theta"]) - (true["tool.rz"] + true["joint6.theta"])) < 4 * std["tool.rz"]
    # The calibrated model predicts the true tool pose (base included) at fresh configurations,
    # within what the encoder noise (+-0.005 deg, ~0.1 mm at the arm's reach) allows.
    q = np.random.default_rng(9).uniform(-2.5, 2.5, (50, 6))
    p_true, r_true = forward_poses(sim.true_model, sim.true_model.parameter_vector(), q)
    p_est, r_est = forward_poses(res.model, res.model.parameter_vector(), q)
    assert np.abs(p_est - p_true).max() < 2e-4
    assert np.linalg.norm(rotation_log(r_est @ np.swapaxes(r_true, -1, -2)), axis=-1).max() < 3e-4
    # Noise sqrt(3) * 0.1 mrad per pose plus the encoders.
    assert res.rotation_rms_after < 3e-4 < res.rotation_rms_before
    points_only = simulate_campaign(nominal, SimulationSettings(frame="tracker"), seed=3).campaign
    assert np.isnan(identify(nominal, points_only).rotation_rms_after)


def test_6dof_simulation_keeps_the_point_only_positions() -> None:
    nominal = load_robot_model(UR10)
    points = simulate_campaign(nominal, SimulationSettings(frame="tracker"), seed=5).campaign.points
    poses = simulate_campaign(nominal, SimulationSettings(frame="tracker", orientation_std=1e-4), seed=5).campaign
    assert poses.points.shape == (53, 12)
    np.testing.assert_array_equal(poses.points[:, :3], points)


def test_calibration_file_of_a_6dof_calibration_applies_the_tool_rotation(tmp_path: Path) -> None:
    from robocal_uncertainty.core.calibration_file import apply_calibration, read_calibration, write_calibration

    nominal = load_robot_model(UR10)
    sim = simulate_campaign(nominal, SimulationSettings(frame="tracker", orientation_std=1e-4), seed=3)
    res = identify(nominal, sim.campaign)
    write_calibration(tmp_path / "cal.json", res, robot="ur10")
    model = apply_calibration(nominal, read_calibration(tmp_path / "cal.json"))
    assert model.tool_rotation
    np.testing.assert_array_equal(model.parameter_vector(), res.estimate)


def test_weights_that_contradict_the_scatter_are_reported() -> None:
    """An orientation std far below the encoder-driven rotation scatter (1e-9 rad against ~1e-4 rad)
    makes rotations outweigh positions ~1e4x: with the stated weights identify must say so
    rather than stay silent; a consistent std gives no such warning."""
    model = load_robot_model(PAPER)
    for ostd, expected in ((1e-9, True), (1e-4, False)):
        sim = simulate_campaign(model, SimulationSettings(n_poses=20, orientation_std=ostd), seed=3)
        result = identify(model, sim.campaign, weighting="stated")
        assert any("do not match the residual scatter" in w for w in result.warnings) is expected, result.warnings


def test_variance_components_make_the_fit_immune_to_a_misstated_std() -> None:
    """Variance components estimate each component's scatter from the residuals: the same data
    with the orientation std stated 1e5 times too small give the same weights and estimates
    as with the right one; the stated weighting gives estimates many uncertainties away."""
    model = load_robot_model(PAPER)
    sim = simulate_campaign(model, SimulationSettings(n_poses=20, orientation_std=1e-4), seed=3)
    measurement = sim.campaign.measurement
    assert isinstance(measurement, PoseMeasurement)
    wrong = dataclasses.replace(sim.campaign, measurement=dataclasses.replace(measurement, rotation_std=(1e-9,) * 3))
    right, low = identify(model, sim.campaign), identify(model, wrong)
    assert low.weighting == right.weighting == "variance_components"
    assert not low.warnings and not right.warnings
    w_low, w_right = np.asarray(low.measurement.weight_std), np.asarray(right.measurement.weight_std)
    # The rotation scatter (~0.12 mrad: encoder noise and the 0.1 mrad orientation noise).
    assert np.all((w_right[3:] > 1e-4) & (w_right[3:] < 1.6e-4)), w_right
    np.testing.assert_allclose(w_low, w_right, rtol=0.03)
    est = right.estimated
    z_low = np.abs(low.estimate - right.estimate)[est] / right.linearized_std[est]
    assert z_low.max() < 0.05, z_low.max()
    stated = identify(model, wrong, weighting="stated")
    z_stated = np.abs(stated.estimate - right.estimate)[est] / right.linearized_std[est]
    assert z_stated.max() > 1.0, z_stated.max()


@pytest.mark.parametrize(
    "weight_std", [(1e-4,) * 5, (1e-4, 1e-4, 1e-4, 0.0, 1e-4, 1e-4), (1e-4, 1e-4, float("nan"), 1e-4, 1e-4, 1e-4)]
)
def test_weight_std_must_be_six_positive_values(weight_std: tuple[float, ...]) -> None:
    with pytest.raises(ConfigError, match="weight_std") as info:
        PoseMeasurement((1e-5,) * 3, (1e-4,) * 3, weight_std=weight_std)  # type: ignore[arg-type]
    assert "\n" not in str(info.value)


def test_weight_std_sets_the_weights() -> None:
    m = PoseMeasurement((1e-5,) * 3, (1e-4,) * 3, weight_std=(2e-4, 2e-4, 2e-4, 1e-3, 1e-3, 1e-3))
    np.testing.assert_array_equal(m.weights, [5e3, 5e3, 5e3, 1e3, 1e3, 1e3])
    np.testing.assert_array_equal(m.std, [1e-5, 1e-5, 1e-5, 1e-4, 1e-4, 1e-4])


def test_too_few_poses_for_variance_components_fall_back_to_the_stated_weights() -> None:
    """8 poses of the UR10 leave ~3 residual degrees of freedom per component: a variance from
    them would swing the weights (and once broke the convergence); the stated ones are used, and
    the warning says why. 20 poses are enough."""
    model = load_robot_model(Path(__file__).resolve().parents[2] / "config" / "ur10.yaml")
    small = simulate_campaign(model, SimulationSettings(n_poses=8, orientation_std=1e-4), seed=1)
    result = identify(model, small.campaign)
    assert result.converged
    assert result.weighting == "stated"
    assert result.measurement.weight_std is None
    [warning] = [w for w in result.warnings if "weighted by the stated uncertainties" in w]
    assert "8 poses leave" in warning and "need 10" in warning
    stated = identify(model, small.campaign, weighting="stated")
    np.testing.assert_array_equal(result.estimate, stated.estimate)
    larger = simulate_campaign(model, SimulationSettings(n_poses=20, orientation_std=1e-4), seed=1)
    assert identify(model, larger.campaign).weighting == "variance_components"
