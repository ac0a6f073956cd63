"""Simulated 6-DOF campaigns: identification recovers the true parameters, the tool orientation
included, within their stated uncertainties.

Truth: the shipped 6-DOF simulator (tracker position noise uniform +-5 um, orientation noise
normal 0.1 mrad per axis, encoder noise uniform +-0.005 deg, 1 mm / 0.1 deg parameter errors
and a tool rotation), with the errors of the parameters the campaign cannot identify put back
to nominal (their effect is absorbed by the identifiable ones, as the point tests do) and the
simulator's own noise re-applied to the adjusted truth.

Reference uncertainty, independent of the identification's ``linearized_std``: the first-order
covariance of the Tikhonov estimate written out here, ``H Sigma H^T`` with the calibration's
weights and lambda, and ``Sigma`` per pose ``s_q^2 J_q J_q^T + diag(instrument)``: the encoder
noise moves all six components of a pose together, which a single residual-scatter variance
cannot express.

Measured (6 campaigns per robot, default L-curve lambda ~0.007, whose shrinkage moves the
z-scores by < 0.01): RMS z over all identifiable parameters 1.00 (paper arm, 28 parameters)
and 0.96 (UR10 in tracker frame, 30 parameters), max |z| 2.56 / 3.21; tool rotation alone
RMS z 0.67 / 0.90. ``linearized_std`` against the reference, per campaign: 0.79-1.11 /
0.82-1.11 for the tool rotation, 0.53-1.67 over all parameters. Over 20 campaigns the ratio
averages 0.67-0.74 for the UR10's base orientation (roll, pitch, yaw: the stated std is ~30 %
too small there, z against it has RMS 1.66, 1.68, 1.29) and 1.42 for the paper arm's joint2.d.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult, identify
from robocal_uncertainty.core.kinematics import forward_poses
from robocal_uncertainty.core.observability import structural_observability
from robocal_uncertainty.core.pose_measurement import pose_values, split_pose_values
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.rotation import rotation_exp, rotation_log
from robocal_uncertainty.core.simulation import SimulationSettings, simulate_campaign

REPO = Path(__file__).resolve().parents[2]
N_CAMPAIGNS = 6
TOOL_ROTATION = ("tool.rx", "tool.ry", "tool.rz")


def identifiable_truth_campaign(
    model: RobotModel, settings: SimulationSettings, seed: int
) -> tuple[Campaign, np.ndarray, np.ndarray]:
    """A simulated 6-DOF campaign whose truth has errors on identifiable parameters only.

    Returns the campaign, the true parameter vector (tool-rotation layout) and the structurally
    identifiable mask. The simulator's noise (tracker position and orientation, encoders) is
    recovered from its output and applied unchanged to the adjusted truth.
    """
    sim = simulate_campaign(model, settings, seed=seed)
    measurement = sim.campaign.measurement
    layout = sim.true_model.layout
    truth = sim.true_model.parameter_vector()
    nominal = model.with_tool_rotation().parameter_vector()
    candidates = np.ones(layout.size, dtype=bool)
    if settings.frame == "base":
        candidates[layout.base_index :] = False
    identifiable = structural_observability(sim.true_model, nominal, candidates, measurement=measurement).identifiable
    q = sim.true_joint_positions
    p_meas, r_meas = split_pose_values(sim.campaign.points)
    p_sim, r_sim = forward_poses(layout, truth, q)
    fixed = candidates & ~identifiable
    truth[fixed] = nominal[fixed]
    p_true, r_true = forward_poses(layout, truth, q)
    noise_rot = rotation_log(r_meas @ np.swapaxes(r_sim, -1, -2))
    values = pose_values(p_true + (p_meas - p_sim), rotation_exp(noise_rot) @ r_true)
    return dataclasses.replace(sim.campaign, points=values), truth, identifiable


def reference_std(result: IdentificationResult, campaign: Campaign, settings: SimulationSettings) -> np.ndarray:
    """First-order std of every estimated parameter under the simulated noise (NaN elsewhere)."""
    layout = result.model.layout
    est = np.flatnonzero(result.estimated)
    n = campaign.n_poses
    meas = result.measurement
    _, jac = meas.predict_and_jacobian(layout, result.estimate, campaign.joint_positions)  # (n, 6, P)
    w = np.asarray(meas.weights, dtype=np.float64)
    scale = result.column_scale[est]
    a_mat = (jac * w[None, :, None]).reshape(6 * n, -1)[:, est] / scale
    reg = result.lambda_**2 * np.diag(result.penalized[est].astype(np.float64))
    h = np.linalg.solve(a_mat.T @ a_mat + reg, a_mat.T)
    theta = [idx["theta"] for idx in layout.joint_slices()]  # a joint offset moves as its reading
    var_q = settings.encoder_noise.half_width**2 / 3.0
    origin = np.zeros(3) if campaign.frame == "tracker" else np.asarray(settings.tracker_xyz)
    distance = np.linalg.norm(campaign.points[:, :3] - origin, axis=1)
    assert settings.orientation_std is not None
    sigma = np.zeros((6 * n, 6 * n))
    for i in range(n):
        jq = jac[i][:, theta]
        instrument = np.r_[
            np.full(3, settings.tracker_noise.std(distance[i]) ** 2), np.full(3, settings.orientation_std**2)
        ]
        block = var_q * jq @ jq.T + np.diag(instrument)
        sigma[6 * i : 6 * i + 6, 6 * i : 6 * i + 6] = w[:, None] * block * w[None, :]
    out = np.full(layout.size, np.nan)
    out[est] = np.sqrt(np.diag(h @ sigma @ h.T)) / scale
    return out


@pytest.mark.parametrize(("robot", "frame"), [("paper_arm", "base"), ("ur10", "tracker")])
def test_6dof_identification_recovers_the_truth_within_its_uncertainty(robot: str, frame: str) -> None:
    model = load_robot_model(REPO / "config" / f"{robot}.yaml")
    settings = SimulationSettings(frame=frame, orientation_std=1e-4)  # type: ignore[arg-type]
    z_ref, z_tool, ratio, nominal_z = [], [], [], []
    for seed in range(N_CAMPAIGNS):
        campaign, truth, identifiable = identifiable_truth_campaign(model, settings, seed)
        result = identify(model, campaign)
        assert result.converged
        np.testing.assert_array_equal(result.estimated, identifiable)
        names = result.parameter_names
        tool = [names.index(n) for n in TOOL_ROTATION]
        # The tool rotation is estimated (joint 6's offset is the one left out) and unpenalised.
        assert result.estimated[tool].all() and not result.penalized[tool].any()
        assert not result.estimated[names.index("joint6.theta")]
        est = result.estimated
        ref = reference_std(result, campaign, settings)
        z = (result.estimate - truth) / ref
        z_ref.append(z[est])
        z_tool.append(z[tool])
        ratio.append(result.linearized_std[est] / ref[est])
        # Not estimating would be far outside: the drawn tool rotation is many std from nominal.
        nominal_z.append(np.abs(result.nominal[tool] - truth[tool]) / ref[tool])
    z_all = np.concatenate(z_ref)
    rms = float(np.sqrt(np.mean(z_all**2)))
    rms_tool = float(np.sqrt(np.mean(np.concatenate(z_tool) ** 2)))
    ratios = np.array(ratio)
    est_index = [int(k) for k in np.flatnonzero(est)]
    tool_cols = [est_index.index(names.index(n)) for n in TOOL_ROTATION]
    print(
        f"{robot}: RMS z {rms:.2f}, max |z| {np.abs(z_all).max():.2f}, tool rotation RMS z {rms_tool:.2f}, "
        f"linearized/reference tool {ratios[:, tool_cols].min():.2f}-{ratios[:, tool_cols].max():.2f}, "
        f"all {ratios.min():.2f}-{ratios.max():.2f}"
    )
    # ~170 z-scores: the RMS of standard normal ones lies within +-0.1 of 1 (2 sigma).
    assert 0.8 < rms < 1.2
    assert np.abs(z_all).max() < 4.0
    # 18 tool-rotation z-scores: RMS within its 2.5-sigma band.
    assert 0.6 < rms_tool < 1.4
    assert np.median(np.concatenate(nominal_z)) > 10.0
    # The identification's own first-order std: right for the tool rotation; elsewhere within
    # the spread it is known to have (base orientation ~30 % small, see the module docstring).
    # (Per campaign, since it rests on that campaign's residual scatter.)
    assert np.all((ratios[:, tool_cols] > 0.7) & (ratios[:, tool_cols] < 1.3))
    assert np.all((ratios > 0.45) & (ratios < 2.2))
