"""CLI: what used to be silently overridden, ignored or unnoticed is now said (issue 18).

Each case ends in one line: ``robocal-uncertainty CMD: error: ...`` with exit status 1, or a
``warning:``/note line with the run going on.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml

from robocal_uncertainty.bagio import write_campaign
from robocal_uncertainty.cli import main
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model
from robocal_uncertainty.core.robot_model import rpy_to_matrix
from robocal_uncertainty.core.simulation import SimulationSettings, simulate_campaign

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "config" / "paper_arm.yaml"
TRIALS = ["--trials", "400"]


def _error(capsys: pytest.CaptureFixture[str], command: str) -> str:
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    prefix = f"robocal-uncertainty {command}: error: "
    assert lines[0].startswith(prefix), lines[0]
    return lines[0][len(prefix) :]


@pytest.fixture(scope="module")
def two_series(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """One simulated robot, tracker frame: 40 training poses, 30 validation poses in the same
    set-up, and the same 30 poses measured after the tracker moved by 20 mm and 5 mrad."""
    model = load_robot_model(PAPER)
    sim = simulate_campaign(model, SimulationSettings(n_poses=70, frame="tracker"), seed=7).campaign
    train, same = sim.subset(np.arange(40)), sim.subset(np.arange(40, 70))
    rot = rpy_to_matrix(np.array([0.003, 0.0, -0.004]))
    moved = dataclasses.replace(same, points=same.points @ rot.T + np.array([0.012, -0.016, 0.0]))
    out = tmp_path_factory.mktemp("series")
    paths = {"train": out / "train.mcap", "same": out / "same.mcap", "moved": out / "moved.mcap"}
    for key, campaign in (("train", train), ("same", same), ("moved", moved)):
        write_campaign(paths[key], campaign)
    return paths


def test_validate_refuses_a_split_option_with_a_validation_campaign(two_series, tmp_path, capsys) -> None:
    capsys.readouterr()
    argv = ["validate", str(two_series["train"]), "--robot", "paper_arm", "--validation-campaign"]
    argv += [str(two_series["same"]), "--train-poses", "20", "--out", str(tmp_path / "v"), *TRIALS]
    assert main(argv) == 1
    assert _error(capsys, "validate") == (
        "--train-poses splits the campaign, --validation-campaign holds out a second campaign whole and "
        "trains on the first whole: give one or the other"
    )
    assert not (tmp_path / "v").exists()


def test_validate_refuses_a_validation_campaign_of_a_moved_tracker(two_series, tmp_path, capsys) -> None:
    capsys.readouterr()
    argv = ["validate", str(two_series["train"]), "--robot", "paper_arm", "--validation-campaign"]
    argv += [str(two_series["moved"]), "--out", str(tmp_path / "v"), *TRIALS]
    assert main(argv) == 1
    msg = _error(capsys, "validate")
    assert msg.startswith("the validation campaign was measured in another set-up than the calibration campaign")
    # The simulated move: 5 mrad, and the points' centroid displaced by the rotation and the 20 mm.
    mm, mrad = (float(v) for v in msg.split("the measured points sit ")[1].split(" mrad")[0].split(" mm and "))
    assert mrad == pytest.approx(5.0, abs=0.05)
    assert 10.0 < mm < 40.0
    assert not (tmp_path / "v").exists()


def test_validate_of_the_same_set_up_states_the_frame_check(two_series, tmp_path, capsys) -> None:
    capsys.readouterr()
    argv = ["validate", str(two_series["train"]), "--robot", "paper_arm", "--validation-campaign"]
    argv += [str(two_series["same"]), "--out", str(tmp_path / "v"), *TRIALS]
    assert main(argv) == 0
    out = capsys.readouterr().out
    (line,) = [x for x in out.splitlines() if x.startswith("validation campaign's frame:")]
    assert "within the stated uncertainty; the measured points sit" in line
    assert "(campaign, 1 fold(s), 30 held-out measurements" in out


def test_a_robot_yaml_typo_is_an_error_naming_the_close_match(tmp_path, capsys) -> None:
    data = yaml.safe_load(PAPER.read_text(encoding="utf-8"))
    data["tool_piont"] = data.pop("tool_point")
    robot = tmp_path / "arm.yaml"
    robot.write_text(yaml.safe_dump(data), encoding="utf-8")
    capsys.readouterr()
    assert main(["fk", "--robot", str(robot), "--joints", "0", "0", "0", "0", "0", "0"]) == 1
    assert _error(capsys, "fk") == (
        f"{robot}: unknown top-level field 'tool_piont' (did you mean 'tool_point'?) "
        "(known: base, convention, hayati_beta_joints, joints, name, tool_point, units)"
    )


def test_calibrate_says_when_the_known_base_is_replaced(two_series, capsys) -> None:
    """paper_arm states its base known at the tracker origin; the simulated tracker stands 2.08 m away."""
    capsys.readouterr()
    assert main(["calibrate", str(two_series["train"]), "--robot", "paper_arm"]) == 0
    out = capsys.readouterr().out
    (line,) = [x for x in out.splitlines() if "known base" in x]
    assert line.strip().startswith("warning: the robot config's known base is 20")
    assert "set base.known: false in the robot config" in line


def test_fk_refuses_joints_and_a_joints_file_together(tmp_path, capsys) -> None:
    joints = tmp_path / "q.txt"
    joints.write_text("0 -2 1 0 1 0\n", encoding="utf-8")
    capsys.readouterr()
    assert (
        main(["fk", "--robot", "paper_arm", "--joints-file", str(joints), "--joints", "0", "-2", "1", "0", "1", "0"])
        == 1
    )
    assert (
        _error(capsys, "fk")
        == f"give --joints or --joints-file, not both (--joints-file {joints} and 6 --joints values)"
    )


def test_fk_of_a_nominal_model_never_labels_base_points_as_the_measurement_frame(capsys) -> None:
    """ur10: base unknown in the tracker frame, so the nominal model has no measurement-frame
    points: refused. paper_arm: the config states the base known at the tracker's origin, so the
    points are the base frame's, and now carry the measurement frame's name (they carried the
    base frame's name under the words "measurement frame")."""
    capsys.readouterr()
    assert main(["fk", "--robot", "ur10", "--joints", "0", "-2", "1", "0", "1", "0", "--frame", "measurement"]) == 1
    assert _error(capsys, "fk") == (
        "the ur10 model's base is unknown in the measurement frame laser_tracker (base.known: false) and the "
        "nominal model cannot place it: give a calibration of a campaign measured in that frame, or --frame base"
    )
    joints = ["--joints", "0", "-2", "1", "0", "1", "0"]
    assert main(["fk", "--robot", "paper_arm", *joints, "--frame", "measurement"]) == 0
    measurement = capsys.readouterr().out.splitlines()
    assert measurement[0].endswith("in frame laser_tracker (measurement frame), mm")
    assert main(["fk", "--robot", "paper_arm", *joints, "--frame", "base"]) == 0
    base = capsys.readouterr().out.splitlines()
    assert base[0].endswith("in frame base_link (base frame), mm")
    assert measurement[2] == base[2]  # the same numbers: the frames coincide by the config


def test_a_second_command_on_the_same_out_refuses_while_the_first_runs(two_series, tmp_path, capsys) -> None:
    """A real second process claims --out (as a running 'validate' does before its work): this
    command refuses, --force or not, and writes nothing there; once that process is gone its
    lock is stale and the command runs."""
    import subprocess
    import sys

    out = tmp_path / "report"
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time\n"
            "from robocal_uncertainty.app.output_paths import claim_report_directory\n"
            f"claim_report_directory({str(out)!r})\n"
            "print('claimed', flush=True)\n"
            "time.sleep(120)\n",
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "claimed"
        capsys.readouterr()
        argv = ["validate", str(two_series["train"]), "--robot", "paper_arm", "--out", str(out), *TRIALS]
        for force in ([], ["--force"]):
            assert main([*argv, *force]) == 1
            assert _error(capsys, "validate") == (
                f"report directory --out {out} is being written by another command (process {holder.pid}, "
                "lock file .robocal-uncertainty.lock): wait for it to finish, or give another --out"
            )
        assert [p.name for p in out.iterdir()] == [".robocal-uncertainty.lock"]
    finally:
        holder.kill()
        holder.wait()
    assert main(argv) == 0
    assert (out / "validation.json").is_file()
    assert not (out / ".robocal-uncertainty.lock").exists()  # released when the command ended


UR10_CSV = ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv"


def test_validate_on_the_real_ur10_series_tells_the_same_set_up_from_a_moved_tracker(tmp_path, capsys) -> None:
    """The UR10 series split at random into two halves of one set-up: the second validates the
    first (rigid fit 0.045 mm and 0.09 mrad, far within the stated 0.65 mm). The same half with
    the tracker turned by 0.35 rad and moved by 1.27 m: refused, naming the move."""
    from robocal_uncertainty.bagio import read_campaign

    if not UR10_CSV.exists():
        pytest.skip("UR10 data not present")
    whole = tmp_path / "ur10.mcap"
    assert main(["import-csv", str(UR10_CSV), "--out", str(whole)]) == 0
    campaign = read_campaign(whole)
    perm = np.random.default_rng(0).permutation(campaign.n_poses)
    train, held = campaign.subset(np.sort(perm[:316])), campaign.subset(np.sort(perm[316:]))
    rot = rpy_to_matrix(np.array([0.0, 0.0, 0.35]))
    moved = dataclasses.replace(held, points=held.points @ rot.T + np.array([1.2, -0.4, 0.05]))
    paths = {name: tmp_path / f"{name}.mcap" for name in ("train", "held", "moved")}
    for name, c in (("train", train), ("held", held), ("moved", moved)):
        write_campaign(paths[name], c)
    capsys.readouterr()
    argv = ["validate", str(paths["train"]), "--robot", "ur10", "--trials", "500", "--validation-campaign"]
    assert main([*argv, str(paths["held"]), "--out", str(tmp_path / "same")]) == 0
    (line,) = [x for x in capsys.readouterr().out.splitlines() if x.startswith("validation campaign's frame:")]
    mm, mrad = (float(v) for v in line.split("points sit ")[1].split(" mrad")[0].split(" mm and "))
    assert mm < 0.1 and mrad < 0.2  # the residual model error (0.4 mm RMS) averaged over 316 points
    assert main([*argv, str(paths["moved"]), "--out", str(tmp_path / "moved")]) == 1
    msg = _error(capsys, "validate")
    mm, mrad = (float(v) for v in msg.split("points sit ")[1].split(" mrad")[0].split(" mm and "))
    assert mrad == pytest.approx(350.0, abs=0.5)
    assert 1000.0 < mm < 2000.0
    assert "RMS error" in msg and "0.40" in msg.split("before the fit, ")[1]  # after the fit: the model error
