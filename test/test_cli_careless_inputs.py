"""Careless inputs never give a number with exit status 0.

Each case is what a careless user did (a unit slip, copied rows, too few trials, a damaged
file, a tiny campaign, a check that cannot separate what it re-registers, absurd numbers): the
command line either refuses in one line (naming the option that accepts it, where one does),
or states the result with a warning and a flag.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.bagio.campaign_mcap import write_campaign
from robocal_uncertainty.cli import main
from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.importers.tracker_csv import read_tracker_csv

ROOT = Path(__file__).resolve().parents[1]
UR10_CSV = ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv"
TEST_JOINTS = ["--test-joints", "0.934319", "-1.79251", "1.5196", "0.272862", "0.934269", "-1.57075"]
QUICK = ["--no-budget", "--no-sweeps", "--no-progress"]


@pytest.fixture(scope="module")
def series() -> Campaign:
    return read_tracker_csv(UR10_CSV)


@pytest.fixture(scope="module")
def campaigns(series: Campaign, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("careless")
    write_campaign(out / "ur10.mcap", series.subset(np.arange(0, series.n_poses, 3)))
    idx = np.sort(np.random.default_rng(0).choice(series.n_poses, 20, replace=False))
    write_campaign(out / "u20.mcap", series.subset(idx))
    write_campaign(out / "dup60.mcap", series.subset(np.tile(idx, 3)))
    write_campaign(out / "u60.mcap", series.subset(np.arange(0, 600, 10)))
    write_campaign(out / "check10.mcap", series.subset(np.arange(0, 632, 63)[:10]))
    return out


def _error_line(err: str) -> str:
    lines = [line for line in err.splitlines() if "error:" in line]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_metres_under_a_millimetre_header_are_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    lines = UR10_CSV.read_text().splitlines()[:61]
    header = lines[0].split(";")
    cols = [header.index(f"measurement_{a}") for a in "xyz"]
    rows = [lines[0]]
    for line in lines[1:]:
        cells = line.split(";")
        for c in cols:
            cells[c] = repr(float(cells[c].replace(",", ".")) / 1000.0).replace(".", ",")
        rows.append(";".join(cells))
    csv = tmp_path / "metres.csv"
    csv.write_text("\n".join(rows) + "\n")
    assert main(["import-csv", str(csv), "--out", str(tmp_path / "m.mcap")]) == 0
    capsys.readouterr()
    assert main(["calibrate", str(tmp_path / "m.mcap"), "--robot", "ur10"]) == 1
    line = _error_line(capsys.readouterr().err)
    assert "0.001 times the robot's size (metres read as millimetres?)" in line
    status = main(["evaluate", str(tmp_path / "m.mcap"), "--robot", "ur10", *TEST_JOINTS, "--trials", "100", *QUICK])
    assert status == 1 and "metres read as millimetres" in _error_line(capsys.readouterr().err)
    assert not Path("robocal_report").exists()


def test_a_monte_carlo_far_from_its_own_gum_is_no_statement(
    campaigns: Path,
    series: Campaign,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    # The second line of defence: with the unit check bypassed, the metre-sized robot's trials
    # diverge (u of metres against a GUM u of micrometres) and the run is refused, not printed.
    from robocal_uncertainty.core import identification

    monkeypatch.setattr(identification, "check_point_scale", lambda model, campaign: None)
    metres = Campaign(
        joint_names=series.joint_names,
        joint_positions=series.joint_positions[:60],
        points=series.points[:60] * 1e-3,
        frame=series.frame,
        frame_id=series.frame_id,
        metadata=dict(series.metadata),
    )
    write_campaign(tmp_path / "metres.mcap", metres)
    out = tmp_path / "report"
    status = main(
        [
            "evaluate",
            str(tmp_path / "metres.mcap"),
            "--robot",
            "ur10",
            *TEST_JOINTS,
            "--trials",
            "200",
            *QUICK,
            "--out",
            str(out),
        ]
    )
    captured = capsys.readouterr()
    assert status == 1, captured.out
    line = _error_line(captured.err)
    assert "did not converge to a statement" in line and "more than 10 either way" in line
    assert "Standard uncertainty" not in captured.out and not (out / "report.json").exists()


def test_a_ten_pose_subset_whose_trials_diverge_is_no_statement(
    series: Campaign, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Real data, no bypass: 10 poses of the UR10 series with a 2.5 mm model error and 5 residual
    # degrees of freedom; about one trial in eight re-identifies far away (u of 1e8 m).
    poses = [24, 53, 59, 112, 113, 148, 366, 503, 505, 546]
    write_campaign(tmp_path / "ten.mcap", series.subset(np.array(poses)))
    out = tmp_path / "report"
    status = main(
        [
            "evaluate",
            str(tmp_path / "ten.mcap"),
            "--robot",
            "ur10",
            *TEST_JOINTS,
            "--trials",
            "2000",
            *QUICK,
            "--out",
            str(out),
        ]
    )
    captured = capsys.readouterr()
    assert status == 1
    line = _error_line(captured.err)
    assert "did not converge to a statement: test configuration 1: Monte Carlo u = " in line
    ratio = float(line.split("(ratio ")[1].split(",")[0])
    assert ratio > 1e6  # 3.3e10 here: diverged trials, not a nonlinearity
    assert "Standard uncertainty" not in captured.out and not (out / "report.json").exists()


def test_repeated_poses_count_once_so_copies_cannot_defeat_the_small_campaign_flag(
    campaigns: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    flags = {}
    for name in ("u20", "dup60"):
        out = Path(f"report_{name}")
        status = main(
            [
                "evaluate",
                str(campaigns / f"{name}.mcap"),
                "--robot",
                "ur10",
                *TEST_JOINTS,
                "--trials",
                "100",
                *QUICK,
                "--out",
                str(out),
            ]
        )
        printed = capsys.readouterr().out
        assert status == 0
        report = json.loads((out / "report.json").read_text())
        flags[name] = (report["model_adequacy"]["trustworthy"], report["model_adequacy"]["residual_dof"], printed)
    assert flags["u20"][0] is False and flags["dup60"][0] is False
    # The 40 copies add nothing: the same residual degrees of freedom as the 20 poses alone.
    assert flags["dup60"][1] == pytest.approx(flags["u20"][1], abs=1.0)
    assert "40 poses repeat an earlier pose's joint readings" in flags["dup60"][2]
    assert "NOT TRUSTWORTHY" in flags["dup60"][2] and "40 repeated poses counted once" in flags["dup60"][2]
    # A point-only run states no rotation: no figure of empty "undetermined" panels.
    assert not list(Path("report_u20").glob("rotation_histograms_*.png"))
    assert (Path("report_u20") / "parameters.png").is_file()


def test_too_few_trials_for_the_interval(campaigns: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["evaluate", str(campaigns / "u60.mcap"), "--robot", "ur10", *TEST_JOINTS, *QUICK]
    assert main([*argv, "--trials", "11"]) == 1
    line = _error_line(capsys.readouterr().err)
    assert "--trials 11 cannot state a 95 % coverage interval: below 2/(1-p) = 40 trials" in line
    assert "--trials 2000 or more, or --trials auto" in line
    assert main([*argv, "--trials", "100", "--coverage", "0.99"]) == 1  # 2/(1-0.99) = 200
    capsys.readouterr()
    assert main([*argv, "--trials", "100", "--out", "few"]) == 0
    printed = capsys.readouterr().out
    assert "warning: a 95 % interval from 100 trials" in printed and "its ends rest on 2 trials each" in printed
    report = Path("few/report.md").read_text()
    assert (
        "converged: not tested (fixed number of trials" in report
        and "converged: yes" not in report.split("## Calibration")[0]
    )
    assert json.loads(Path("few/report.json").read_text())["monte_carlo"]["convergence_tested"] is False


def test_a_damaged_campaign_is_refused_unless_dropping_is_accepted(
    campaigns: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = bytearray((campaigns / "ur10.mcap").read_bytes())
    # 200 bytes flipped from the first top-level record starting past the middle: its length
    # field is destroyed, so the record framing breaks there while the footer stays intact.
    # (Bytes flipped inside a record body are caught by the chunk CRC, also in one line.)
    middle = 8
    while middle < len(data) // 2:
        middle += 9 + struct.unpack_from("<Q", data, middle + 1)[0]
    data[middle : middle + 200] = bytes(b ^ 0xFF for b in data[middle : middle + 200])
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    assert main(["calibrate", str(damaged), "--robot", "ur10"]) == 1
    line = _error_line(capsys.readouterr().err)
    assert "is damaged" in line and "intact footer" in line and "--accept-damaged" in line
    assert main(["calibrate", str(damaged), "--robot", "ur10", "--accept-damaged"]) == 0
    captured = capsys.readouterr()
    assert "the rest dropped (--accept-damaged)" in captured.err
    n = int(captured.out.split("Calibration of ur10: ")[1].split(" poses")[0])
    assert 0 < n < 211
    # A file cut short (writer killed, no footer) is still recovered with a warning, as before.
    truncated = tmp_path / "truncated.mcap"
    whole = (campaigns / "ur10.mcap").read_bytes()
    truncated.write_bytes(whole[: len(whole) * 3 // 4])
    assert main(["calibrate", str(truncated), "--robot", "ur10"]) == 0
    assert "is truncated (writer stopped before the footer)" in capsys.readouterr().err


def test_validate_of_a_small_training_set_is_flagged(campaigns: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["validate", str(campaigns / "u60.mcap"), "--robot", "ur10", "--train-poses", "10", "--trials", "100"]
    assert main([*argv, "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "warning: the statement under test (10 training poses): NOT TRUSTWORTHY" in printed
    report = json.loads(Path("robocal_validation/validation.json").read_text())
    assert report["folds"][0]["trustworthy"] is False


def test_verify_retool_says_what_the_check_cannot_separate(
    campaigns: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cal = tmp_path / "cal.json"
    assert main(["calibrate", str(campaigns / "ur10.mcap"), "--robot", "ur10", "--json", str(cal)]) == 0
    capsys.readouterr()
    status = main(
        [
            "verify",
            str(cal),
            str(campaigns / "check10.mcap"),
            "--robot",
            "ur10",
            "--retool",
            "--out",
            str(tmp_path / "v"),
        ]
    )
    printed = capsys.readouterr().out
    assert status == 0
    assert "tracker move and tool point cannot be separated by this check: base.x, base.y, tool.z act alike" in printed
    assert "tracker moved" not in printed and "tool point re-registered" not in printed
    report = json.loads((tmp_path / "v" / "verify.json").read_text())
    assert report["inseparable"] == ["base.x", "base.y", "tool.z"]
    assert "cannot be separated" in (tmp_path / "v" / "verify.md").read_text()


@pytest.mark.parametrize("verb", ["calibrate", "evaluate"])
def test_lambda_whose_square_overflows_is_one_line(
    verb: str, campaigns: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [verb, str(campaigns / "u60.mcap"), "--robot", "ur10", "--lambda", "1e200"]
    if verb == "evaluate":
        argv += [*TEST_JOINTS, *QUICK]
    assert main(argv) == 1
    assert "--lambda must be 'auto', 'gcv' or a number from 0 to 1e+100, got '1e200'" in _error_line(
        capsys.readouterr().err
    )


def test_a_csv_coordinate_no_tracker_measures_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    lines = UR10_CSV.read_text().splitlines()[:20]
    header = lines[0].split(";")
    cells = lines[5].split(";")
    cells[header.index("measurement_x")] = "1e300"
    lines[5] = ";".join(cells)
    csv = tmp_path / "big.csv"
    csv.write_text("\n".join(lines) + "\n")
    assert main(["import-csv", str(csv), "--out", str(tmp_path / "big.mcap")]) == 1
    line = _error_line(capsys.readouterr().err)
    assert "line 6 (data row 5): column 'measurement_x': '1e300' is a coordinate of 1e+297 m" in line
    assert not (tmp_path / "big.mcap").exists()


def test_a_map_whose_trials_diverge_is_refused_and_an_honest_one_is_not(
    series: Campaign, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # The map shares evaluate's trials: on the same diverging 10-pose subset its spread is checked
    # against the first-order statement at configurations spread over the map, and refused.
    poses = [24, 53, 59, 112, 113, 148, 366, 503, 505, 546]
    write_campaign(tmp_path / "ten.mcap", series.subset(np.array(poses)))
    argv = ["--robot", "ur10", "--configurations", "40", "--trials", "2000", "--no-progress"]
    status = main(["map", str(tmp_path / "ten.mcap"), *argv, "--out", str(tmp_path / "ten_map")])
    captured = capsys.readouterr()
    assert status == 1
    line = _error_line(captured.err)
    assert "did not converge to a map: map configuration " in line
    assert float(line.split("(ratio ")[1].split(",")[0]) > 1e6
    # 120 poses of the same series: an honest map, within the factor everywhere it is checked.
    write_campaign(tmp_path / "many.mcap", series.subset(np.arange(0, 600, 5)))
    assert main(["map", str(tmp_path / "many.mcap"), *argv, "--out", str(tmp_path / "many_map")]) == 0
