"""Table 2 layout and rounding to the uncertainty (two significant digits of u)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo import CoverageInterval, Histogram, OutputSummary
from robocal_uncertainty.report import (
    format_budget,
    format_table2,
    round_to_uncertainty,
)


@pytest.mark.parametrize(
    ("value", "u", "expected"),
    [
        (228.91951, 0.4774, "228.92"),  # seed Table 2, x
        (0.4774, 0.4774, "0.48"),
        (-99.2792, 0.5063, "-99.28"),
        (532.4152, 0.0316, "532.415"),
        (0.0316, 0.0316, "0.032"),
        (1.241, 0.4774, "1.24"),
        (1.23456, 0.0996, "1.23"),  # u rounds up to 0.10: still two digits
        (0.0996, 0.0996, "0.10"),
        (12345.6, 260.0, "12350"),  # u >= 10: round to tens
        (3.0, 1.0, "3.0"),
        (-0.0004, 0.0316, "-0.000"),
        (5.0, 0.0, "5"),  # zero uncertainty: 6 significant digits
        (float("nan"), 1.0, "n/a"),
    ],
)
def test_round_to_uncertainty_hand_values(value, u, expected):
    assert round_to_uncertainty(value, u) == expected


def test_round_to_uncertainty_digits():
    assert round_to_uncertainty(228.91951, 0.4774, digits=1) == "228.9"
    assert round_to_uncertainty(228.91951, 0.4774, digits=3) == "228.920"
    with pytest.raises(ConfigError):
        round_to_uncertainty(1.0, 0.1, digits=0)


def _axis(estimate_mm, u_mm, big_u_mm, low_mm, high_mm):
    s = 1e-3
    sym = CoverageInterval(low_mm * s, high_mm * s, "probabilistically_symmetric", 0.95)
    return OutputSummary(
        estimate=estimate_mm * s,
        standard_uncertainty=u_mm * s,
        probabilistically_symmetric=sym,
        shortest=sym,
        expanded_from="probabilistically_symmetric",
        expanded_uncertainty=big_u_mm * s,
        coverage_factor=big_u_mm / u_mm,
        relative_expanded_uncertainty=big_u_mm / abs(estimate_mm),
        histogram=Histogram(np.zeros(1, np.int64), np.array([0.0, 1.0])),
        n_trials=10000,
    )


def test_seed_table2_numbers(setup):
    # The seed's Table 2 values (mm), put into a real result's structure.
    axes = (
        _axis(228.9195, 0.4774, 1.2412, 225.5416, 231.4231),
        _axis(-99.2792, 0.5063, 1.3164, -102.5322, -93.8767),
        _axis(532.4152, 0.0316, 0.0821, 532.2508, 532.5565),
    )
    pose = dataclasses.replace(setup.result.poses[0], axes=axes)
    result = dataclasses.replace(setup.result, poses=(pose,))
    text = format_table2(result)
    lines = {line.split("  ")[0]: line for line in text.splitlines()}
    assert lines["Output value / mm"].split()[-3:] == ["228.92", "-99.28", "532.415"]
    assert lines["Standard uncertainty / mm"].split()[-3:] == ["0.48", "0.51", "0.032"]
    assert lines["Expanded uncertainty / mm"].split()[-3:] == ["1.24", "1.32", "0.082"]
    assert "(225.54, 231.42)" in lines["Coverage interval / mm"]
    assert "(-102.53, -93.88)" in lines["Coverage interval / mm"]
    assert "(532.251, 532.557)" in lines["Coverage interval / mm"]
    # 100 U/|y|: 0.5422 %, 1.3259 %, 0.01542 % with two significant digits.
    assert lines["Relative expanded uncertainty / %"].split()[-3:] == [
        "0.54",
        "1.3",
        "0.015",
    ]


def test_format_table2_of_a_run(setup):
    result = setup.result
    text = format_table2(result)
    pose = result.poses[0]
    for ax in pose.axes:
        u_mm = ax.standard_uncertainty * 1e3
        assert round_to_uncertainty(ax.estimate * 1e3, u_mm) in text
        assert round_to_uncertainty(u_mm, u_mm) in text
        low = round_to_uncertainty(ax.probabilistically_symmetric.low * 1e3, u_mm)
        high = round_to_uncertainty(ax.probabilistically_symmetric.high * 1e3, u_mm)
        assert f"({low}, {high})" in text
    for needle in (
        "-7.5005",
        "-234.4840",
        "20.7451",
        "trials: 1000",
        "seed: 1",
        "95 %",
        "probabilistically symmetric",
        "sources: tracker, encoder",
        "GUM validated",
        "Relative expanded uncertainty / %",
    ):
        assert needle in text
    assert "Output value / µm" in format_table2(result, unit="µm")
    with pytest.raises(ConfigError):
        format_table2(result, unit="inch")


def test_format_budget(setup):
    result = setup.result
    text = format_budget({"tracker": result, "encoder": result})
    assert "u_x / µm" in text and "u_pos / µm" in text
    u_um = [a.standard_uncertainty * 1e6 for a in result.poses[0].axes]
    row = next(line for line in text.splitlines() if line.startswith("tracker"))
    assert row.split()[1:4] == [round_to_uncertainty(u, u) for u in u_um]


def test_round_to_uncertainty_keeps_two_significant_digits_of_u() -> None:
    from robocal_uncertainty.report.table2 import format_significant, round_to_uncertainty

    assert round_to_uncertainty(206.176, 8.3) == "206.2"
    assert round_to_uncertainty(1708870.0, 45000.0) == "1709000"
    assert round_to_uncertainty(0.4597, 0.0083) == "0.4597"
    assert format_significant(206.176) == "210"


def test_describe_dependency_reads_as_columns() -> None:
    from robocal_uncertainty.core.observability import describe_dependency

    text = describe_dependency("joint3.d = 1 * joint2.d")
    assert text == (
        "joint3.d and joint2.d act alike (column of joint3.d = 1 × column of joint2.d): "
        "only their combination is identifiable"
    )
    assert describe_dependency("joint6.theta does not move the measured point").endswith("point")
