"""Command line input checks: foreign calibrations, joint limits, truncated campaigns.

Each ends in one line on stderr: ``robocal-uncertainty CMD: error: ...`` with exit status 1,
or ``warning: ...`` when the input is usable.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from robocal_uncertainty.bagio import read_campaign, write_campaign
from robocal_uncertainty.cli import PAPER_TEST_JOINTS_DEG, main
from robocal_uncertainty.core import Campaign

JOINTS = [str(v) for v in PAPER_TEST_JOINTS_DEG]
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def paper_campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("checks") / "c.mcap"
    assert main(["simulate", "--robot", "paper_arm", "--out", str(path), "--seed", "11"]) == 0
    return path


@pytest.fixture(scope="module")
def paper_calibration(paper_campaign: Path) -> Path:
    path = paper_campaign.with_name("cal.json")
    assert main(["calibrate", str(paper_campaign), "--robot", "paper_arm", "--json", str(path)]) == 0
    return path


def _error(capsys: pytest.CaptureFixture[str], command: str) -> str:
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    prefix = f"robocal-uncertainty {command}: error: "
    assert lines[0].startswith(prefix), lines[0]
    return lines[0][len(prefix) :]


# ------------------------------------------------------------------- foreign calibration


def test_fk_refuses_another_robots_calibration(paper_calibration: Path, capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    argv = ["fk", "--robot", "ur10", "--calibration", str(paper_calibration), "--joints", "0", "-1", "1", "0", "1", "0"]
    assert main(argv) == 1
    msg = _error(capsys, "fk")
    assert msg == (
        f"calibration {paper_calibration} was identified on robot 'paper_arm' and cannot be applied to robot 'ur10'"
    )


def test_fk_applies_the_calibration_to_its_own_robot(
    paper_calibration: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    argv = ["fk", "--robot", "paper_arm", "--calibration", str(paper_calibration), "--joints", *JOINTS, "--degrees"]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert captured.err == ""
    assert "calibrated paper_arm model" in captured.out


# ------------------------------------------------------------------------ joint limits


def test_fk_degrees_typed_as_radians(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["fk", "--robot", "paper_arm", "--joints", *JOINTS]) == 1
    msg = _error(capsys, "fk")
    assert msg.startswith("--joints configuration 1 of 1: joint joint1 = -7.5005 rad (-429.747 deg)")
    assert "is outside its limits [-175, 175] deg" in msg
    assert msg.endswith("; did you mean --degrees?")


def test_fk_ur10_degrees_typed_as_radians(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["fk", "--robot", "ur10", "--joints", "0", "-90", "90", "0", "90", "0"]) == 1
    msg = _error(capsys, "fk")
    assert "joint shoulder_lift_joint = -90 rad" in msg and "[-360, 360] deg" in msg
    assert msg.endswith("did you mean --degrees?")


def test_fk_beyond_limits_in_degrees_has_no_hint(capsys: pytest.CaptureFixture[str]) -> None:
    joints = list(JOINTS)
    joints[1] = "-60"  # joint2 of the paper arm: [-265, -95] deg
    assert main(["fk", "--robot", "paper_arm", "--joints", *joints, "--degrees"]) == 1
    msg = _error(capsys, "fk")
    assert msg == (
        "--joints configuration 1 of 1: joint joint2 = -1.0472 rad (-60 deg) is outside its limits [-265, -95] deg"
    )


def test_fk_joints_file_names_file_and_row(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "q.txt"
    path.write_text("# deg\n" + " ".join(JOINTS) + "\n" + " ".join([*JOINTS[:5], "200"]) + "\n")
    assert main(["fk", "--robot", "paper_arm", "--joints-file", str(path), "--degrees"]) == 1
    msg = _error(capsys, "fk")
    assert msg.startswith(f"{path}: configuration 2 of 2: joint joint6 = 3.49066 rad (200 deg)")


def test_joints_missing_or_beyond_limits_read_alike_in_fk_and_evaluate(
    paper_campaign: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """fk --joints[-file] and evaluate --test-joints[-file] share one reader: same messages."""
    assert main(["fk", "--robot", "paper_arm"]) == 1
    assert _error(capsys, "fk") == "give --joints or --joints-file"
    out = tmp_path / "report"
    evaluate = ["evaluate", str(paper_campaign), "--robot", "paper_arm", "--out", str(out), "--no-progress"]
    assert main(evaluate) == 1
    assert _error(capsys, "evaluate") == "give --test-joints or --test-joints-file"
    path = tmp_path / "q.txt"
    path.write_text(" ".join([*JOINTS[:5], "200"]) + "\n")
    assert main([*evaluate, "--test-joints-file", str(path), "--degrees"]) == 1
    assert _error(capsys, "evaluate").startswith(f"{path}: test configuration 1 of 1: joint joint6 = 3.49066 rad")
    assert not out.exists()


def test_evaluate_refuses_test_joints_beyond_limits(
    paper_campaign: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "report"
    argv = ["evaluate", str(paper_campaign), "--robot", "paper_arm", "--test-joints", *JOINTS, "--out", str(out)]
    assert main([*argv, "--trials", "100", "--no-progress"]) == 1
    msg = _error(capsys, "evaluate")
    assert msg.startswith("--test-joints configuration 1 of 1: joint joint1 = -7.5005 rad")
    assert msg.endswith("did you mean --degrees?")
    assert not out.exists()  # refused before any Monte Carlo


def test_calibrate_refuses_a_campaign_recorded_in_degrees(
    paper_campaign: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    good = read_campaign(paper_campaign)
    bad = tmp_path / "degrees.mcap"
    write_campaign(
        bad,
        Campaign(
            joint_names=good.joint_names,
            joint_positions=np.degrees(good.joint_positions),
            points=good.points,
            frame=good.frame,
            frame_id=good.frame_id,
        ),
    )
    capsys.readouterr()
    assert main(["calibrate", str(bad), "--robot", "paper_arm"]) == 1
    msg = _error(capsys, "calibrate")
    assert msg.startswith(f"{bad}: campaign pose 1 of 53: joint ")
    assert "deg) is outside its limits [" in msg
    assert msg.endswith("the readings look like degrees (import-csv --angle-unit deg?)")


def test_real_ur10_campaign_is_within_limits(real_ur10_calibration: Any) -> None:
    # The real series' readings are radians within the UR10's limits: no warning on stderr.
    assert "632 poses" in real_ur10_calibration.printed
    assert real_ur10_calibration.errors == ""


# ------------------------------------------------------------------- truncated campaign


def test_truncated_campaign_is_one_warning_line(
    paper_campaign: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    chopped = tmp_path / "chopped.mcap"
    chopped.write_bytes(paper_campaign.read_bytes()[:-2000])
    with pytest.warns(UserWarning, match="is truncated"):
        n = read_campaign(chopped).n_poses  # the pose count the reader recovers
    assert 0 < n <= 53
    capsys.readouterr()
    assert main(["calibrate", str(chopped), "--robot", "paper_arm"]) == 0
    captured = capsys.readouterr()
    assert captured.err.splitlines() == [
        f"warning: {chopped} is truncated (writer stopped before the footer); "
        f"recovered {n} poses up to the last complete record"
    ]
    assert "UserWarning" not in captured.err
    assert f"{n} poses" in captured.out


def test_complete_campaign_has_no_warning(paper_campaign: Path, capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["calibrate", str(paper_campaign), "--robot", "paper_arm"]) == 0
    assert capsys.readouterr().err == ""


def test_truncated_campaign_warning_reaches_the_evaluate_report(
    paper_campaign: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import json

    chopped = tmp_path / "chopped.mcap"
    chopped.write_bytes(paper_campaign.read_bytes()[:-2000])
    joints = ["-7.5005", "-234.4840", "-106.7448", "-92.3875", "-61.5425", "20.7451"]
    args = ["evaluate", str(chopped), "--robot", "paper_arm", "--test-joints", *joints, "--degrees"]
    args += ["--trials", "300", "--no-budget", "--no-sweeps", "--no-progress", "--out", str(tmp_path / "r")]
    assert main(args) == 0
    assert "is truncated" in capsys.readouterr().err
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    assert any("is truncated" in w for w in report["warnings"])
    assert "is truncated" in (tmp_path / "r" / "report.md").read_text()


def test_base_frame_points_in_another_urdf_link_and_the_tool_point(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Points in UR's `base` (the DH frame; base_link turned by 180 degrees) calibrated with the
    URDF chain from base_link: refused, naming --base-link (it made a 1-8 mm 'model error').
    --tool-point is a URDF option: refused for a robot YAML."""
    campaign = tmp_path / "ur10.mcap"
    assert main(["simulate", "--robot", "ur10", "--poses", "40", "--out", str(campaign), "--seed", "2"]) == 0
    capsys.readouterr()
    urdf = str(ROOT / "robocal_uncertainty" / "data" / "ur10.urdf")
    assert main(["calibrate", str(campaign), "--robot", urdf]) == 1
    message = _error(capsys, "calibrate")
    assert "the points are in URDF link 'base', the chain starts at 'base_link'" in message
    assert message.endswith("give --base-link base")
    assert main(["calibrate", str(campaign), "--robot", urdf, "--base-link", "base", "--tip-link", "tool0"]) == 0
    out = capsys.readouterr().out
    assert "residual RMS" in out and "-> 0.04" in out  # the noise level (0.0448 mm)
    assert main(["calibrate", str(campaign), "--robot", "ur10", "--tool-point", "0", "0", "0.109"]) == 1
    assert "--robot ur10 is not a .urdf file" in _error(capsys, "calibrate")
