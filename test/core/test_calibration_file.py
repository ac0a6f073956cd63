"""A calibration file applies only to the robot it was identified on."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import SimulationSettings, identify, load_robot_model, simulate_campaign
from robocal_uncertainty.core.calibration_file import apply_calibration, read_calibration, write_calibration
from robocal_uncertainty.errors import ConfigError

DATA = Path(__file__).resolve().parents[2] / "robocal_uncertainty" / "data"


@pytest.fixture(scope="module")
def paper_arm():
    return load_robot_model(DATA / "paper_arm.yaml")


@pytest.fixture(scope="module")
def calibration(paper_arm, tmp_path_factory: pytest.TempPathFactory) -> dict:
    campaign = simulate_campaign(paper_arm, SimulationSettings(), seed=5).campaign
    path = tmp_path_factory.mktemp("cal") / "cal.json"
    write_calibration(path, identify(paper_arm, campaign), robot="paper_arm")
    return read_calibration(path)


def _refused(model, data: dict) -> str:
    with pytest.raises(ConfigError) as excinfo:
        apply_calibration(model, data, where="calibration cal.json")
    msg = str(excinfo.value)
    assert "\n" not in msg
    return msg


def test_file_states_robot_and_joint_names(calibration) -> None:
    assert calibration["model_name"] == "paper_arm"
    assert calibration["joint_names"] == [f"joint{i}" for i in range(1, 7)]


def test_same_robot_gets_the_estimates(paper_arm, calibration) -> None:
    applied = apply_calibration(paper_arm, calibration)
    estimates = {e["name"]: e["estimate"] for e in calibration["parameters"]}
    np.testing.assert_array_equal(applied.parameter_vector(), [estimates[n] for n in paper_arm.layout.names])


def test_other_robot_is_refused_naming_both(calibration) -> None:
    ur10 = load_robot_model(DATA / "ur10.yaml")
    # Same parameter layout (6 joints, beta on rows 3 and 4): only the names tell them apart.
    assert ur10.layout.names == load_robot_model(DATA / "paper_arm.yaml").layout.names
    msg = _refused(ur10, calibration)
    assert msg == "calibration cal.json was identified on robot 'paper_arm' and cannot be applied to robot 'ur10'"


def test_missing_model_name_is_refused(paper_arm, calibration) -> None:
    data = copy.deepcopy(calibration)
    del data["model_name"]
    assert "has no 'model_name'" in _refused(paper_arm, data)


def test_other_joint_names_are_refused(paper_arm, calibration) -> None:
    data = copy.deepcopy(calibration)
    data["joint_names"][0] = "base_joint"
    msg = _refused(paper_arm, data)
    assert "'base_joint'" in msg and "'joint1'" in msg and "robot 'paper_arm'" in msg


def test_file_without_joint_names_is_still_read(paper_arm, calibration) -> None:
    data = copy.deepcopy(calibration)
    del data["joint_names"]  # files written before joint names were recorded
    apply_calibration(paper_arm, data)


def test_other_parameter_layout_is_refused(paper_arm, calibration) -> None:
    data = copy.deepcopy(calibration)
    data["parameters"] = [e for e in data["parameters"] if e["name"] != "joint3.beta"]
    msg = _refused(paper_arm, data)
    assert "lacks parameters joint3.beta" in msg and "robot model 'paper_arm'" in msg
    data = copy.deepcopy(calibration)
    data["parameters"].append({"name": "joint7.alpha", "estimate": 0.0})
    assert "parameter 'joint7.alpha' (robot 'paper_arm') does not exist" in _refused(paper_arm, data)
    data = copy.deepcopy(calibration)
    data["parameters"].append(dict(data["parameters"][0]))
    assert "given twice" in _refused(paper_arm, data)


def test_written_file_is_plain_json(tmp_path: Path, calibration) -> None:
    path = tmp_path / "again.json"
    path.write_text(json.dumps(calibration))
    assert read_calibration(path) == calibration
