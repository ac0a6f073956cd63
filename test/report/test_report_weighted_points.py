"""A calibration of points weighted by a stated instrument std reaches the reports.

A point measurement holds its std as a tuple (a pose measurement as an array); the JSON and
Markdown writers once called ``.tolist()`` on it and failed for weighted points.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from robocal_uncertainty.core.identification import identify
from robocal_uncertainty.core.measurement import PointMeasurement
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model
from robocal_uncertainty.core.simulation import SimulationSettings, simulate_campaign
from robocal_uncertainty.report.configurations import _num
from robocal_uncertainty.report.document import _weighting_lines
from robocal_uncertainty.report.json_report import _measurement


def test_weighted_point_calibration_states_its_std_in_json_and_markdown() -> None:
    model = load_robot_model(Path(__file__).resolve().parents[2] / "robocal_uncertainty" / "data" / "paper_arm.yaml")
    campaign = simulate_campaign(model, SimulationSettings(n_poses=30), seed=4).campaign
    std = (20e-6, 30e-6, 40e-6)
    campaign = dataclasses.replace(campaign, measurement=PointMeasurement(std=std))
    calibration = identify(model, campaign)
    out = _measurement(calibration)
    assert out["stated_std"] == list(std)
    np.testing.assert_allclose(out["std"], std, rtol=1e-12)
    assert "stated instrument uncertainties" in _weighting_lines(calibration)[1]


def test_an_axis_without_coverage_factor_is_an_empty_csv_cell() -> None:
    assert _num(None, 1.0) == ""
    assert _num(2.5e-4, 1e6) == "250"
