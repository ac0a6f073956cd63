"""JSON report: required keys per configuration, numbers equal to the result, strict JSON."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from robocal_uncertainty.errors import InputError
from robocal_uncertainty.report import (
    REPORT_FORMAT_VERSION,
    read_report_json,
    uncertainty_to_dict,
    write_report_json,
)
from robocal_uncertainty.report.json_report import to_json_value
from robocal_uncertainty.uncertainty import SOURCE_DESCRIPTIONS

POSE_KEYS = {
    "joint_positions_rad",
    "mean_m",
    "standard_uncertainty_m",
    "covariance_m2",
    "expanded_uncertainty_m",
    "coverage_factor",
    "coverage_probability",
    "n_trials",
    "converged",
    "adaptive",
    "tolerance_reached_m",
    "axes",
    "gum",
    "region",
}
GUM_KEYS = {
    "applicable",
    "estimate_m",
    "standard_uncertainty_m",
    "expanded_uncertainty_m",
    "coverage_factor",
    "validated",
    "d_low_m",
    "d_high_m",
    "delta_m",
}
CAL_KEYS = {
    "parameters",
    "dependencies",
    "lambda",
    "lambda_method",
    "rms_before_m",
    "max_before_m",
    "rms_after_m",
    "max_after_m",
    "condition_number",
    "iterations",
    "converged",
    "n_poses",
    "warnings",
}


def _forbid_constants(name: str) -> None:
    raise AssertionError(f"non-strict JSON constant {name}")


@pytest.fixture(scope="module")
def roundtrip(setup, tmp_path_factory):
    path = tmp_path_factory.mktemp("json") / "report.json"
    write_report_json(
        path,
        setup.result,
        robot_name="paper_arm",
        campaign_source="simulated, seed 1",
        extra_settings={"cli": "--trials 1000"},
    )
    return path


def test_file_is_strict_json_and_reads_back(roundtrip):
    text = roundtrip.read_text(encoding="utf-8")
    strict = json.loads(text, parse_constant=_forbid_constants)
    data = read_report_json(roundtrip)
    assert data == strict
    assert data["format_version"] == REPORT_FORMAT_VERSION
    assert data["robot_name"] == "paper_arm"
    assert data["campaign_source"] == "simulated, seed 1"
    assert data["extra_settings"] == {"cli": "--trials 1000"}
    assert data["software"]["version"]
    assert "_m" in data["units"] and "_rad" in data["units"] and "_m2" in data["units"]


def test_required_keys_and_values_per_configuration(setup, roundtrip):
    data = read_report_json(roundtrip)
    result = setup.result
    assert len(data["test_configurations"]) == len(result.poses) == 1
    for entry, pose in zip(data["test_configurations"], result.poses):
        assert set(entry) >= POSE_KEYS
        assert set(entry["gum"]) >= GUM_KEYS
        np.testing.assert_array_equal(entry["joint_positions_rad"], pose.joint_positions)
        np.testing.assert_array_equal(entry["mean_m"], pose.mean)
        np.testing.assert_array_equal(entry["covariance_m2"], pose.covariance)
        assert entry["n_trials"] == result.n_trials == 1000
        assert entry["coverage_probability"] == 0.95
        assert entry["converged"] is True and entry["adaptive"] is False
        assert entry["tolerance_reached_m"] is None
        for ax_entry, ax, name in zip(entry["axes"], pose.axes, "xyz"):
            assert ax_entry["axis"] == name
            assert ax_entry["estimate_m"] == ax.estimate
            assert ax_entry["standard_uncertainty_m"] == ax.standard_uncertainty
            assert ax_entry["expanded_uncertainty_m"] == ax.expanded_uncertainty
            assert ax_entry["coverage_factor"] == ax.coverage_factor
            sym = ax_entry["intervals"]["probabilistically_symmetric"]
            short = ax_entry["intervals"]["shortest"]
            assert (sym["low_m"], sym["high_m"]) == (
                ax.probabilistically_symmetric.low,
                ax.probabilistically_symmetric.high,
            )
            assert (short["low_m"], short["high_m"]) == (
                ax.shortest.low,
                ax.shortest.high,
            )
            assert sym["kind"] == "probabilistically_symmetric"
            assert short["kind"] == "shortest"
            assert sym["coverage_probability"] == 0.95
            rel = ax_entry["relative_expanded_uncertainty_pct"]
            assert rel == pytest.approx(100 * ax.relative_expanded_uncertainty)
        assert entry["standard_uncertainty_m"] == [a.standard_uncertainty for a in pose.axes]
        assert entry["gum"]["validated"] == list(pose.gum.validated)
        np.testing.assert_array_equal(entry["gum"]["estimate_m"], pose.gum.estimate)
        np.testing.assert_array_equal(entry["gum"]["standard_uncertainty_m"], pose.gum.standard_uncertainty)
        np.testing.assert_array_equal(entry["gum"]["delta_m"], pose.gum.delta)
        assert entry["gum"]["coverage_factor"] == pytest.approx(1.959964, abs=1e-6)
        assert pose.region is not None
        assert entry["region"]["coverage_factor"] == pose.region.coverage_factor
        np.testing.assert_array_equal(entry["region"]["covariance_m2"], pose.region.covariance)


def test_calibration_sources_settings_and_parameters(setup, roundtrip):
    data = read_report_json(roundtrip)
    result = setup.result
    cal = result.calibration
    assert set(data["calibration"]) >= CAL_KEYS
    params = data["calibration"]["parameters"]
    assert [p["name"] for p in params] == list(cal.parameter_names)
    assert [p["estimated"] for p in params] == cal.estimated.tolist()
    for p, std in zip(params, cal.linearized_std):
        # NaN for parameters that were not estimated must be written as null.
        assert (p["linearized_std"] is None) == (not math.isfinite(std))
        assert p["unit"] in ("m", "rad")
    assert data["calibration"]["lambda"] == cal.lambda_
    assert data["calibration"]["dependencies"] == list(cal.dependencies)
    assert data["calibration"]["n_poses"] == 53
    assert [s["name"] for s in data["sources"]] == ["tracker", "encoder"]
    assert data["sources"][0]["description"] == SOURCE_DESCRIPTIONS["tracker"]
    settings = data["settings"]
    assert settings["tracker_noise_a_m"] == result.settings.tracker_noise.a
    assert settings["encoder_half_width_rad"] == result.settings.encoder_noise.half_width
    for key in (
        "lambda_range_used",
        "min_poses",
        "subset_size",
        "tracker_noise_b_m_per_m",
    ):
        assert key in settings
    mc = data["monte_carlo"]
    assert (mc["seed"], mc["block_size"], mc["n_trials"]) == (
        1,
        result.block_size,
        1000,
    )
    assert [p["name"] for p in data["parameters"]] == list(result.parameter_names)
    assert data["parameters"][0]["standard_uncertainty"] == (result.parameters[0].standard_uncertainty)
    assert isinstance(data["warnings"], list)


def test_dict_has_no_nan_anywhere(setup):
    data = uncertainty_to_dict(setup.result, robot_name="paper_arm")

    def walk(v):
        if isinstance(v, dict):
            for x in v.values():
                walk(x)
        elif isinstance(v, list):
            for x in v:
                walk(x)
        else:
            assert not (isinstance(v, float) and not math.isfinite(v))
            assert v is None or isinstance(v, (bool, int, float, str))

    walk(data)
    json.dumps(data, allow_nan=False)


def test_to_json_value_replaces_non_finite():
    assert to_json_value(np.array([1.0, np.nan, np.inf])) == [1.0, None, None]
    assert to_json_value({"a": (np.float32(2.5), np.int64(3), np.bool_(True))}) == {"a": [2.5, 3, True]}
    with pytest.raises(InputError):
        to_json_value(object())


def test_read_rejects_wrong_version_format_and_nan(roundtrip, tmp_path):
    data = json.loads(roundtrip.read_text(encoding="utf-8"))
    bad = tmp_path / "v99.json"
    bad.write_text(json.dumps({**data, "format_version": 99}), encoding="utf-8")
    with pytest.raises(InputError, match="format_version 99"):
        read_report_json(bad)
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"format": "something else"}), encoding="utf-8")
    with pytest.raises(InputError, match="not a"):
        read_report_json(other)
    nan = tmp_path / "nan.json"
    nan.write_text('{"format": NaN}', encoding="utf-8")
    with pytest.raises(InputError, match="NaN"):
        read_report_json(nan)
    with pytest.raises(InputError, match="cannot read"):
        read_report_json(tmp_path / "missing.json")
