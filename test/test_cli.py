"""The command line gives the API's numbers for the same seed, and one-line errors."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from robocal_uncertainty.bagio import read_campaign
from robocal_uncertainty.cli import PAPER_TEST_JOINTS_DEG, main
from robocal_uncertainty.core import identify, load_robot_model
from robocal_uncertainty.uncertainty import UncertaintySettings, evaluate_uncertainty

JOINTS = [str(v) for v in PAPER_TEST_JOINTS_DEG]
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def campaign_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("cli") / "campaign.mcap"
    assert main(["simulate", "--robot", "paper_arm", "--out", str(path), "--seed", "7"]) == 0
    return path


def test_fk_prints_the_seed_test_pose(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["fk", "--robot", "paper_arm", "--joints", *JOINTS, "--degrees"]) == 0
    row = capsys.readouterr().out.strip().splitlines()[-1].split()
    # Independent value: the seed's Table 1 chain evaluated by hand, 227.468/-98.454/533.780 mm.
    np.testing.assert_allclose([float(v) for v in row], [227.468459, -98.454294, 533.779761], atol=1e-6)


def test_evaluate_report_equals_api(campaign_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "report"
    argv = [
        "evaluate",
        str(campaign_file),
        "--robot",
        "paper_arm",
        "--test-joints",
        *JOINTS,
        "--degrees",
        "--trials",
        "600",
        "--seed",
        "3",
        "--out",
        str(out),
        "--no-budget",
        "--no-progress",
        "--sources",
        "tracker,encoder,pose_choice",
        "--backend",
        "numpy",  # the library's default, which the API call below uses: compared to the bit
    ]
    assert main(argv) == 0
    report = json.loads((out / "report.json").read_text())
    model = load_robot_model(ROOT / "config" / "paper_arm.yaml")
    campaign = read_campaign(campaign_file)
    api = evaluate_uncertainty(
        model,
        campaign,
        np.radians(PAPER_TEST_JOINTS_DEG),
        uncertainty=UncertaintySettings(sources=("tracker", "encoder", "pose_choice")),
        calibration=identify(model, campaign),
        trials=600,
        seed=3,
    )
    text = json.dumps(report)
    for value in api.poses[0].mean:
        assert repr(float(value)) in text
    for axis in api.poses[0].axes:
        assert repr(float(axis.standard_uncertainty)) in text
        assert repr(float(axis.shortest.low)) in text


def test_demo_prints_table2_and_writes_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "demo"
    assert main(["demo", "--trials", "400", "--budget-trials", "200", "--out", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    for row in (
        "Output value / mm",
        "Standard uncertainty / mm",
        "Expanded uncertainty / mm",
        "Coverage interval / mm",
        "Relative expanded uncertainty / %",
        "Uncertainty budget",
    ):
        assert row in text
    for name in ("report.json", "report.md", "report.html"):
        assert (out / name).stat().st_size > 0


def test_import_csv_and_calibrate_real_ur10(real_ur10_calibration: Any) -> None:
    assert "632 poses" in real_ur10_calibration.printed
    cal = json.loads(real_ur10_calibration.calibration.read_text())
    # Real robot: residual RMS after calibration is a few tenths of a millimetre.
    assert 1e-4 < cal["residual_rms_after_m"] < 6e-4 < cal["residual_rms_before_m"]


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (["--trials", "0"], "--trials must be a positive integer"),
        (["--coverage", "1.5"], r"--coverage is a probability in \(0, 1\), got 1.5$"),
        (["--sources", "tracker,thermal"], "unknown uncertainty source"),
        (["--sources", "lambda", "--lambda-range", "5", "9"], "excludes the calibration's optimum"),
    ],
)
def test_bad_settings_end_in_one_line(
    campaign_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], match: str
) -> None:
    argv = [
        "evaluate",
        str(campaign_file),
        "--robot",
        "paper_arm",
        "--test-joints",
        *JOINTS,
        "--degrees",
        "--out",
        str(tmp_path),
        "--no-progress",
        "--no-budget",
        *extra,
    ]
    if "--trials" not in extra:
        argv += ["--trials", "100"]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert pytest.importorskip("re").search(match, err)


def test_wrong_test_joint_count_and_missing_file(campaign_file: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["evaluate", str(campaign_file), "--robot", "paper_arm", "--test-joints", "1", "2", "3"]) == 1
    assert "must have 6 values per configuration" in capsys.readouterr().err
    assert main(["calibrate", "no_such_campaign.mcap", "--robot", "paper_arm"]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no_such_campaign.mcap" in err


def test_bad_calibration_file_and_trial_options(
    campaign_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A binary file given as calibration JSON (here the campaign MCAP itself).
    assert main(["fk", "--robot", "paper_arm", "--joints", *JOINTS, "--calibration", str(campaign_file)]) == 1
    assert "is not UTF-8 JSON text" in capsys.readouterr().err
    broken = tmp_path / "cal.json"
    broken.write_text(
        json.dumps(
            {
                "format": "robocal_uncertainty/calibration/1",
                "model_name": "paper_arm",
                "parameters": [{"name": "joint1.d"}],
            }
        )
    )
    assert main(["fk", "--robot", "paper_arm", "--joints", *JOINTS, "--calibration", str(broken)]) == 1
    assert "has no finite 'estimate'" in capsys.readouterr().err
    argv = [
        "evaluate",
        str(campaign_file),
        "--robot",
        "paper_arm",
        "--test-joints",
        *JOINTS,
        "--degrees",
        "--trials",
        "100",
        "--out",
        str(tmp_path / "r"),
        "--no-progress",
        "--budget-trials",
        "0",
    ]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--budget-trials must be a positive integer" in err
