"""Section report: JSON in SI with units, Markdown/CSV/PNG, the measured coverage stated."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.app.section_inspection import SectionInspection, section_demo
from robocal_uncertainty.inspection.section import PARAMETER_NAMES
from robocal_uncertainty.report.section_report import (
    COVERAGE_STUDY,
    SECTION_REPORT_FORMAT,
    format_section_table,
    write_section_report,
)


@pytest.fixture(scope="module")
def demo() -> SectionInspection:
    return section_demo(trials=4000, seed=3)


def test_demo_knows_its_truth_and_offsets_are_covered(demo: SectionInspection) -> None:
    assert demo.cloud.n_points == 1836
    assert demo.truth is not None and demo.truth.shape == (9,)
    outputs = demo.result.monte_carlo.outputs
    # Offsets and twist: well calibrated (coverage study 93.5-94.5 %); this draw is inside.
    for j in (2, 3, 4):
        assert outputs[j].probabilistically_symmetric.contains(float(demo.truth[j]))
    # Seed magnitudes: thickness u of order 1-2 um, chord GUM U of order 5 um.
    assert 1e-6 < outputs[0].standard_uncertainty < 2e-6
    assert 3e-6 < demo.result.gum.outputs[1].expanded_uncertainty < 6e-6
    # Bias correction: the max/min parameters' bias is positive and the reflected interval lies below.
    for fix, out in zip(demo.corrections, outputs):
        mc = out.probabilistically_symmetric
        assert fix.interval.low == pytest.approx(2 * fix.measured - mc.high, abs=1e-15)
        assert fix.interval.high == pytest.approx(2 * fix.measured - mc.low, abs=1e-15)
        assert fix.estimate == pytest.approx(fix.measured - fix.bias, abs=1e-15)
        if fix.recommended:
            assert fix.bias > 0, fix.name


def test_report_files_and_content(demo: SectionInspection, tmp_path: Path) -> None:
    files = write_section_report(demo.result, demo.corrections, tmp_path, truth=demo.truth, extra={"nominal": "r37"})
    data = json.loads(files.json.read_text())
    assert data["format"] == SECTION_REPORT_FORMAT
    assert data["units"] == {"length": "m", "angle": "rad"}
    assert data["n_trials"] == 4000 and data["seed"] == 3 and data["nominal"] == "r37"
    assert [row["name"] for row in data["parameters"]] == list(PARAMETER_NAMES)
    thickness = data["parameters"][0]
    mc = demo.result.monte_carlo.outputs[0]
    assert thickness["u"] == mc.standard_uncertainty and thickness["unit"] == "m"
    assert thickness["truth"] == pytest.approx(float(demo.truth[0]))
    assert set(thickness["budget"]) == {"mpe", "thermal", "probing", "algorithm"}
    budget = np.array(list(thickness["budget"].values()))
    assert np.sqrt((budget**2).sum()) == pytest.approx(thickness["gum_u"], rel=1e-9)
    assert thickness["coverage_study_jcgm101"] == COVERAGE_STUDY["max_thickness"][0]
    assert "under-cover" in data["coverage_note"] and "72.0%" in data["coverage_note"]
    markdown = files.markdown.read_text()
    assert "## Known limitation: coverage of the max/min-defined parameters" in markdown
    assert "| maximum thickness | 72.0% | 89.0% |" in markdown
    assert "| profile, pressure side | 0.0% | 7.5% |" in markdown
    assert "## GUM budget per source" in markdown
    with files.csv.open() as stream:
        rows = list(csv.DictReader(stream))
    assert [r["parameter"] for r in rows] == list(PARAMETER_NAMES)
    assert float(rows[1]["u"]) == pytest.approx(demo.result.monte_carlo.outputs[1].standard_uncertainty)
    assert files.histograms.stat().st_size > 10_000


def test_console_table_layout(demo: SectionInspection) -> None:
    table = format_section_table(demo.result, demo.corrections, truth=demo.truth).splitlines()
    assert table[0].startswith("parameter") and "bias-corrected interval" in table[0]
    assert sum("truth" in line for line in table) == 9
    thickness = table[2].split()
    assert thickness[:3] == ["maximum", "thickness", f"{demo.corrections[0].measured * 1e3:.4f}"]
