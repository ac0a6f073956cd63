"""CLI: simulate sessions, calibrate with a session record, verify a check of a new session."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from robocal_uncertainty.cli import main


@pytest.fixture(scope="module")
def sessions(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("sessions")
    args = ["simulate", "--robot", "ur10", "--sessions", "3", "--session-poses", "53", "10", "10"]
    args += [
        "--out",
        str(out / "ur10.mcap"),
        "--seed",
        "4",
        "--joint-drift-deg",
        "0",
        "--temperature-k",
        "0",
        "--tool-remount-um",
        "500",
    ]
    assert main(args) == 0
    assert main(["calibrate", str(out / "ur10.session1.mcap"), "--robot", "ur10", "--json", str(out / "cal.json")]) == 0
    return out


def test_simulated_sessions_carry_their_truth(sessions: Path) -> None:
    truth = json.loads((sessions / "ur10.session2.truth.json").read_text())
    assert truth["format"] == "robocal_uncertainty/session_truth/1" and truth["session"] == 2
    assert truth["change"]["temperature_delta_K"] == 0.0
    assert len(truth["change"]["tool_offset_m"]) == 3 and len(truth["true_joint_positions_rad"]) == 10
    cal = json.loads((sessions / "cal.json").read_text())
    assert cal["format"] == "robocal_uncertainty/calibration/3" and cal["scope"] == "session"
    assert cal["session"]["frame"] == "tracker" and len(cal["session"]["registration"]["covariance"]) == 6


def test_verify_prints_verdict_move_and_writes_the_report(sessions: Path, capsys: pytest.CaptureFixture[str]) -> None:
    report = sessions / "check"
    args = ["verify", str(sessions / "cal.json"), str(sessions / "ur10.session2.mcap"), "--robot", "ur10"]
    status = main([*args, "--retool", "--out", str(report), "--null-trials", "4000"])
    out = capsys.readouterr().out
    assert status == 0, out
    assert out.startswith("consistent: the robot agrees with its calibration")
    assert "tracker moved" in out and "mrad since the calibration session" in out
    assert "10 check poses, 30 equations, 9 re-registered (21 degrees of freedom left)" in out
    data = json.loads((report / "verify.json").read_text())
    assert data["consistent"] is True and data["test"]["dof"] == 21
    assert (report / "verify.png").stat().st_size > 1000
    assert "# Check measurement" in (report / "verify.md").read_text()
    # Without re-registering the remounted probe (500 um per axis), the check sees it.
    assert main([*args, "--null-trials", "4000"]) == 3
    assert capsys.readouterr().out.startswith("drifted: the robot deviates from its calibration by about")


def test_verify_refuses_small_checks_and_files_without_a_session(
    sessions: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    small = tmp_path / "small.mcap"
    args = ["simulate", "--robot", "ur10", "--frame", "tracker", "--poses", "3", "--out", str(small)]
    assert main(args) == 0
    capsys.readouterr()
    assert main(["verify", str(sessions / "cal.json"), str(small), "--robot", "ur10"]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("robocal-uncertainty verify: error: check campaign too small: 3 poses") and "\n" not in err
    old = json.loads((sessions / "cal.json").read_text())
    old["format"] = "robocal_uncertainty/calibration/1"
    for key in ("session", "parameter_covariance", "noise", "model_error"):
        old.pop(key)
    v1 = tmp_path / "v1.json"
    v1.write_text(json.dumps(old))
    assert main(["verify", str(v1), str(sessions / "ur10.session2.mcap"), "--robot", "ur10"]) == 1
    assert "has no session record" in capsys.readouterr().err
    assert main(["verify", str(sessions / "cal.json"), str(small), "--robot", "ur10", "--significance", "5"]) == 1
    assert "--significance is a probability" in capsys.readouterr().err


def test_evaluate_adds_the_between_session_component(sessions: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cal = sessions / "cal_future.json"
    args = ["calibrate", str(sessions / "ur10.session1.mcap"), "--robot", "ur10", "--json", str(cal)]
    assert main([*args, "--sessions", str(sessions / "ur10.session2.mcap")]) == 0
    assert "statement scope: future sessions (between-session component from 2 sessions" in capsys.readouterr().out
    joints = ["--test-joints", "0.9", "-1.8", "1.5", "0.3", "0.9", "-1.6"]
    base = ["evaluate", str(sessions / "ur10.session1.mcap"), "--robot", "ur10", *joints, "--trials", "2000"]
    assert main([*base, "--between-session", str(cal), "--out", str(sessions / "ev"), "--force"]) == 0
    out = capsys.readouterr().out
    assert "between_session" in out.split("Uncertainty budget")[1]
    # A file of one session has no component to add: one-line refusal.
    assert main([*base, "--between-session", str(sessions / "cal.json"), "--out", str(sessions / "ev2")]) == 1
    assert "has no between-session component: calibrate it with --sessions" in capsys.readouterr().err


def test_verify_of_a_urdf_calibration_equals_that_of_the_dh_model(
    sessions: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # The shipped ur10.urdf from UR's base to tool0 is the DH model's kinematics (to 4e-16 m):
    # calibrated and verified through the URDF chain, the check gives the DH model's test.
    urdf = str(Path(__file__).resolve().parents[1] / "robocal_uncertainty" / "data" / "ur10.urdf")
    chain = ["--base-link", "base", "--tip-link", "tool0"]
    cal = sessions / "cal_urdf.json"
    assert main(["calibrate", str(sessions / "ur10.session1.mcap"), "--robot", urdf, *chain, "--json", str(cal)]) == 0
    capsys.readouterr()
    verdicts = []
    for robot, calibration, extra in ((urdf, cal, chain), ("ur10", sessions / "cal.json", [])):
        args = ["verify", str(calibration), str(sessions / "ur10.session3.mcap"), "--robot", robot, *extra]
        status = main([*args, "--retool", "--null-trials", "2000", "--out", str(sessions / f"v_{robot[-4:]}")])
        out = capsys.readouterr().out
        verdicts.append((status, json.loads((sessions / f"v_{robot[-4:]}" / "verify.json").read_text())))
        assert status == 0, out
    (_, via_urdf), (_, via_dh) = verdicts
    assert via_urdf["test"]["dof"] == via_dh["test"]["dof"] == 21
    assert via_urdf["test"]["chi2"] == pytest.approx(via_dh["test"]["chi2"], rel=2e-3)
    assert via_urdf["test"]["p_value"] == pytest.approx(via_dh["test"]["p_value"], abs=0.02)
