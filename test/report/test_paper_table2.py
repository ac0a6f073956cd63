"""The seed's published Table 2 as data, and its comparison with our result."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.report.references import ROBOT_PAPER_REFERENCE
from robocal_uncertainty.report.table2 import (
    PAPER_TABLE2,
    format_paper_comparison,
    paper_difference_note,
    round_to_uncertainty,
)

REPO = Path(__file__).resolve().parents[2]
SEED_NAME = "000_ccde7396bea0450c.txt"
SEED_CANDIDATES = (REPO / "shared" / "seeds" / SEED_NAME, REPO.parent / "shared" / "seeds" / SEED_NAME)
# Row labels of Table 2 in the seed text, in the order of PaperTable2Axis's fields.
LABELS = ("输出值/mm", "标准不确定度/mm", "扩展不确定度/mm", "包含区间/mm", "相对不确定度/%")


def _number(text: str) -> float:
    # The seed groups decimals in threes with a space: "228.919 5".
    return float(text.replace(" ", ""))


def _seed_table2() -> dict[str, list[object]]:
    path = next((p for p in SEED_CANDIDATES if p.is_file()), None)
    if path is None:
        pytest.skip("seed text not available (checkout without shared/)")
    rows = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        cells = line.split("\t")
        if cells[0] in LABELS:
            assert cells[0] not in rows, f"Table 2 row {cells[0]} found twice"
            assert len(cells) == 4, line
            rows[cells[0]] = cells[1:]
    assert set(rows) == set(LABELS)
    columns: dict[str, list[object]] = {}
    for i, axis in enumerate("xyz"):
        values: list[object] = []
        for label in LABELS:
            cell = rows[label][i].strip()
            if label.startswith("包含区间"):
                low, high = cell.strip("()").split(",")
                values.append((_number(low), _number(high)))
            else:
                values.append(_number(cell))
        columns[axis] = values
    return columns


def test_seed_table2_equals_the_seed_text():
    seed = _seed_table2()
    assert list(PAPER_TABLE2) == ["x", "y", "z"]
    for axis, (value, u, big_u, interval, relative) in seed.items():
        row = PAPER_TABLE2[axis]
        assert row.output_value == value
        assert row.standard_uncertainty == u
        assert row.expanded_uncertainty == big_u
        assert row.coverage_interval == interval
        assert row.relative_uncertainty == relative


def test_seed_table2_facts_stated_in_the_comment():
    for row in PAPER_TABLE2.values():
        # U/u = 2.6 on every axis; relative uncertainty = 100 U/|y| (to the printed digits).
        assert row.expanded_uncertainty / row.standard_uncertainty == pytest.approx(2.6, abs=2e-3)
        assert 100 * row.expanded_uncertainty / abs(row.output_value) == pytest.approx(
            row.relative_uncertainty, abs=1.1e-4
        )
    # x and y intervals reach beyond sqrt(39) u from the mean (Cantelli's bound for a 95 %
    # probabilistically symmetric interval); z stays within it.
    reach = {
        axis: max(abs(end - row.output_value) for end in row.coverage_interval) / row.standard_uncertainty
        for axis, row in PAPER_TABLE2.items()
    }
    assert reach["x"] > math.sqrt(39) and reach["y"] > math.sqrt(39)
    assert reach["z"] < math.sqrt(39)
    assert max(reach.values()) == pytest.approx(10.67, abs=0.01)


def test_format_paper_comparison_shows_both(setup):
    result = setup.result
    text = format_paper_comparison(result)
    lines = text.splitlines()
    assert lines[0] == "Jiang et al. Table 2 (real arm) / this run (test configuration 1), mm"
    head = lines.index(next(line for line in lines if line.startswith("Axis")))
    assert " ".join(" ".join(lines[1:head]).split()) == f"({ROBOT_PAPER_REFERENCE})"
    assert lines[head].split()[-1] == "Jiang/ours"  # column "u Jiang/ours": never "seed", the random seed's word
    pose = result.poses[0]
    for axis, ours in zip("xyz", pose.axes):
        seed = PAPER_TABLE2[axis]
        row = next(line for line in lines if line.startswith(axis + " "))
        u = ours.standard_uncertainty * 1e3
        low = round_to_uncertainty(ours.interval.low * 1e3, u)
        high = round_to_uncertainty(ours.interval.high * 1e3, u)
        for needle in (
            f"{seed.output_value:.4f} / {round_to_uncertainty(ours.estimate * 1e3, u)}",
            f"{seed.standard_uncertainty:.4f} / {round_to_uncertainty(u, u)}",
            f"{seed.expanded_uncertainty:.4f} / {round_to_uncertainty(ours.expanded_uncertainty * 1e3, u)}",
            f"({seed.coverage_interval[0]:.4f}, {seed.coverage_interval[1]:.4f}) / ({low}, {high})",
        ):
            assert needle in row
        # Ratio of the two u, two significant digits.
        assert float(row.split()[-1]) == pytest.approx(seed.standard_uncertainty / u, rel=0.06)
    # Short: title, reference, grid (column names, rule, 3 rows), then the wrapped note.
    assert " ".join(lines[head + 5 :]) == " ".join(paper_difference_note().split())
    assert "seed" not in text.lower()
    assert len(format_paper_comparison(result, note=False).splitlines()) == head + 5
    assert all(len(line) <= 120 for line in lines)


def test_the_paper_is_named_as_its_text_names_it():
    """Authors, title and DOI of the printed reference, as in the paper's own text."""
    path = next((p for p in SEED_CANDIDATES if p.is_file()), None)
    if path is None:
        pytest.skip("seed text not available (checkout without shared/)")
    text = path.read_text(encoding="utf-8")
    assert "Uncertainty evaluation of calibration model of six DOF robot arm" in text
    assert "Jiang Wensong¹, Li Xuan¹, Luo Zai¹, Yang Li², Guo Bin¹" in text
    assert "DOI: 10.19650/j.cnki.cjsi.J2209613" in text
    assert ROBOT_PAPER_REFERENCE.startswith("Jiang W., Li X., Luo Z., Yang L., Guo B., 'Uncertainty evaluation of ")
    assert "six DOF robot arm'" in ROBOT_PAPER_REFERENCE and "J2209613" in ROBOT_PAPER_REFERENCE


def test_format_paper_comparison_rejects_a_bad_pose(setup):
    for bad in (1, -1, True, "0"):
        with pytest.raises(ConfigError):
            format_paper_comparison(setup.result, pose=bad)


def test_paper_difference_note_is_measured_not_a_placeholder():
    note = paper_difference_note()
    assert "placeholder" not in note.lower() and "todo" not in note.lower()
    assert note.count(". ") + 1 <= 2  # one or two sentences
    for needle in ("0.01-0.04 mm", "0.03 mm", "0.5 mm"):
        assert needle in note
