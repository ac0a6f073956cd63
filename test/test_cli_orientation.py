"""Orientation rows in the console table of ``evaluate`` (issue 8): per axis rx, ry, rz the
standard and expanded uncertainty and the coverage interval in mrad, equal to the result
object's values; "undetermined" cells and the undetermined rotation named for a point campaign."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from robocal_uncertainty import app
from robocal_uncertainty.cli import PAPER_TEST_JOINTS_DEG, main
from robocal_uncertainty.report.table2 import format_table2, round_to_uncertainty

ROOT = Path(__file__).resolve().parents[1]
UR10_CSV = ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv"
UR10_TEST = ["0.934319", "-1.79251", "1.5196", "0.272862", "0.934269", "-1.57075"]
UR10_TEST_2 = ["1.44324", "-1.27933", "0.587473", "0.691467", "1.44312", "-1.57083"]
QUICK = ["--trials", "300", "--no-budget", "--no-sweeps", "--no-progress", "--seed", "2"]


@pytest.fixture
def captured(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """The Evaluation objects the command line's ``evaluate`` calls return."""
    results: list[Any] = []
    evaluate = app.evaluate

    def spy(*args: Any, **kwargs: Any) -> Any:
        results.append(evaluate(*args, **kwargs))
        return results[-1]

    monkeypatch.setattr(app, "evaluate", spy)
    return results


def _orientation_blocks(out: str) -> list[tuple[str, dict[str, list[str]], list[str]]]:
    """Per test configuration: (header line, rows by label -> [rx, ry, rz], undetermined lines)."""
    lines = out.splitlines()
    blocks = []
    for i, line in enumerate(lines):
        if not line.startswith("Tool orientation in frame "):
            continue
        assert lines[i + 1].split() == ["Quantity", "rx", "ry", "rz"]
        rows = {}
        for row in lines[i + 3 : i + 6]:
            label, cells = row[:27].strip(), row[27:].split()
            if label.startswith("Coverage interval"):
                cells = [" ".join(cells[k : k + 2]) for k in range(0, len(cells), 2)] if "(" in row else cells
            rows[label] = cells
        notes = []
        for row in lines[i + 6 :]:
            if not row.startswith("undetermined: "):
                break
            notes.append(row)
        blocks.append((line, rows, notes))
    return blocks


def _expected_rows(orientation: Any) -> dict[str, list[str]]:
    rows: dict[str, list[str]] = {
        "Standard uncertainty / mrad": [],
        "Expanded uncertainty / mrad": [],
        "Coverage interval / mrad": [],
    }
    for axis, determined in zip(orientation.axes, orientation.determined):
        if not determined:
            for cells in rows.values():
                cells.append("undetermined")
            continue
        u = axis.standard_uncertainty * 1e3
        rows["Standard uncertainty / mrad"].append(round_to_uncertainty(u, u))
        rows["Expanded uncertainty / mrad"].append(round_to_uncertainty(axis.expanded_uncertainty * 1e3, u))
        low, high = (round_to_uncertainty(v * 1e3, u) for v in (axis.interval.low, axis.interval.high))
        rows["Coverage interval / mrad"].append(f"({low}, {high})")
    return rows


def test_six_dof_campaign_prints_the_result_objects_orientation(
    tmp_path: Path, captured: list[Any], capsys: pytest.CaptureFixture[str]
) -> None:
    campaign = tmp_path / "ur10_6dof.mcap"
    argv = ["import-csv", str(UR10_CSV), "--orientation-convention", "intrinsic_xyz", "--out", str(campaign)]
    assert main(argv) == 0
    capsys.readouterr()
    argv = ["evaluate", str(campaign), "--robot", "ur10", "--test-joints", *UR10_TEST, *UR10_TEST_2]
    assert main([*argv, "--out", str(tmp_path / "report"), *QUICK]) == 0
    out = capsys.readouterr().out
    result = captured[-1].uncertainty
    assert len(result.poses) == 2
    blocks = _orientation_blocks(out)
    assert len(blocks) == 2
    for (header, rows, notes), pose in zip(blocks, result.poses):
        o = pose.orientation
        assert o is not None and o.fully_determined  # a 6-DOF probe determines every rotation
        quat = ", ".join(f"{v:.6f}" for v in o.mean_quaternion)
        assert header.startswith(f"Tool orientation in frame laser_tracker: mean quaternion (x, y, z, w) = ({quat})")
        assert "in mrad" in header
        assert rows == _expected_rows(o)
        assert notes == []
        # The numbers are rotation deviations of tens of µrad: the printed u is in mrad, not rad.
        u = [float(v) for v in rows["Standard uncertainty / mrad"]]
        np.testing.assert_allclose(u, [a.standard_uncertainty * 1e3 for a in o.axes], rtol=0.05)
        assert all(1e-3 < v < 10 for v in u)
    # The report holds the orientation rows and a rotation histogram figure per configuration.
    md = (tmp_path / "report" / "report.md").read_text(encoding="utf-8")
    assert md.count("Tool orientation: mean (chordal L2) quaternion") == 2
    for i in (1, 2):
        assert (tmp_path / "report" / f"rotation_histograms_{i}.png").stat().st_size > 10_000
        assert f"](rotation_histograms_{i}.png)" in md
    # The model-error line of a 6-DOF campaign states its rotation part in µrad, not µm.
    adequacy = next(line for line in out.splitlines() if line.startswith("Model adequacy"))
    if not result.model_adequacy.adequate:
        std = result.model_adequacy.standard_uncertainty
        assert f"rotation ({', '.join(f'{v * 1e6:.1f}' for v in std[3:])}) urad" in adequacy
    # ... and report.md in mrad (it printed all six values as µm)
    assert not result.model_adequacy.adequate  # the UR10's unmodelled errors: 0.2-0.3 mm, 0.6-0.7 mrad
    std = result.model_adequacy.standard_uncertainty
    rot = f"and rotation ({', '.join(f'{v * 1e3:.3f}' for v in std[3:])}) mrad, carried by the residual source"
    assert rot in md
    assert all(0.3e-3 < v < 1.5e-3 for v in std[3:]) and all(0.1e-3 < v < 0.4e-3 for v in std[:3])


def test_point_campaign_names_the_undetermined_tool_axis(
    tmp_path: Path, captured: list[Any], capsys: pytest.CaptureFixture[str]
) -> None:
    campaign = tmp_path / "c20.mcap"
    assert main(["simulate", "--out", str(campaign), "--poses", "20", "--seed", "5"]) == 0
    capsys.readouterr()
    joints = [str(v) for v in PAPER_TEST_JOINTS_DEG]
    argv = ["evaluate", str(campaign), "--robot", "paper_arm", "--test-joints", *joints, "--degrees"]
    assert main([*argv, "--out", str(tmp_path / "report"), *QUICK]) == 0
    out = capsys.readouterr().out
    o = captured[-1].uncertainty.poses[0].orientation
    [(header, rows, notes)] = _orientation_blocks(out)
    assert header.startswith("Tool orientation in frame base_link: mean quaternion")
    assert not o.fully_determined
    assert rows == _expected_rows(o)
    assert rows["Standard uncertainty / mrad"] == ["undetermined"] * 3  # the tool axis overlaps x, y and z here
    # The tool point lies on joint 6's axis: no rotation is determined (the unseen joint-6
    # parameters tilt the flange too), and one line says so instead of three arbitrary axes.
    assert o.undetermined_directions.shape == (3, 3)
    assert notes == [
        "undetermined: every rotation of the tool; no parameter the measurements see fixes its orientation "
        "(e.g. points on joint 6's axis see neither the rotation about it nor the flange tilt of the joint-6 "
        "parameters held at nominal), so rx, ry, rz carry no uncertainty statement"
    ]
    # Without orientation the table is the position table alone.
    assert "Tool orientation" not in format_table2(captured[-1].uncertainty, orientation=False)


def test_validate_prints_the_held_out_orientation_statistics(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    campaign = tmp_path / "ur10_6dof.mcap"
    argv = ["import-csv", str(UR10_CSV), "--orientation-convention", "intrinsic_xyz", "--out", str(campaign)]
    assert main(argv) == 0
    results: list[Any] = []
    validate = app.validate

    def spy(*args: Any, **kwargs: Any) -> Any:
        results.append(validate(*args, **kwargs))
        return results[-1]

    monkeypatch.setattr(app, "validate", spy)
    capsys.readouterr()
    out_dir = tmp_path / "validation"
    argv = ["validate", str(campaign), "--robot", "ur10", "--train-poses", "53", "--trials", "200"]
    assert main([*argv, "--out", str(out_dir), "--no-progress"]) == 0
    out = capsys.readouterr().out
    rotation = results[-1].orientation_axes
    assert [a.axis for a in rotation] == ["rx", "ry", "rz"]
    lines = out.splitlines()
    start = lines.index(
        next(line for line in lines if line.split()[:4] == ["axis", "RMS", "error", "/"] and "mrad" in line)
    )
    for line, a in zip(lines[start + 1 : start + 4], rotation):
        assert line.split() == [
            a.axis,
            f"{a.rms_error * 1e3:.4f}",
            f"{a.normalized_rms:.3f}",
            f"{100 * a.inside_fraction:.1f}",
        ]
    assert "reliability: stated p / observed % (x, y, z, 3-D, rx, ry, rz)" in out

    data = json.loads((out_dir / "validation.json").read_text())
    assert [a["rms_error_rad"] for a in data["orientation_axes"]] == [a.rms_error for a in rotation]
    assert data["reliability"]["observed"]["rz"] == rotation[2].reliability.tolist()
