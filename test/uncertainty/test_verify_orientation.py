"""Verifying a 6-DOF calibration: the tool orientations' error level beside the positions'.

References: a rotation noise of known standard deviation (the level must recover it, the
re-registration's kept equations taken off), a remounted probe (a tool rotation that only
``retool`` may absorb), and a check whose orientations are disturbed (drifted by orientations
alone, the positions still consistent).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.app.verification import calibrate_session, verify
from robocal_uncertainty.core import EncoderNoise, SimulationSettings, TrackerNoise, load_robot_model
from robocal_uncertainty.core.calibration_file import write_calibration
from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.measurement import POINT
from robocal_uncertainty.core.simulation import simulate_campaign
from robocal_uncertainty.errors import InputError
from robocal_uncertainty.report.verification_report import verification_lines, verification_to_dict
from robocal_uncertainty.uncertainty.sessions.orientation import orientation_level

UR10 = Path(__file__).resolve().parents[2] / "robocal_uncertainty" / "data" / "ur10.yaml"
SIGMA = 1e-3  # rotation noise [rad]


@pytest.fixture(scope="module")
def ur10_6dof():
    return load_robot_model(UR10).with_tool_rotation()


def _exact_campaign(model, n: int, seed: int, sigma: float, tool_turn: float = 0.0) -> Campaign:
    """Poses the model predicts exactly in a tracker frame, orientations turned by normal noise of `sigma`
    per axis (and the tool rotation turned by `tool_turn` about x: a remounted probe)."""
    sim = simulate_campaign(
        model, SimulationSettings(n_poses=n, frame="tracker", orientation_std=1e-4), seed=seed
    ).campaign
    layout = model.layout
    p = model.parameter_vector()
    b0 = layout.base_index
    p[b0 : b0 + 6] = (2.0, 0.5, 0.3, 0.01, -0.02, 2.8)
    p[layout.names.index("tool.rx")] += tool_turn
    meas = sim.measurement
    pred = meas.predict(layout, p, sim.joint_positions)
    errors = np.zeros((n, 6))
    errors[:, 3:] = np.random.default_rng(seed).normal(0.0, sigma, (n, 3))
    return dataclasses.replace(sim, points=meas.perturb(pred, errors))


def test_the_orientation_level_recovers_a_known_rotation_noise(ur10_6dof) -> None:
    campaign = _exact_campaign(ur10_6dof, 120, 5, SIGMA)
    level, kept, rms, z = orientation_level(ur10_6dof, campaign, retool=True)
    # 360 rotation equations, the 12 re-registered parameters take about half of 12 off them.
    assert 345.0 < kept < 358.0
    assert abs(level / SIGMA**2 - 1.0) < 4.0 * np.sqrt(2.0 / kept), level / SIGMA**2
    assert rms == pytest.approx(np.sqrt(3.0) * SIGMA, rel=0.15)
    assert z.shape == (360,) and abs(np.mean(z**2) - 1.0) < 0.05


def test_a_remounted_probe_turns_and_only_retool_absorbs_it(ur10_6dof) -> None:
    campaign = _exact_campaign(ur10_6dof, 60, 6, SIGMA, tool_turn=5e-3)
    level, kept, _, _ = orientation_level(ur10_6dof, campaign, retool=True)
    assert abs(level / SIGMA**2 - 1.0) < 4.0 * np.sqrt(2.0 / kept)
    fixed, _, _, _ = orientation_level(ur10_6dof, campaign, retool=False)
    assert fixed > 5.0 * SIGMA**2  # the 5 mrad turn stays in the residuals


def test_points_only_checks_are_refused_by_the_orientation_half(ur10_6dof) -> None:
    sim = simulate_campaign(ur10_6dof, SimulationSettings(n_poses=10), seed=1).campaign
    with pytest.raises(InputError, match="no orientations"):
        orientation_level(ur10_6dof, sim, retool=True)


def test_a_6dof_calibration_is_verified_on_positions_and_orientations(tmp_path: Path) -> None:
    """Calibrated on 30 simulated 6-DOF poses: the other 12 of the same robot are consistent; the same
    12 with their orientations turned by 3 mrad more noise are drifted by the orientations alone."""
    model = load_robot_model(UR10)
    sim = simulate_campaign(
        model, SimulationSettings(n_poses=42, frame="tracker", orientation_std=2e-4), seed=3
    ).campaign
    cal = calibrate_session(
        model.with_tool_rotation(),
        sim.subset(np.arange(30)),
        tracker_noise=TrackerNoise(),
        encoder_noise=EncoderNoise(),
    )
    assert cal.state is not None and cal.state.orientation_level is not None
    ref = cal.state.orientation_level
    assert ref.folds == 5 and ref.repeats == 4 and ref.poses == 30
    assert 0.5 < np.sqrt(ref.level) / 2e-4 < 1.6  # the simulated orientation noise, 0.2 mrad
    from robocal_uncertainty.cli.calibrate import session_lines

    assert any(
        line.startswith("6-DOF: verify also tests a 6-DOF check's orientations") for line in session_lines(cal.state)
    )
    path = tmp_path / "cal6.json"
    write_calibration(path, cal.result, robot=model.name, session=cal.state)
    assert json.loads(path.read_text())["session"]["orientation_level"]["level"] == pytest.approx(ref.level)
    check = sim.subset(np.arange(30, 42))
    good = verify(model, path, check, retool=True, null_trials=200).verification
    assert good.orientation is not None and good.significance == 0.025
    assert good.orientation.consistent and good.consistent, good.verdict
    turned = np.zeros((12, 6))
    turned[:, 3:] = np.random.default_rng(0).normal(0.0, 3e-3, (12, 3))
    bad_check = dataclasses.replace(check, points=check.measurement.perturb(check.points, turned))
    bad = verify(model, path, bad_check, retool=True, null_trials=200).verification
    assert bad.p_value == pytest.approx(good.p_value)  # the positions are the same
    assert not bad.consistent and not bad.orientation.consistent
    assert bad.verdict.startswith("drifted: the tool orientations deviate")
    assert bad.orientation.level_test.ratio > 5.0
    lines = verification_lines(bad)
    assert any(line.startswith("orientations against the statement's tolerance") for line in lines)
    data = verification_to_dict(bad, calibration=str(path), check_campaign="bad", robot=model.name, scope="session")
    assert data["orientation"]["consistent"] is False and data["orientation"]["tolerance"]["verdict"] == "drifted"
    # A points-only check of the same calibration: the positions alone, at the full significance.
    positions = np.asarray(check.measurement.positions(check.points))
    points = dataclasses.replace(check, points=positions, measurement=POINT, point_std=None)
    alone = verify(model, path, points, retool=True, null_trials=200).verification
    assert alone.orientation is None and alone.significance == 0.05
