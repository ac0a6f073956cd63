"""The field's correction (kriging) in ``evaluate`` and ``validate``: the same correction as ``fk``.

On 90 real UR10 poses (series D, a model-error field estimated): ``evaluate`` with the
correction must move every test position by the kriged mean that ``fk --field-correction``
adds from the calibration file of the same calibration, and state the covariance
``corrected_statement`` gives from the uncorrected Monte Carlo's; ``validate`` with the correction
must count the same Monte Carlo's held-out errors, moved by that mean, and give the uncorrected
RMS of the plain ``validate`` (same seed, same trials).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.app import evaluate, validate
from robocal_uncertainty.app.forward_kinematics import tool_points
from robocal_uncertainty.app.validation import validate_with_field_correction
from robocal_uncertainty.core import identify
from robocal_uncertainty.core.calibration_file import apply_calibration, calibration_to_dict
from robocal_uncertainty.core.field_kriging import krige, kriging_basis
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model, resolve_robot_config
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.importers.tracker_csv import read_tracker_csv
from robocal_uncertainty.uncertainty.calibration.settings import EvaluationSettings
from robocal_uncertainty.uncertainty.field_kriging import corrected_statement
from robocal_uncertainty.uncertainty.sessions.state import session_state
from robocal_uncertainty.uncertainty.sources import UncertaintySettings

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def ur10_90():
    campaign = read_tracker_csv(ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv")
    campaign = campaign.subset(np.sort(np.random.default_rng(29).permutation(campaign.n_poses)[:90]))
    return load_robot_model(resolve_robot_config("ur10")), campaign


def _options(joints: np.ndarray | None, trials: int = 300) -> EvaluationSettings:
    return EvaluationSettings(
        uncertainty=UncertaintySettings(), test_joints=joints, trials=trials, seed=3, budget=False, sweeps=False
    )


def test_evaluate_with_the_correction_is_fk_s_correction_at_the_same_configurations(ur10_90) -> None:
    model, campaign = ur10_90
    joints = np.vstack((campaign.joint_positions[5] + 0.03, campaign.joint_positions[40] - 0.02, np.full(6, 1.1)))
    plain = evaluate(model, campaign, _options(joints)).uncertainty
    corrected = evaluate(model, campaign, _options(joints), field_correction=True).uncertainty
    # fk's path: the calibration file of this calibration, read back as fk reads it.
    calibration = identify(model, campaign)
    state, _ = session_state(
        calibration, campaign, UncertaintySettings().tracker_noise, UncertaintySettings().encoder_noise
    )
    data = calibration_to_dict(calibration, robot="ur10", session=state)
    calibrated = apply_calibration(model, data)
    fk = tool_points(calibrated, joints, calibrated=True, field_correction=kriging_basis(data, calibrated))
    assert fk.correction is not None
    moved = np.stack([p.mean for p in corrected.poses]) - np.stack([p.mean for p in plain.poses])
    np.testing.assert_allclose(moved, fk.correction, atol=1e-12)
    assert np.all(np.linalg.norm(fk.correction[:2], axis=1) > 10e-6)  # a real correction near the poses
    # The stated covariance: the kriging covariance in place of the field's prior in the Monte Carlo's.
    kriged = krige(kriging_basis(data, calibrated), calibrated.layout, calibrated.parameter_vector(), joints)
    _, expected = corrected_statement(kriged, np.stack([p.covariance for p in plain.poses]))
    np.testing.assert_allclose(np.stack([p.covariance for p in corrected.poses]), expected, rtol=1e-9, atol=1e-18)
    for before, after, shift in zip(plain.poses, corrected.poses, fk.correction):
        np.testing.assert_allclose(after.gum.estimate - before.gum.estimate, shift, atol=1e-12)
        # Intervals recomputed from the mapped trials: centred on the moved mean.
        lo = np.array([a.probabilistically_symmetric.low for a in after.axes])
        hi = np.array([a.probabilistically_symmetric.high for a in after.axes])
        assert np.all((lo < after.mean) & (after.mean < hi))
    assert any("conditional mean" in w for w in corrected.warnings)


def test_evaluate_refuses_the_correction_where_the_model_explains_the_points(ur10_90) -> None:
    model, campaign = ur10_90
    # Points the nominal model explains up to the tracker's noise: no model error, no field.
    from robocal_uncertainty.core.kinematics import forward_points

    exact = forward_points(model.layout, model.parameter_vector(), campaign.joint_positions)
    noise = np.random.default_rng(5).uniform(-5e-6, 5e-6, exact.shape)
    simulated = dataclasses.replace(campaign, points=exact + noise)
    with pytest.raises(ConfigError, match=r"no significant model error .* nothing to correct"):
        evaluate(model, simulated, _options(np.full((1, 6), 0.5)), field_correction=True)


def test_validate_with_the_correction_moves_the_same_monte_carlo_by_the_kriged_mean(ur10_90) -> None:
    model, campaign = ur10_90
    options = _options(None, trials=200)
    plain = validate(model, campaign, options, train_poses=75)
    corrected, check = validate_with_field_correction(model, campaign, options, train_poses=75)
    # The uncorrected errors are the plain validation's (same split, trials and seed).
    np.testing.assert_allclose(check.uncorrected_rms, [a.rms_error for a in plain.axes], rtol=1e-10)
    np.testing.assert_allclose(check.corrected_rms, [a.rms_error for a in corrected.axes], rtol=1e-12)
    # The shift is the kriged mean of the training calibration's field at the held-out poses.
    held = np.setdiff1d(np.arange(campaign.n_poses), _train_indices(campaign.n_poses, 75, options.seed))
    train = campaign.subset(_train_indices(campaign.n_poses, 75, options.seed))
    cal = identify(model, train)
    state, _ = session_state(cal, train, UncertaintySettings().tracker_noise, UncertaintySettings().encoder_noise)
    data = calibration_to_dict(cal, robot="ur10", session=state)
    calibrated = apply_calibration(model, data)
    kriged = krige(
        kriging_basis(data, calibrated),
        calibrated.layout,
        calibrated.parameter_vector(),
        campaign.joint_positions[held],
    )
    np.testing.assert_allclose(plain.errors - corrected.errors, kriged.mean, atol=1e-12)
    assert np.isfinite(check.median_statement_ratio) and check.median_statement_ratio > 0.0


def _train_indices(n: int, n_train: int, seed: int) -> np.ndarray:
    from robocal_uncertainty.uncertainty.holdout import split_campaign

    return split_campaign(n, n_train=n_train, seed=seed)[0].train


def test_validate_prints_and_records_the_correction(ur10_90, tmp_path: Path, capsys) -> None:
    import json

    from robocal_uncertainty.bagio import write_campaign
    from robocal_uncertainty.cli import main

    _, campaign = ur10_90
    path = tmp_path / "ur10_90.mcap"
    write_campaign(path, campaign)
    common = ["--robot", "ur10", "--trials", "100", "--field-correction"]
    validate_args = ["validate", str(path), *common, "--train-poses", "75", "--out", str(tmp_path / "v")]
    assert main(validate_args) == 0
    out = capsys.readouterr().out
    check = json.loads((tmp_path / "v" / "validation.json").read_text())["extra_settings"]["field_correction"]
    line = next(row for row in out.splitlines() if row.startswith("field correction (kriging"))
    before, after = check["uncorrected_rms_3d_m"] * 1e3, check["corrected_rms_3d_m"] * 1e3
    assert f"{before:.3f} mm without, {after:.3f} mm with it" in line
    assert line in (tmp_path / "v" / "validation.md").read_text()
