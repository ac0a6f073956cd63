"""``robocal-uncertainty suggest`` (issue 12): the printed table, the JSON and the CSV carry the
numbers of :func:`suggest_poses` called directly; the same seed gives the same output; careless
input ends in one line on stderr with exit status 1 (2 for argparse usage errors)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.app import suggest_poses
from robocal_uncertainty.bagio import read_campaign
from robocal_uncertainty.cli import PAPER_TEST_JOINTS_DEG, main
from robocal_uncertainty.core import EncoderNoise, TrackerNoise, load_robot_model
from robocal_uncertainty.core.robot_formats.robot_yaml import resolve_robot_config
from robocal_uncertainty.uncertainty import UncertaintySettings

ROOT = Path(__file__).resolve().parents[1]
UR10_CSV = ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv"
JOINTS = [str(v) for v in PAPER_TEST_JOINTS_DEG]
SECOND = ["30", "-180", "45", "10", "-20", "5"]
TEST_Q = np.radians([PAPER_TEST_JOINTS_DEG, [float(v) for v in SECOND]])


@pytest.fixture(scope="module")
def campaign20(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("suggest") / "c20.mcap"
    assert main(["simulate", "--out", str(path), "--poses", "20", "--seed", "3"]) == 0
    return path


@pytest.fixture(scope="module")
def paper_arm():
    return load_robot_model(resolve_robot_config("paper_arm"))


def _suggest(campaign: Path, *extra: str) -> list[str]:
    return [
        "suggest",
        str(campaign),
        "--robot",
        "paper_arm",
        "--test-joints",
        *JOINTS,
        *SECOND,
        "--degrees",
        *extra,
    ]


def _table(out: str, n_joints: int) -> dict[str, list[str]]:
    """Rows of the printed table by rank ("now", "1", ...): the cells after the rank."""
    lines = out.splitlines()
    start = next(i for i, line in enumerate(lines) if line.split()[:1] == ["rank"])
    assert set(lines[start + 1].replace(" ", "")) == {"-"}
    rows = {}
    for line in lines[start + 2 :]:
        cells = line.split()
        if not cells or not (cells[0] == "now" or cells[0].isdigit()):
            break
        rows[cells[0]] = cells[1:]
    assert len(rows["now"]) == 2  # no joints on the campaign's own row
    assert all(len(cells) == n_joints + 2 for rank, cells in rows.items() if rank != "now")
    return rows


def _um(value: float | None) -> str:
    return "-" if value is None else f"{value * 1e6:.3f}"


def _error(capsys: pytest.CaptureFixture[str]) -> str:
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    prefix = "robocal-uncertainty suggest: error: "
    assert lines[0].startswith(prefix), lines[0]
    assert "Next-best poses" not in captured.out
    return lines[0][len(prefix) :]


def test_printed_json_and_csv_numbers_are_those_of_suggest_poses(
    campaign20: Path, paper_arm, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out_json, out_csv = tmp_path / "s.json", tmp_path / "s.csv"
    argv = _suggest(campaign20, "--count", "3", "--candidates", "150", "--check", "2", "--trials", "300")
    argv += ["--seed", "7", "--encoder-noise-deg", "0.01", "--json", str(out_json), "--csv", str(out_csv)]
    capsys.readouterr()
    assert main(argv) == 0
    printed = capsys.readouterr()
    assert printed.err == ""
    # The noise as the command line converts it (5.0 um * 1e-6 is one ulp off 5e-6: the Monte Carlo
    # numbers below are compared exactly).
    settings = UncertaintySettings(
        tracker_noise=TrackerNoise(a=5.0 * 1e-6, b=0.0 * 1e-6),
        encoder_noise=EncoderNoise(half_width=float(np.radians(0.01))),
    )
    direct = suggest_poses(
        paper_arm,
        read_campaign(campaign20),
        TEST_Q,
        settings=settings,
        n_candidates=150,
        count=3,
        monte_carlo_check=2,
        trials=300,
        seed=7,
        backend="auto",  # the command's default
    )
    assert len(direct.suggestions) == 3
    assert direct.suggestions[0].monte_carlo_u_m is not None and direct.suggestions[2].monte_carlo_u_m is None

    rows = _table(printed.out, paper_arm.n_joints)
    assert rows["now"] == [_um(direct.current_u_m), _um(direct.monte_carlo_current_u_m)]
    for rank, s in enumerate(direct.suggestions, start=1):
        cells = rows[str(rank)]
        assert cells[:-2] == [f"{v:.4f}" for v in np.degrees(s.joint_positions)]
        assert cells[-2:] == [_um(s.predicted_u_m), _um(s.monte_carlo_u_m)]
    assert "joint1 / deg" in printed.out and "predicted RMS u_pos / µm" in printed.out
    assert "Monte Carlo: 300 trials, random seed 7" in printed.out

    data = json.loads(out_json.read_text())
    assert data["joint_names"] == list(paper_arm.joint_names)
    assert data["current_rms_u_pos_m"] == direct.current_u_m
    assert data["monte_carlo_current_rms_u_pos_m"] == direct.monte_carlo_current_u_m
    assert data["monte_carlo_trials"] == 300 and data["seed"] == 7
    assert data["candidates"] == {"file": None, "count": 150, "seed": 7}
    assert data["encoder_noise_half_width_rad"] == pytest.approx(np.radians(0.01), rel=1e-15)
    np.testing.assert_allclose(data["test_joint_positions_rad"], TEST_Q, rtol=0, atol=1e-15)
    assert [s["rank"] for s in data["suggestions"]] == [1, 2, 3]
    for entry, s in zip(data["suggestions"], direct.suggestions):
        assert entry["joint_positions_rad"] == s.joint_positions.tolist()
        np.testing.assert_allclose(entry["joint_positions_deg"], np.degrees(s.joint_positions), rtol=1e-15)
        assert entry["predicted_rms_u_pos_m"] == s.predicted_u_m
        assert entry["monte_carlo_rms_u_pos_m"] == s.monte_carlo_u_m
        assert entry["reduction_m2"] == s.reduction_m2
    # Each added pose lowers the first-order uncertainty.
    predicted = [s["predicted_rms_u_pos_m"] for s in data["suggestions"]]
    assert data["current_rms_u_pos_m"] > predicted[0] > predicted[1] > predicted[2]

    # The CSV holds the joint rows in degrees (--degrees), exactly, and reads back as a joints file.
    lines = out_csv.read_text().splitlines()
    assert lines[0].startswith("#") and "joint positions in deg" in lines[0]
    assert lines[1] == ",".join(f"{name}_deg" for name in paper_arm.joint_names)
    csv_q = np.array([[float(v) for v in line.split(",")] for line in lines[2:]])
    np.testing.assert_array_equal(csv_q, np.degrees([s.joint_positions for s in direct.suggestions]))
    capsys.readouterr()
    assert main(["fk", "--robot", "paper_arm", "--joints-file", str(out_csv), "--degrees"]) == 0
    assert len(capsys.readouterr().out.strip().splitlines()) == 2 + 3


def test_same_seed_same_output_other_seed_other_candidates(
    campaign20: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    outputs = []
    for seed, name in (("4", "a"), ("4", "b"), ("5", "c")):
        path = tmp_path / f"{name}.json"
        capsys.readouterr()
        assert (
            main(_suggest(campaign20, "--count", "2", "--candidates", "80", "--seed", seed, "--json", str(path))) == 0
        )
        out = capsys.readouterr().out.replace(str(path), "OUT")
        outputs.append((out, json.loads(path.read_text())))
    assert outputs[0] == outputs[1]
    assert "(random seed 4)" in outputs[0][0]
    first = [s["joint_positions_rad"] for s in outputs[0][1]["suggestions"]]
    other = [s["joint_positions_rad"] for s in outputs[2][1]["suggestions"]]
    assert first != other
    # The campaign's own first-order uncertainty does not depend on the candidates.
    assert outputs[0][1]["current_rms_u_pos_m"] == outputs[2][1]["current_rms_u_pos_m"]


def test_candidates_file_ranks_its_rows(
    campaign20: Path, paper_arm, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rng = np.random.default_rng(2)
    low, high = paper_arm.joint_limits[:, 0] + 0.1, paper_arm.joint_limits[:, 1] - 0.1
    q = low + (high - low) * rng.random((12, paper_arm.n_joints))
    path = tmp_path / "candidates.txt"
    path.write_text("# radians\n" + "\n".join(" ".join(repr(float(v)) for v in row) for row in q) + "\n")
    out = tmp_path / "s.json"
    argv = ["suggest", str(campaign20), "--robot", "paper_arm", "--test-joints", *JOINTS, "--degrees"]
    capsys.readouterr()
    # --degrees applies to the candidates file too: radians read as degrees are another set.
    assert main([*argv, "--candidates-file", str(path), "--count", "4", "--json", str(out)]) == 1
    assert _error(capsys).startswith(f"{path}: candidate 1 of 12: joint ")
    argv = ["suggest", str(campaign20), "--robot", "paper_arm", "--test-joints-file"]
    tests = tmp_path / "tests.csv"
    tests.write_text(",".join(JOINTS) + "\n")
    qdeg = tmp_path / "candidates_deg.txt"
    qdeg.write_text("\n".join(",".join(repr(float(v)) for v in row) for row in np.degrees(q)) + "\n")
    argv += [str(tests), "--degrees", "--candidates-file", str(qdeg), "--count", "4", "--json", str(out)]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert f"ranked among the 12 configurations of {qdeg}" in printed
    data = json.loads(out.read_text())
    assert data["candidates"] == {"file": str(qdeg), "count": 12, "seed": None}
    direct = suggest_poses(
        paper_arm, read_campaign(campaign20), TEST_Q[:1], candidates=np.radians(np.degrees(q)), count=4
    )
    assert [s["joint_positions_rad"] for s in data["suggestions"]] == [
        s.joint_positions.tolist() for s in direct.suggestions
    ]
    assert [s["predicted_rms_u_pos_m"] for s in data["suggestions"]] == [s.predicted_u_m for s in direct.suggestions]
    # Every suggestion is one of the file's rows, none twice.
    rows = [int(np.argmin(np.abs(q - np.array(s["joint_positions_rad"])).sum(axis=1))) for s in data["suggestions"]]
    assert len(set(rows)) == 4
    np.testing.assert_allclose([data["suggestions"][k]["joint_positions_rad"] for k in range(4)], q[rows], atol=1e-12)


def test_on_the_shipped_ur10_data(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    campaign = tmp_path / "ur10.mcap"
    assert main(["import-csv", str(UR10_CSV), "--out", str(campaign)]) == 0
    test_q = [0.934319, -1.79251, 1.5196, 0.272862, 0.934269, -1.57075]
    out = tmp_path / "s.json"
    argv = ["suggest", str(campaign), "--robot", "ur10", "--test-joints", *map(str, test_q)]
    capsys.readouterr()
    assert main([*argv, "--count", "2", "--candidates", "60", "--json", str(out)]) == 0
    printed = capsys.readouterr()
    assert printed.err == ""
    assert "Next-best poses for ur10 (632 poses measured)" in printed.out
    assert "shoulder_pan_joint / rad" in printed.out
    model = load_robot_model(resolve_robot_config("ur10"))
    direct = suggest_poses(
        model, read_campaign(campaign).reorder_joints(model.joint_names), [test_q], n_candidates=60, count=2
    )
    rows = _table(printed.out, model.n_joints)
    assert rows["now"] == [_um(direct.current_u_m), "-"]
    for rank, s in enumerate(direct.suggestions, start=1):
        assert rows[str(rank)] == [*(f"{v:.6f}" for v in s.joint_positions), _um(s.predicted_u_m), "-"]
    data = json.loads(out.read_text())
    assert data["frame_id"] == direct.frame_id == "laser_tracker"
    assert data["monte_carlo_trials"] == 0 and data["monte_carlo_current_rms_u_pos_m"] is None
    assert [s["predicted_rms_u_pos_m"] for s in data["suggestions"]] == [s.predicted_u_m for s in direct.suggestions]


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (["--count", "0"], "--count must be a positive integer, got 0"),
        (["--candidates", "-3"], "--candidates must be a positive integer, got -3"),
        (["--check", "-1"], "--check must be an integer >= 0, got -1"),
        (["--check", "3", "--count", "2"], "--check 3 is more than the --count 2 suggestions"),
        (["--count", "20", "--candidates", "10"], "--count 20 is more than the --candidates 10 drawn"),
        (["--trials", "0", "--check", "1"], "--trials must be a positive integer, got 0"),
        (["--lambda", "big"], "--lambda must be 'auto', 'gcv' or a number, got 'big'"),
        (["--sources", "tracker,gremlins"], "unknown uncertainty source(s) ['gremlins']"),
    ],
)
def test_bad_options_are_one_line(
    campaign20: Path, extra: list[str], expected: str, capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    assert main(_suggest(campaign20, *extra)) == 1
    assert _error(capsys).startswith(expected)


def test_careless_input_is_one_line(campaign20: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    base = ["suggest", str(campaign20), "--robot", "paper_arm"]
    capsys.readouterr()
    assert main(base) == 1
    assert _error(capsys) == "give --test-joints or --test-joints-file"
    # Test joints typed in degrees without --degrees.
    assert main([*base, "--test-joints", *JOINTS]) == 1
    assert _error(capsys).endswith("did you mean --degrees?")
    # A candidates file with a short row, and one with fewer rows than --count.
    bad = tmp_path / "bad.txt"
    bad.write_text(" ".join(JOINTS) + "\n" + " ".join(JOINTS[:5]) + "\n")
    assert main(_suggest(campaign20, "--candidates-file", str(bad))) == 1
    assert _error(capsys) == f"joints file {bad}, line 2: 5 values, the robot has 6 joints"
    few = tmp_path / "few.txt"
    few.write_text(" ".join(JOINTS) + "\n")
    assert main(_suggest(campaign20, "--candidates-file", str(few))) == 1
    assert _error(capsys) == f"--count 5 is more than the 1 configuration in --candidates-file {few}"
    # Outputs: an existing file without --force, the campaign itself, --json and --csv alike.
    existing = tmp_path / "exists.json"
    existing.write_text("{}")
    assert main(_suggest(campaign20, "--json", str(existing))) == 1
    assert _error(capsys) == f"--json {existing} exists already (give --force to replace it)"
    assert existing.read_text() == "{}"
    assert main(_suggest(campaign20, "--csv", str(campaign20), "--force")) == 1
    assert _error(capsys) == f"--csv {campaign20} is the campaign being read"
    same = tmp_path / "same"
    assert main(_suggest(campaign20, "--json", str(same), "--csv", str(same))) == 1
    assert _error(capsys) == f"--json and --csv name the same file {same}"
    assert not same.exists()
    # A missing campaign.
    assert main(_suggest(tmp_path / "missing.mcap")) == 1
    assert str(tmp_path / "missing.mcap") in _error(capsys)


def test_candidates_and_candidates_file_exclude_each_other(
    campaign20: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as done:
        main(_suggest(campaign20, "--candidates", "10", "--candidates-file", str(tmp_path / "q.txt")))
    assert done.value.code == 2
    assert "not allowed with argument" in capsys.readouterr().err


def test_a_six_dof_campaign_is_refused_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    campaign = tmp_path / "ur10_6dof.mcap"
    argv = ["import-csv", str(UR10_CSV), "--orientation-convention", "intrinsic_xyz", "--out", str(campaign)]
    assert main(argv) == 0
    capsys.readouterr()
    test_q = ["0.934319", "-1.79251", "1.5196", "0.272862", "0.934269", "-1.57075"]
    assert main(["suggest", str(campaign), "--robot", "ur10", "--test-joints", *test_q]) == 1
    assert _error(capsys).startswith("next-best poses need point measurements, got ")
