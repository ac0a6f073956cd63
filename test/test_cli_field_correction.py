"""``fk --field-correction``: the calibrated points plus the field's kriged mean, with its uncertainty.

A calibration of 80 real UR10 poses (series D) carries its model-error field and residuals; fk
with the option must move each point by exactly the kriged mean of that file's field and print
the kriging standard uncertainty, refuse a file without the field in one line, and the URDF
export must say that it cannot carry the correction.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.cli import main
from robocal_uncertainty.core import identify
from robocal_uncertainty.core.calibration_file import apply_calibration, read_calibration, write_calibration
from robocal_uncertainty.core.field_kriging import krige, kriging_basis
from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model, resolve_robot_config
from robocal_uncertainty.importers.tracker_csv import read_tracker_csv
from robocal_uncertainty.uncertainty.sessions.state import session_state

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def field_calibration(tmp_path_factory: pytest.TempPathFactory) -> Path:
    campaign = read_tracker_csv(ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv")
    campaign = campaign.subset(np.sort(np.random.default_rng(29).permutation(campaign.n_poses)[:80]))
    model = load_robot_model(resolve_robot_config("ur10"))
    cal = identify(model, campaign)
    state, _ = session_state(cal, campaign, TrackerNoise(), EncoderNoise())
    path = tmp_path_factory.mktemp("field") / "cal.json"
    write_calibration(path, cal, robot="ur10", session=state)
    return path


def _fk_json(path: Path, calibration: Path, joints: np.ndarray, *extra: str) -> dict[str, object]:
    args = ["fk", "--robot", "ur10", "--calibration", str(calibration), "--json", str(path), "--joints"]
    assert main([*args, *(f"{v:.9f}" for v in joints.ravel()), *extra]) == 0
    return dict(json.loads(path.read_text()))


def test_fk_field_correction_adds_the_kriged_mean_and_reports_its_uncertainty(
    field_calibration: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = read_calibration(field_calibration)
    q_t = np.asarray(data["model_error"]["field"]["joint_positions_rad"])
    joints = np.vstack((q_t[3] + 0.02, q_t[10] - 0.03, np.full(6, 2.8)))
    plain = _fk_json(tmp_path / "plain.json", field_calibration, joints)
    corrected = _fk_json(tmp_path / "field.json", field_calibration, joints, "--field-correction")
    out = capsys.readouterr().out
    model = apply_calibration(load_robot_model(resolve_robot_config("ur10")), data)
    kriged = krige(kriging_basis(data, model), model.layout, model.parameter_vector(), joints)
    moved = np.asarray(corrected["points_measurement_frame_m"]) - np.asarray(plain["points_measurement_frame_m"])
    np.testing.assert_allclose(moved, kriged.mean, atol=1e-12)
    assert np.all(np.linalg.norm(kriged.mean[:2], axis=1) > 10e-6)  # a real correction near the poses
    record = corrected["field_correction"]
    assert isinstance(record, dict)
    np.testing.assert_allclose(record["covariance_m2"], kriged.covariance, rtol=1e-12)
    # Printed: point, correction and standard uncertainty (mm), then the std ratio.
    rows = [line.split() for line in out.splitlines() if line and not line.startswith("#")]
    field_rows = np.array(rows[-3:], dtype=float)
    np.testing.assert_allclose(field_rows[:, 3:6], kriged.mean * 1e3, atol=1e-6)
    u = np.sqrt(np.diagonal(kriged.covariance, axis1=1, axis2=2)) * 1e3
    np.testing.assert_allclose(field_rows[:, 6:9], u, atol=1e-6)
    assert np.all(u > 0.0)
    # Near the poses the correction knows the error (ratio < 1); far away it knows less.
    assert field_rows[0, 9] < field_rows[2, 9]


def test_fk_field_correction_refuses_a_calibration_without_the_field(
    field_calibration: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = read_calibration(field_calibration)
    data["model_error"]["field"] = None
    stripped = tmp_path / "no_field.json"
    stripped.write_text(json.dumps(data), encoding="utf-8")
    code = main(
        ["fk", "--robot", "ur10", "--calibration", str(stripped), "--joints", *["0.1"] * 6, "--field-correction"]
    )
    err = capsys.readouterr().err.strip()
    assert code == 1
    assert len(err.splitlines()) == 1
    assert "error:" in err and "no model-error field" in err


def test_fk_field_correction_says_an_adequate_calibration_has_nothing_to_correct(
    field_calibration: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A calibration whose model passed the adequacy test estimates no field: the message must
    # say so, not advise a recalibration that would end the same way.
    data = read_calibration(field_calibration)
    data["model_error"].update(field=None, adequate=True, p_value=0.27)
    adequate = tmp_path / "adequate.json"
    adequate.write_text(json.dumps(data), encoding="utf-8")
    code = main(
        ["fk", "--robot", "ur10", "--calibration", str(adequate), "--joints", *["0.1"] * 6, "--field-correction"]
    )
    err = capsys.readouterr().err.strip()
    assert code == 1 and len(err.splitlines()) == 1
    assert "no significant model error (adequacy test p = 0.27)" in err and "recalibrate" not in err


def test_export_says_the_urdf_cannot_carry_the_field_correction(
    field_calibration: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "ur10.urdf"
    assert main(["export", str(field_calibration), "--format", "urdf", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "cannot carry the model-error field's correction" in text


def test_the_file_stores_the_folds_factors_and_fk_reads_them_back(
    field_calibration: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from robocal_uncertainty.core.field_cross_validation import cross_validated_factors

    data = read_calibration(field_calibration)
    record = data["model_error"]["field"]["cross_validation"]
    model = apply_calibration(load_robot_model(resolve_robot_config("ur10")), data)
    plain = kriging_basis(data, model, cross_validate=False)
    # The stored factors are the folds' own, recomputed here from the file's field.
    cross = cross_validated_factors(plain, model.layout, model.parameter_vector())
    np.testing.assert_allclose(record["factors_xyz"], cross.factors, rtol=1e-12)
    np.testing.assert_allclose(record["ratios"], cross.ratios, rtol=1e-12)
    assert record["n_poses"] == 80 and record["folds"] == 5
    assert kriging_basis(data, model).factors_source == "stored"
    # An older file without them: computed now, said so, the same numbers.
    del data["model_error"]["field"]["cross_validation"]
    older = tmp_path / "older.json"
    older.write_text(json.dumps(data))
    joints = np.full((1, 6), 0.5)
    stored = _fk_json(tmp_path / "a.json", field_calibration, joints, "--field-correction")
    capsys.readouterr()
    computed = _fk_json(tmp_path / "b.json", older, joints, "--field-correction")
    assert "stores no cross-validated kriging factors" in capsys.readouterr().out
    np.testing.assert_array_equal(
        computed["field_correction"]["covariance_m2"], stored["field_correction"]["covariance_m2"]
    )
    # An edited file (residuals changed after the factors were computed) is refused in one line.
    edited = read_calibration(field_calibration)
    edited["model_error"]["field"]["residuals_m"][0][0] += 1e-6
    path = tmp_path / "edited.json"
    path.write_text(json.dumps(edited))
    args = ["fk", "--robot", "ur10", "--calibration", str(path), "--field-correction", "--joints", *["0.5"] * 6]
    assert main(args) == 1
    err = capsys.readouterr().err.strip()
    assert "computed from other poses, residuals or field" in err and len(err.splitlines()) == 1
