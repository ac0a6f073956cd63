"""CLI: every position names its frame; validate proves the statement on held-out poses."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from robocal_uncertainty.cli import main

UR10_CSV = Path(__file__).resolve().parent / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv"
UR10_JOINTS = ["0.934319", "-1.79251", "1.5196", "0.272862", "0.934269", "-1.57075"]


@pytest.fixture(scope="module")
def ur10_campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if not UR10_CSV.exists():
        pytest.skip("UR10 data not present")
    out = tmp_path_factory.mktemp("ur10") / "ur10.mcap"
    assert main(["import-csv", str(UR10_CSV), "--out", str(out)]) == 0
    return out


def test_fk_defaults_to_the_measurement_frame_of_a_tracker_calibration(
    real_ur10_calibration: Any, capsys: pytest.CaptureFixture[str]
) -> None:
    cal = real_ur10_calibration.calibration
    assert main(["fk", "--robot", "ur10", "--calibration", str(cal), "--joints", *UR10_JOINTS]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "frame laser_tracker (measurement frame)" in lines[0]
    measured_first_pose_mm = np.array([2336.7643, -905.76441, -454.63664])  # row 1 of the CSV
    predicted = np.array([float(v) for v in lines[2].split()])
    assert np.linalg.norm(predicted - measured_first_pose_mm) < 1.0  # calibrated to ~0.4 mm RMS
    assert main(["fk", "--robot", "ur10", "--calibration", str(cal), "--joints", *UR10_JOINTS, "--frame", "base"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "(base frame)" in lines[0]
    base_point = np.array([float(v) for v in lines[2].split()])
    # The tracker stands about 2.5 m from the robot: the two frames differ by metres.
    assert np.linalg.norm(base_point - predicted) > 1000.0


def test_validate_on_ur10_writes_the_proof(ur10_campaign: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "val"
    args = ["validate", str(ur10_campaign), "--robot", "ur10", "--train-poses", "53", "--trials", "2000"]
    assert main([*args, "--out", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "579 held-out measurements" in text and "normalised RMS" in text
    data = json.loads((out / "validation.json").read_text())
    assert data["n_held_out"] == 579 and data["frame_id"] == "laser_tracker"
    assert [a["axis"] for a in data["axes"]] == ["x", "y", "z"]
    assert all(0.9 <= a["inside_fraction"] <= 1.0 for a in data["axes"])
    assert (out / "reliability.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "reliability.png" in (out / "validation.md").read_text()


def test_validate_refuses_conflicting_splits(ur10_campaign: Path, capsys) -> None:
    args = ["validate", str(ur10_campaign), "--robot", "ur10", "--train-poses", "53", "--k-folds", "3"]
    assert main(args) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "only one of" in err[0]


def test_evaluate_names_the_frame(tmp_path: Path, capsys) -> None:
    campaign = tmp_path / "t.mcap"
    assert main(["simulate", "--frame", "tracker", "--seed", "5", "--out", str(campaign)]) == 0
    joints = ["-7.5005", "-234.4840", "-106.7448", "-92.3875", "-61.5425", "20.7451"]
    common = ["evaluate", str(campaign), "--robot", "paper_arm", "--test-joints", *joints, "--degrees"]
    common += ["--trials", "500", "--no-budget", "--no-sweeps", "--no-progress"]
    assert main([*common, "--out", str(tmp_path / "r")]) == 0
    assert "Positions in frame laser_tracker (measurement frame" in capsys.readouterr().out
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    assert report["output_frame"]["frame_id"] == "laser_tracker"
    assert report["test_configurations"][0]["frame_id"] == "laser_tracker"
    base = {p["name"]: p for p in report["parameters"] if p["name"].startswith("base.")}
    assert len(base) == 6 and all(p["standard_uncertainty"] > 0 for p in base.values())
    assert main([*common, "--frame", "base", "--out", str(tmp_path / "b")]) == 0
    assert "Positions in frame base_link (base frame" in capsys.readouterr().out


def test_validate_refuses_the_base_frame(ur10_campaign: Path, capsys) -> None:
    assert main(["validate", str(ur10_campaign), "--robot", "ur10", "--frame", "base"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "measurement frame only" in err[0]
