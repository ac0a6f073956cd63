"""The command line keeps its promises (issue 11): early checks, one overwrite rule, helpful
defaults, messages in the command line's words.

Every error is one line on stderr, ``robocal-uncertainty CMD: error: ...``, with exit status 1
(2 for argparse usage errors), printed before any calibration output and without touching an
existing file. The tests locate their data from this file, so they pass from any directory.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.bagio import read_campaign
from robocal_uncertainty.bagio.raw_bag_simulator import (
    RawBagSettings,
    RawRecord,
    read_raw_truth,
    write_raw_bag,
    write_raw_records,
)
from robocal_uncertainty.bagio.ros_messages import (
    JOINT_STATE,
    POINT_STAMPED,
    encode_joint_state,
    encode_point_stamped,
)
from robocal_uncertainty.cli import PAPER_TEST_JOINTS_DEG, main
from robocal_uncertainty.core import SimulationSettings, load_robot_model, simulate_campaign
from robocal_uncertainty.pipeline.replay import replay_bag

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "test" / "data"
BASE_BAG = DATA / "paper_arm_base_raw.mcap"
TRACKER_BAG = DATA / "paper_arm_tracker_raw.mcap"
PAPER_ARM = ROOT / "robocal_uncertainty" / "data" / "paper_arm.yaml"
JOINTS = [str(v) for v in PAPER_TEST_JOINTS_DEG]
QUICK = ["--trials", "100", "--no-budget", "--no-sweeps", "--no-progress"]


@pytest.fixture(scope="module")
def campaign12(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("promises") / "c12.mcap"
    assert main(["simulate", "--out", str(path), "--poses", "12", "--seed", "4"]) == 0
    return path


@pytest.fixture(autouse=True)
def _elsewhere(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Run every test from an unrelated directory: nothing may depend on the cwd."""
    monkeypatch.chdir(tmp_path)


def _error(capsys: pytest.CaptureFixture[str], command: str) -> str:
    """The one error line (the last stderr line; replay logs dropped messages before it)."""
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert lines, captured
    prefix = f"robocal-uncertainty {command}: error: "
    assert lines[-1].startswith(prefix), captured.err
    assert "Traceback" not in captured.err and "NoneType" not in captured.err
    assert all(line.startswith(("replay: dropped", prefix)) for line in lines), captured.err
    assert "Calibration of" not in captured.out  # refused before any calibration output
    return lines[-1][len(prefix) :]


def _evaluate(campaign: Path, *extra: str) -> list[str]:
    return ["evaluate", str(campaign), "--robot", "paper_arm", "--test-joints", *JOINTS, "--degrees", *extra]


# --------------------------------------------------------------------- version, usage


def test_version_and_usage_exit_status(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    assert capsys.readouterr().out.startswith("robocal-uncertainty 0.")
    with pytest.raises(SystemExit) as usage:
        main(["evaluate"])
    assert usage.value.code == 2  # argparse convention: usage errors exit 2 with a usage block
    assert "the following arguments are required" in capsys.readouterr().err


def test_every_option_has_help(capsys: pytest.CaptureFixture[str]) -> None:
    from robocal_uncertainty.cli import _build_parser

    parser = _build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name, command in sub.choices.items():  # type: ignore[union-attr]
        for action in command._actions:
            if action.dest != "help":
                assert action.help, f"{name} {action.option_strings or action.dest} has no help"


def test_readme_documents_the_exit_status() -> None:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    for fact in ("**Exit status.**", "1: an error", "2: a usage error", "141: the output pipe", "--force"):
        assert fact in text, fact


# --------------------------------------------------------------------- early checks


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--trials", "0"], "--trials must be a positive integer or 'auto', got '0'"),
        (["--trials", "-5"], "--trials must be a positive integer or 'auto', got '-5'"),
        (["--trials", "abc"], "--trials must be a positive integer or 'auto', got 'abc'"),
        (["--coverage", "1.5"], "--coverage is a probability in (0, 1), got 1.5"),
        (["--coverage", "95"], "--coverage is a probability in (0, 1), got 95; did you mean 0.95?"),
        (["--workers", "0"], "--workers must be a positive integer, got 0"),
        (["--subset-size", "1000"], "--subset-size 1000 is more than the campaign's 12 poses"),
        (["--min-poses", "13"], "--min-poses 13 is more than the campaign's 12 poses"),
        (["--budget-trials", "0"], "--budget-trials must be a positive integer, got 0"),
        (["--sweep-trials", "-1"], "--sweep-trials must be a positive integer, got -1"),
        (["--max-trials", "0"], "--max-trials must be a positive integer, got 0"),
        (["--tracker-noise-um", "-5"], "--tracker-noise-um must be a finite number >= 0 um, got -5"),
        (["--encoder-noise-deg", "nan"], "--encoder-noise-deg must be a finite number >= 0 deg, got nan"),
        (["--seed", "-1"], "--seed must be an integer >= 0, got -1"),
        (["--lambda-range", "5", "1"], "--lambda-range needs 0 <= LOW < HIGH, got 5 1"),
        (["--lambda", "big"], "--lambda must be 'auto', 'gcv' or a number, got 'big'"),
        (["--pairing-tolerance-ms", "-1"], "--pairing-tolerance-ms must be a finite number >= 0 ms, got -1"),
        (
            ["--dask", "nonsense"],
            "--dask must be 'local' or a scheduler address such as tcp://host:8786, got 'nonsense'",
        ),
        (
            ["--dask", "tcp://host"],
            "--dask must be 'local' or a scheduler address such as tcp://host:8786, got 'tcp://host'",
        ),
    ],
)
def test_bad_options_are_refused_before_any_work(
    campaign12: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], message: str
) -> None:
    out = tmp_path / "report"
    assert main(_evaluate(campaign12, "--out", str(out), "--no-progress", *extra)) == 1
    assert _error(capsys, "evaluate") == message
    assert not out.exists()


@pytest.mark.parametrize(
    "address", ["local", "tcp://127.0.0.1:8786", "127.0.0.1:8786", "tls://sched.lan:8786", "tcp://[::1]:8786"]
)
def test_dask_addresses_distributed_accepts_pass_the_early_check(address: str) -> None:
    from robocal_uncertainty.cli import _DASK_ADDRESS

    assert _DASK_ADDRESS.match(address)


def test_min_poses_below_identifiable_names_the_flag(
    campaign12: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "report"
    argv = _evaluate(campaign12, "--out", str(out), "--sources", "tracker,n_poses", "--min-poses", "2", *QUICK)
    assert main(argv) == 1
    msg = _error(capsys, "evaluate")
    assert msg.startswith("--min-poses = 2 must lie between ") and "min_poses" not in msg
    assert not out.exists()


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--k-folds", "1"], "--k-folds must be an integer >= 2, got 1"),
        (["--k-folds", "13"], "--k-folds 13 is more than the campaign's 12 poses"),
        (["--holdout-fraction", "1.5"], "--holdout-fraction must lie in (0, 1), got 1.5"),
        (["--train-poses", "12"], "--train-poses 12 leaves no pose to hold out: the campaign has 12 poses"),
        (["--trials", "auto"], "validate needs a fixed number of --trials, not auto"),
    ],
)
def test_validate_options_in_cli_words(
    campaign12: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], message: str
) -> None:
    argv = ["validate", str(campaign12), "--robot", "paper_arm", "--out", str(tmp_path / "v"), *extra]
    assert main(argv) == 1
    assert _error(capsys, "validate") == message


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--window-s", "0"], "--window-s must be 'auto' or a number of seconds > 0, got '0'"),
        (["--min-points", "1"], "--min-points must be an integer >= 2, got 1"),
        (["--joint-motion-threshold-rad", "0"], "--joint-motion-threshold-rad must be a finite number > 0 rad, got 0"),
    ],
)
def test_replay_options_in_cli_words(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], message: str
) -> None:
    argv = ["replay", str(BASE_BAG), "--robot", "paper_arm", "--test-joints", *JOINTS, "--degrees", *extra]
    assert main([*argv, "--out", str(tmp_path / "r"), *QUICK]) == 1
    assert _error(capsys, "replay") == message


def test_no_traceback_from_a_fresh_process(campaign12: Path, tmp_path: Path) -> None:
    argv = [sys.executable, "-m", "robocal_uncertainty", *_evaluate(campaign12, "--trials", "0")]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(argv, cwd=tmp_path, capture_output=True, text=True, env=env, check=False, timeout=120)
    assert done.returncode == 1
    assert done.stdout == ""
    assert done.stderr.splitlines() == [
        "robocal-uncertainty evaluate: error: --trials must be a positive integer or 'auto', got '0'"
    ]


# --------------------------------------------------------------------- output paths


def _untouched(path: Path) -> tuple[bytes, int]:
    return path.read_bytes(), path.stat().st_mtime_ns


@pytest.mark.parametrize("command", ["simulate", "import-csv", "calibrate", "fk"])
def test_existing_output_file_is_refused_without_force(
    campaign12: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    target = tmp_path / "existing.out"
    target.write_text("keep me\n")
    before = _untouched(target)
    csv = DATA / "ur10_laser_tracker" / "measurements_iso_cubes.csv"
    argv = {
        "simulate": ["simulate", "--out", str(target)],
        "import-csv": ["import-csv", str(csv), "--out", str(target)],
        "calibrate": ["calibrate", str(campaign12), "--robot", "paper_arm", "--json", str(target)],
        "fk": ["fk", "--robot", "paper_arm", "--joints", *JOINTS, "--degrees", "--json", str(target)],
    }[command]
    assert main(argv) == 1
    option = "--json" if command in ("calibrate", "fk") else "--out"
    assert _error(capsys, command) == f"{option} {target} exists already (give --force to replace it)"
    assert _untouched(target) == before
    assert main([*argv, "--force"]) == 0
    assert target.read_bytes() != before[0]


@pytest.mark.parametrize("command", ["import-csv", "calibrate", "fk", "replay"])
def test_force_never_replaces_an_input(
    campaign12: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    """--force replaces earlier outputs, never the file the command reads (one line, exit 1)."""
    csv = tmp_path / "table.csv"
    csv.write_bytes((DATA / "ur10_laser_tracker" / "measurements_iso_cubes.csv").read_bytes())
    campaign = tmp_path / "c.mcap"
    campaign.write_bytes(campaign12.read_bytes())
    calibration = tmp_path / "cal.json"
    assert main(["calibrate", str(campaign), "--robot", "paper_arm", "--json", str(calibration)]) == 0
    bag = tmp_path / "raw.mcap"
    bag.write_bytes(TRACKER_BAG.read_bytes())
    capsys.readouterr()
    argv, target, words = {
        "import-csv": (["import-csv", str(csv), "--out", "./table.csv"], csv, "--out ./table.csv is the tracker CSV"),
        "calibrate": (
            ["calibrate", str(campaign), "--robot", "paper_arm", "--json", str(campaign)],
            campaign,
            f"--json {campaign} is the campaign being read",
        ),
        "fk": (
            [
                "fk",
                "--robot",
                "paper_arm",
                "--calibration",
                str(calibration),
                "--joints",
                *JOINTS,
                "--degrees",
                "--json",
                str(calibration),
            ],
            calibration,
            f"--json {calibration} is the --calibration being applied",
        ),
        "replay": (
            [
                "replay",
                str(bag),
                "--robot",
                "paper_arm",
                "--test-joints",
                *JOINTS,
                "--degrees",
                *QUICK,
                "--out",
                str(tmp_path / "rep"),
                "--campaign-out",
                str(bag),
            ],
            bag,
            f"--campaign-out {bag} is the bag being replayed",
        ),
    }[command]
    before = _untouched(target)
    assert main([*argv, "--force"]) == 1
    assert _error(capsys, command).startswith(words)
    assert _untouched(target) == before


@pytest.mark.parametrize(
    ("make", "message"),
    [
        ("dir", "cannot write --json {p}: it is a directory"),
        ("missing", "cannot write --json {p}: directory {parent} does not exist"),
        ("under-file", "cannot write --json {p}: {parent} is a file, not a directory"),
    ],
)
def test_unwritable_json_is_refused_before_calibrating(
    campaign12: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], make: str, message: str
) -> None:
    if make == "dir":
        path = tmp_path / "adir"
        path.mkdir()
    elif make == "missing":
        path = tmp_path / "no" / "such" / "cal.json"
    else:
        (tmp_path / "afile").write_text("x")
        path = tmp_path / "afile" / "cal.json"
    assert main(["calibrate", str(campaign12), "--robot", "paper_arm", "--json", str(path)]) == 1
    assert _error(capsys, "calibrate") == message.format(p=path, parent=path.parent)


def test_output_in_a_directory_that_refuses_files_fails_before_work(
    campaign12: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A directory whose permission bits say writable but that refuses new files (a read-only
    mount, /proc, anything when root) is found before the calibration, in one line; it was a
    traceback after the work."""
    from robocal_uncertainty.app import output_paths

    def read_only(*args: object, **kwargs: object) -> None:
        raise OSError(30, "Read-only file system")

    monkeypatch.setattr(output_paths.tempfile, "TemporaryFile", read_only)
    path = tmp_path / "cal.json"
    assert main(["calibrate", str(campaign12), "--robot", "paper_arm", "--json", str(path)]) == 1
    assert _error(capsys, "calibrate") == f"cannot write --json {path}: directory {tmp_path} is not writable"
    out = tmp_path / "rep"
    assert main(_evaluate(campaign12, "--out", str(out), *QUICK)) == 1
    assert _error(capsys, "evaluate") == f"cannot write the report to --out {out}: directory {tmp_path} is not writable"
    assert not path.exists() and not out.exists()


def test_write_failing_during_the_run_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A write that fails after the checks (disk full) ends in one line, exit 1, no traceback."""
    path = tmp_path / "points.json"

    def disk_full(self: Path, *args: object, **kwargs: object) -> None:
        raise OSError(28, "No space left on device", str(self))

    monkeypatch.setattr(Path, "write_text", disk_full)
    assert main(["fk", "--robot", "paper_arm", "--joints", *JOINTS, "--degrees", "--json", str(path)]) == 1
    captured = capsys.readouterr()
    assert captured.err == f"robocal-uncertainty fk: error: cannot access {path}: No space left on device\n"


def test_report_directory_rule(campaign12: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "report"
    fast = ["--trials", "100", "--budget-trials", "50", "--sweep-trials", "20", "--no-progress", "--histograms", "0"]
    assert main(_evaluate(campaign12, "--out", str(out), *fast)) == 0
    sweeps = sorted(p.name for p in out.glob("sweep_*.png"))
    assert sweeps == ["sweep_lambda.png"]  # 12 poses: the equations sweep is skipped (a note says so)
    assert "note: the sweep over the number of equations is skipped" in capsys.readouterr().out
    mine = out / "notes.txt"
    mine.write_text("my notes\n")
    report = _untouched(out / "report.json")
    # The same command again: refused before any work, nothing touched.
    assert main(_evaluate(campaign12, "--out", str(out), *fast)) == 1
    assert _error(capsys, "evaluate") == (
        f"report directory --out {out} exists and is not empty (give --force to replace the earlier report, "
        "or another --out)"
    )
    assert _untouched(out / "report.json") == report
    # --force replaces the report; a --no-sweeps run leaves no stale sweep plot, other files stay.
    assert main(_evaluate(campaign12, "--out", str(out), *fast, "--no-sweeps", "--force")) == 0
    assert not list(out.glob("sweep_*.png"))
    assert mine.read_text() == "my notes\n"
    assert (out / "report.json").read_bytes() != report[0]
    capsys.readouterr()
    # A file where the report directory should be.
    assert main(_evaluate(campaign12, "--out", str(mine), *QUICK)) == 1
    assert _error(capsys, "evaluate") == (f"cannot write the report to --out {mine}: it is a file, not a directory")


def test_default_report_directory_is_not_replaced_silently(
    campaign12: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "robocal_report").mkdir()
    (tmp_path / "robocal_report" / "report.json").write_text("{}")
    assert main(_evaluate(campaign12, *QUICK)) == 1
    assert "report directory --out robocal_report exists and is not empty" in _error(capsys, "evaluate")
    assert main(["demo", *QUICK]) == 1
    assert "give --force" in _error(capsys, "demo")


# --------------------------------------------------------------------- small campaigns


def test_small_campaign_works_with_default_settings(
    campaign12: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = _evaluate(campaign12, "--out", str(tmp_path / "r"), "--sources", "tracker,encoder,n_poses,pose_choice")
    assert main([*argv, "--trials", "100", "--budget-trials", "50", "--sweep-trials", "20", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "note: the campaign's 12 poses are fewer than the 14 the n_poses source starts from" in out
    assert "set --min-poses to choose" in out
    assert "note: 33/53 of the campaign's 12 poses (7) cannot identify" in out
    assert "Calibration of paper_arm: 12 poses" in out


# --------------------------------------------------------------------- pairing tolerance


def _campaign_bag(path: Path, lag_ns: list[int], n: int = 20) -> None:
    """A recording with one /joint_states and one /tracker/point per pose, the point stamped
    `lag_ns[i]` after the joints (no campaign metadata: a plain rosbag2-style MCAP)."""
    model = load_robot_model(PAPER_ARM)
    campaign = simulate_campaign(model, SimulationSettings(n_poses=n), seed=9).campaign
    records = []
    for i in range(n):
        t = 1_700_000_000_000_000_000 + i * 2_000_000_000
        joints = encode_joint_state(t, tuple(campaign.joint_names), campaign.joint_positions[i])
        point = encode_point_stamped(t + lag_ns[i], "base_link", campaign.points[i])
        records.append(RawRecord("/joint_states", JOINT_STATE, t, joints))
        records.append(RawRecord("/tracker/point", POINT_STAMPED, t + lag_ns[i], point))
    write_raw_records(path, records)


def test_points_stamped_10_ms_after_the_joints_calibrate_by_default(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "lagged.mcap"
    _campaign_bag(bag, [10_000_000] * 20)
    assert main(["calibrate", str(bag), "--robot", "paper_arm"]) == 0
    captured = capsys.readouterr()
    assert "Calibration of paper_arm: 20 poses" in captured.out
    assert captured.err == ""
    assert main(["calibrate", str(bag), "--robot", "paper_arm", "--pairing-tolerance-ms", "5"]) == 1
    assert _error(capsys, "calibrate") == (
        f"{bag}: no pose found: pose 1 of 20: the /joint_states message nearest to its /tracker/point stamp is "
        "10 ms away; pose 1: 10 ms, more than --pairing-tolerance-ms 5"
    )


def test_validation_campaign_is_read_like_the_campaign(
    campaign12: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--validation-campaign gets the same --pairing-tolerance-ms and raw-recording check as the
    campaign (it was read with exact stamp matching only: a 10 ms lag found no pose)."""
    bag = tmp_path / "lagged.mcap"
    _campaign_bag(bag, [10_000_000] * 20)
    argv = ["validate", str(campaign12), "--robot", "paper_arm", "--validation-campaign", str(bag)]
    argv += ["--trials", "50", "--no-progress"]
    assert main([*argv, "--out", str(tmp_path / "r1")]) == 0
    assert "Traceback" not in capsys.readouterr().err
    assert main([*argv, "--out", str(tmp_path / "r2"), "--pairing-tolerance-ms", "5"]) == 1
    assert _error(capsys, "validate").startswith(f"{bag}: no pose found: pose 1 of 20")
    argv[argv.index(str(bag))] = str(BASE_BAG)
    assert main([*argv, "--out", str(tmp_path / "r3")]) == 1
    assert _error(capsys, "validate").startswith(f"{BASE_BAG}: 3300 tracker points, typically 4 ms apart")
    assert not (tmp_path / "r3").exists()


def test_a_point_beyond_the_tolerance_is_named_with_its_gap(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = tmp_path / "late.mcap"
    lags = [10_000_000] * 20
    lags[6] = 80_000_000
    _campaign_bag(bag, lags)
    assert main(["calibrate", str(bag), "--robot", "paper_arm"]) == 0
    captured = capsys.readouterr()
    assert captured.err.splitlines() == [
        f"warning: {bag}: 1 of 20 points on /tracker/point have no /joint_states message within the pairing "
        "tolerance of 50 ms and were dropped (pose 7 of 20: the /joint_states message nearest to its "
        "/tracker/point stamp is 80 ms away)"
    ]
    assert "19 poses" in captured.out


# --------------------------------------------------------------------- replay defaults


@pytest.mark.parametrize("bag", [BASE_BAG, TRACKER_BAG])
def test_replay_default_window_finds_every_dwell_of_the_shipped_bags(bag: Path) -> None:
    model = load_robot_model(PAPER_ARM)
    truth = read_raw_truth(bag)
    result = replay_bag(bag, model, calibrate=False, auto_window=True)
    assert len(result.samples) == len(truth.windows)
    assert 0.05 < result.collector.window_s < 0.5  # 0.3 s dwells: the window was shortened


def test_replay_default_window_on_a_realistic_recording(tmp_path: Path) -> None:
    model = load_robot_model(PAPER_ARM)
    bag = tmp_path / "realistic.mcap"
    sim = simulate_campaign(model, SimulationSettings(n_poses=10), seed=3)
    settings = RawBagSettings(joint_rate_hz=125, tracker_rate_hz=500, dropout_rate_hz=0.5, dropout_s=(0.02, 0.3))
    write_raw_bag(bag, sim, settings, seed=5)
    result = replay_bag(bag, model, calibrate=False, auto_window=True)
    assert len(result.samples) == 10
    assert result.collector.window_s == 0.5  # 2 s dwells keep the default window


def test_replay_cli_defaults_find_the_poses(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["replay", str(BASE_BAG), "--robot", "paper_arm", "--test-joints", *JOINTS, "--degrees"]
    assert main([*argv, "--out", str(tmp_path / "r"), *QUICK]) == 0
    out = capsys.readouterr().out
    assert "30 static poses found (window 0.118 s, auto, from the joints' still intervals)" in out


@pytest.mark.parametrize(
    ("extra", "robot", "message"),
    [
        (
            ["--window-s", "0.5"],
            "paper_arm",
            "0 static poses found: the longest still window of the joints was 0.304 s with 77 tracker points "
            "(--window-s 0.5, --joint-motion-threshold-rad 0.0005); try --window-s 0.12",
        ),
        (
            ["--tracker-frame", "laser"],
            "paper_arm",
            "0 static poses found: no tracker point is in frame 'laser' (points by frame: base_link (3300)): "
            "check --tracker-frame",
        ),
        ([], "ur10", "0 static poses found: no joint state carries the joints of robot ur10"),
    ],
)
def test_replay_without_poses_says_why_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], robot: str, message: str
) -> None:
    joints = ["0", "-1", "1", "0", "1", "0"] if robot == "ur10" else [*JOINTS, "--degrees"]
    argv = ["replay", str(BASE_BAG), "--robot", robot, "--test-joints", *joints, *extra]
    assert main([*argv, "--out", str(tmp_path / "r"), *QUICK]) == 1
    assert _error(capsys, "replay").startswith(f"{BASE_BAG}: {message}")


def test_replay_of_a_campaign_file_says_use_evaluate(
    campaign12: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["replay", str(campaign12), "--robot", "paper_arm", "--test-joints", *JOINTS, "--degrees"]
    assert main([*argv, "--out", str(tmp_path / "r"), *QUICK]) == 1
    assert _error(capsys, "replay") == (
        f"{campaign12}: 0 static poses found: this is a campaign file (one joint reading per pose), "
        "not a raw recording: use 'evaluate' on it"
    )


@pytest.mark.parametrize("command", ["calibrate", "evaluate", "validate", "map"])
def test_raw_recording_given_as_a_campaign_says_use_replay(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    """Pairing each streamed tracker point of a raw recording with a joint reading made
    thousands of moving "poses" and a nonsense calibration (31 mm RMS) reported as a result."""
    out = tmp_path / "r"
    argv = {
        "calibrate": ["calibrate", str(TRACKER_BAG), "--robot", "paper_arm"],
        "evaluate": _evaluate(TRACKER_BAG, "--out", str(out), *QUICK),
        "validate": ["validate", str(TRACKER_BAG), "--robot", "paper_arm", "--out", str(out), "--no-progress"],
        "map": ["map", str(TRACKER_BAG), "--robot", "paper_arm", "--out", str(out), "--no-progress"],
    }[command]
    assert main(argv) == 1
    assert _error(capsys, command) == (
        f"{TRACKER_BAG}: 1588 tracker points, typically 5 ms apart: this is a raw recording (a campaign has "
        "one point per static pose, seconds apart), not a campaign: use 'replay' on it"
    )
    assert not out.exists()


# --------------------------------------------------------------------- messages


def test_tab_separated_csv_is_read(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = tmp_path / "tabs.csv"
    csv.write_text("q1[deg]\tq2[deg]\tx[mm]\ty[mm]\tz[mm]\n1,5\t2\t100\t200\t300\n")
    out = tmp_path / "c.mcap"
    assert main(["import-csv", str(csv), "--out", str(out)]) == 0
    assert capsys.readouterr().out.startswith(f"wrote {out}: 1 pose, joints q1, q2")
    campaign = read_campaign(out)
    np.testing.assert_allclose(np.degrees(campaign.joint_positions), [[1.5, 2.0]])
    np.testing.assert_allclose(campaign.points, [[0.1, 0.2, 0.3]])


def test_csv_errors_count_data_rows_from_one_and_name_options(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    csv = tmp_path / "bad.csv"
    csv.write_text("joint1[rad],x[m],y[m],z[m]\n1,2,3,4\n1,nan,3,4\n")
    assert main(["import-csv", str(csv), "--out", str(tmp_path / "c.mcap")]) == 1
    assert f"{csv}: line 3 (data row 2): column 'x'" in _error(capsys, "import-csv")
    csv.write_text("joint1,x[m],y[m],z[m]\n1,2,3,4\n")
    assert main(["import-csv", str(csv), "--out", str(tmp_path / "c.mcap")]) == 1
    assert "--angle-unit" in _error(capsys, "import-csv")
    csv.write_text("a1[rad],a2[rad],x[m],y[m],z[m]\n1,2,3,4,5\n")
    assert main(["import-csv", str(csv), "--out", str(tmp_path / "c.mcap"), "--joint-columns", "a2,a1"]) == 0
    capsys.readouterr()


def test_ragged_joints_file_names_the_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "q.txt"
    path.write_text("# test joints, deg\n" + " ".join(JOINTS) + "\n1 2 3\n")
    assert main(["fk", "--robot", "paper_arm", "--joints-file", str(path), "--degrees"]) == 1
    assert _error(capsys, "fk") == f"joints file {path}, line 3: 3 values, the robot has 6 joints"


def test_robot_yaml_value_error_names_the_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "arm.yaml"
    bad.write_text(PAPER_ARM.read_text().replace("a: 428.052", "a: abc"))
    assert main(["fk", "--robot", str(bad), "--joints", *JOINTS, "--degrees"]) == 1
    assert _error(capsys, "fk") == f"robot config {bad}: joint 3 a must be a number, got 'abc'"
