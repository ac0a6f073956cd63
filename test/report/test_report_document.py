"""write_report: every file written, PNGs valid, numbers rounded in the documents."""

from __future__ import annotations

import numpy as np
import pytest

from robocal_uncertainty.errors import InputError
from robocal_uncertainty.report import (
    REPORT_FILES,
    Sweep,
    plot_uncertainty_vs,
    read_report_json,
    round_to_uncertainty,
    write_report,
)

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _is_png(path) -> bool:
    data = path.read_bytes()
    return len(data) > 1000 and data[:8] == PNG_SIGNATURE and b"IEND" in data[-16:]


def test_write_report_creates_everything(setup, tmp_path):
    result = setup.result
    sweeps = [
        Sweep(
            "lambda",
            "λ (scaled)",
            [0.001, 0.01, 0.1],
            np.full((3, 3), 2e-5),
            reference=result.calibration.lambda_,
            log_x=True,
            n_trials=100,
        ),
        Sweep(
            "equations",
            "number of equations",
            [60, 159],
            np.array([[3e-5] * 3, [2e-5] * 3]),
        ),
    ]
    out = write_report(
        tmp_path / "rep",
        result,
        robot_name="paper_arm",
        budget={"tracker": result, "encoder": result},
        sweeps=sweeps,
        campaign_source="simulated",
    )
    assert out == tmp_path / "rep"
    for name in REPORT_FILES:
        assert (out / name).stat().st_size > 0
    pngs = sorted(p.name for p in out.glob("*.png"))
    assert pngs == [
        "histograms_1.png",
        "lcurve.png",
        "parameters.png",
        "position_error_1.png",
        # No rotation_histograms_1.png: from points alone no rotation of the tool is determined,
        # and a figure of three empty "undetermined" panels says nothing the text does not.
        "sweep_equations.png",
        "sweep_lambda.png",
    ]
    assert all(_is_png(out / name) for name in pngs)

    data = read_report_json(out / "report.json")
    assert [b["source"] for b in data["budget"]] == ["tracker", "encoder"]
    assert [s["name"] for s in data["sweeps"]] == ["lambda", "equations"]

    md = (out / "report.md").read_text(encoding="utf-8")
    html = (out / "report.html").read_text(encoding="utf-8")
    ax = result.poses[0].axes[0]
    value = round_to_uncertainty(ax.estimate * 1e3, ax.standard_uncertainty * 1e3)
    for doc in (md, html):
        assert value in doc
        for heading in (
            "Summary",
            "Table 2",
            "Uncertainty budget",
            "GUM",
            "Calibration",
            "Not identifiable",
            "Settings and reproducibility",
        ):
            assert heading in doc
        assert "joint6.theta" in doc  # a non-identifiable parameter with its reason
    assert "![" in md and "(histograms_1.png)" in md
    assert html.startswith("<!DOCTYPE html>") and "<table>" in html
    assert html.count('<img src="data:image/png;base64,') == len(pngs)


def test_write_report_linked_images(setup, tmp_path):
    out = write_report(tmp_path, setup.result, robot_name="arm", embed_images=False)
    html = (out / "report.html").read_text(encoding="utf-8")
    assert '<img src="histograms_1.png"' in html
    assert not (out / "sweep_lambda.png").exists()


def test_plot_uncertainty_vs_checks_shape(tmp_path):
    path = plot_uncertainty_vs([1, 2, 3], np.ones((3, 3)) * 1e-5, "n", tmp_path / "u.png")
    assert _is_png(path)
    with pytest.raises(InputError):
        plot_uncertainty_vs([1, 2], np.ones((3, 3)), "n", tmp_path / "v.png")
