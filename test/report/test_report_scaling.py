"""Reports with many test configurations: summary plots and tables, a few histograms, compact files.

Timing lives in ``benchmarks/bench_report.py``; these tests check size and content only.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core.simulation import draw_joint_positions
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.report import read_report_json, write_report, write_report_json
from robocal_uncertainty.report.configurations import (
    DEFAULT_HISTOGRAMS,
    DETAIL_LIMIT,
    select_configurations,
    summarize_configurations,
)
from robocal_uncertainty.uncertainty import UncertaintySettings, evaluate_uncertainty

N_MANY = 150
SUMMARY_PNGS = {"configurations.png", "uncertainty_vs_reach.png"}
ALWAYS_PNGS = {"lcurve.png", "parameters.png"}


def _evaluate(setup, n_test: int):
    q = draw_joint_positions(setup.model, n_test, rng=np.random.default_rng(2), margin=np.radians(5.0))
    return evaluate_uncertainty(
        setup.model,
        setup.campaign,
        q,
        uncertainty=UncertaintySettings(sources=("tracker", "encoder")),
        trials=200,
        seed=1,
    )


def _per_config_pngs(indices, result) -> set[str]:
    out = set()
    for i in indices:
        out |= {f"histograms_{i + 1}.png", f"position_error_{i + 1}.png"}
        orientation = result.poses[i].orientation
        # A rotation figure only where some rotation is determined (no panels that are all "undetermined").
        if orientation is not None and any(orientation.determined):
            out.add(f"rotation_histograms_{i + 1}.png")
    return out


@pytest.fixture(scope="module")
def many(setup):
    return _evaluate(setup, N_MANY)


@pytest.fixture(scope="module")
def many_report(many, tmp_path_factory):
    return write_report(tmp_path_factory.mktemp("many") / "report", many, robot_name="paper_arm")


def test_many_configurations_report_is_small_and_summarised(many, many_report):
    out: Path = many_report
    size = sum(p.stat().st_size for p in out.iterdir())
    assert size < 5e6, f"report of {N_MANY} configurations is {size / 1e6:.1f} MB"

    worst = summarize_configurations(many).worst
    expected = {*range(DEFAULT_HISTOGRAMS), worst}
    assert {p.name for p in out.glob("*.png")} == SUMMARY_PNGS | ALWAYS_PNGS | _per_config_pngs(expected, many)

    md = (out / "report.md").read_text(encoding="utf-8")
    html = (out / "report.html").read_text(encoding="utf-8")
    for doc in (md, html):
        assert f"{N_MANY} test configurations in frame" in doc  # the overview line
        assert f"at test configuration {worst + 1} " in doc
        assert "configurations.csv" in doc
    assert "(configurations.png)" in md and "(uncertainty_vs_reach.png)" in md
    assert html.count('<img src="data:image/png;base64,') == len(list(out.glob("*.png")))
    # Worst-first table: its first row names the worst configuration; only 10 rows.
    table = md.split("## Test configurations", 1)[1]
    first_row = next(line for line in table.splitlines() if line.startswith("| ") and line[2].isdigit())
    assert first_row.startswith(f"| {worst + 1} |")
    # Per-configuration sections only for the selection, not for all 150.
    assert md.count("### Test configuration ") == 2 * len(expected)  # Table 2 and GUM
    assert len(md) < 100_000

    data = read_report_json(out / "report.json")
    assert len(data["test_configurations"]) == N_MANY
    assert data["configuration_summary"]["worst_index"] == worst
    assert len(data["configuration_summary"]["position_uncertainty_m"]) == N_MANY
    pose = data["test_configurations"][worst]
    for key in ("mean_m", "covariance_m2", "standard_uncertainty_m", "expanded_uncertainty_m", "gum", "region"):
        assert pose[key] is not None
    assert set(pose["axes"][0]["intervals"]) == {"probabilistically_symmetric", "shortest"}
    assert len(pose["region"]["semi_axes_m"]) == 3
    # ~10 kB per configuration (positions, orientation incl. its undetermined directions, GUM, region).
    assert (out / "report.json").stat().st_size < 1.7e6

    with (out / "configurations.csv").open(encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == N_MANY
    u_pos = [float(r["u_pos_um"]) for r in rows]
    assert int(np.argmax(u_pos)) == worst
    assert rows[worst]["configuration"] == str(worst + 1)
    assert float(rows[0]["u_x_um"]) == pytest.approx(many.poses[0].axes[0].standard_uncertainty * 1e6, rel=1e-8)


def test_histograms_argument_selects_figures(many, tmp_path):
    budget = {"tracker": many, "encoder": many}
    out = write_report(tmp_path / "none", many, robot_name="arm", histograms=0, embed_images=False, budget=budget)
    assert {p.name for p in out.glob("*.png")} == SUMMARY_PNGS | ALWAYS_PNGS
    # Budget: one table over all configurations, full tables only for the worst.
    budget_md = (out / "report.md").read_text(encoding="utf-8").split("## Uncertainty budget", 1)[1].split("\n## ")[0]
    assert f"Source (over {N_MANY} configurations)" in budget_md
    assert budget_md.count("### Test configuration ") == 1
    out = write_report(tmp_path / "two", many, robot_name="arm", histograms=[3, 10], embed_images=False)
    assert {p.name for p in out.glob("*.png")} == SUMMARY_PNGS | ALWAYS_PNGS | _per_config_pngs([3, 10], many)
    html = (out / "report.html").read_text(encoding="utf-8")
    assert '<img src="histograms_11.png"' in html


def test_few_configurations_keep_every_detail(setup, tmp_path):
    result = _evaluate(setup, 3)
    out = write_report(tmp_path, result, robot_name="arm", embed_images=False)
    assert {p.name for p in out.glob("*.png")} == SUMMARY_PNGS | ALWAYS_PNGS | _per_config_pngs(range(3), result)
    md = (out / "report.md").read_text(encoding="utf-8")
    for i in range(3):
        assert f"Test configuration {i + 1}: position (x, y, z)" in md  # per-configuration summary line
        assert md.count(f"### Test configuration {i + 1}\n") == 2  # Table 2 and GUM
    assert "Shown for test configurations" not in md


def test_select_configurations_rules_and_errors():
    assert select_configurations(None, DETAIL_LIMIT) == tuple(range(DETAIL_LIMIT))
    assert select_configurations(None, 150, worst=70) == (*range(DEFAULT_HISTOGRAMS), 70)
    assert select_configurations(None, 150, worst=2) == tuple(range(DEFAULT_HISTOGRAMS))
    assert select_configurations("all", 4) == (0, 1, 2, 3)
    assert select_configurations(20, 4) == (0, 1, 2, 3)
    assert select_configurations([5, 1, 5], 10) == (1, 5)
    with pytest.raises(ConfigError, match="count >= 0, got -1"):
        select_configurations(-1, 10)
    with pytest.raises(ConfigError, match="got 'some'"):
        select_configurations("some", 10)
    with pytest.raises(ConfigError, match=r"index 10 is not a 0-based configuration index in \[0, 10\)"):
        select_configurations([0, 10], 10)
    with pytest.raises(ConfigError, match="got True"):
        select_configurations(True, 10)


def test_write_report_rejects_bad_histograms(setup, tmp_path):
    with pytest.raises(ConfigError, match="index 1 is not"):
        write_report(tmp_path, setup.result, robot_name="arm", histograms=[1])


def test_json_number_arrays_on_one_line_strings_untouched(setup, tmp_path):
    tricky = "[1,\n 2] stays as written"
    path = write_report_json(tmp_path / "r.json", setup.result, robot_name="arm", extra_settings={"note": tricky})
    text = path.read_text(encoding="utf-8")
    data = json.loads(text)
    assert data["extra_settings"]["note"] == tricky
    mean = data["test_configurations"][0]["mean_m"]
    assert '"mean_m": ' + json.dumps(mean) in text
    assert data["test_configurations"][0]["covariance_m2"] == setup.result.poses[0].covariance.tolist()


def test_cli_histograms_option(tmp_path, capsys):
    from robocal_uncertainty.cli import main

    out = tmp_path / "demo"
    argv = ["demo", "--out", str(out), "--trials", "200", "--no-budget", "--no-sweeps", "--no-progress"]
    assert main([*argv, "--histograms", "0"]) == 0
    assert not (out / "histograms_1.png").exists()
    assert (out / "configurations.csv").exists()
    with pytest.raises(SystemExit):
        main([*argv, "--histograms", "some"])
    assert "expected a count >= 0 or 'all', got 'some'" in capsys.readouterr().err
