"""Warnings about the input (a truncated campaign recovered) reach report.json and the documents."""

from __future__ import annotations

import json

import pytest

from robocal_uncertainty.errors import InputError
from robocal_uncertainty.report import read_report_json, uncertainty_to_dict, write_report

TRUNCATED = "c.mcap is truncated (writer stopped before the footer); recovered 41 poses up to the last complete record"


def test_report_lists_input_warnings_first(setup, tmp_path) -> None:
    own = list(setup.result.warnings)
    out = write_report(tmp_path, setup.result, robot_name="paper_arm", embed_images=False, input_warnings=[TRUNCATED])
    report = read_report_json(out / "report.json")
    assert report["warnings"] == [TRUNCATED, *own]
    md = (out / "report.md").read_text(encoding="utf-8")
    section = md.split("## Warnings", 1)[1]
    assert TRUNCATED in section
    assert "None." not in section
    assert TRUNCATED in (out / "report.html").read_text(encoding="utf-8")


def test_without_input_warnings_the_report_is_unchanged(setup, tmp_path) -> None:
    out = write_report(tmp_path, setup.result, robot_name="paper_arm", embed_images=False)
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    assert report["warnings"] == list(setup.result.warnings)


def test_warnings_are_listed_once(setup) -> None:
    data = uncertainty_to_dict(setup.result, robot_name="arm", input_warnings=(TRUNCATED, TRUNCATED))
    assert data["warnings"].count(TRUNCATED) == 1


def test_bare_string_is_refused(setup) -> None:
    with pytest.raises(InputError, match="sequence of strings"):
        uncertainty_to_dict(setup.result, robot_name="arm", input_warnings=TRUNCATED)
