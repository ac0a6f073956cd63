"""Issue 18 items 1-3: the validated sources by default, small campaigns flagged, parameters
held by the regularisation named as such (core, report and command line)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from robocal_uncertainty.bagio.campaign_mcap import write_campaign
from robocal_uncertainty.cli import main
from robocal_uncertainty.core import identify
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model, resolve_robot_config
from robocal_uncertainty.importers.tracker_csv import read_tracker_csv
from robocal_uncertainty.pipeline.diagnostics import DiagnosticLevel, uncertainty_status
from robocal_uncertainty.uncertainty import UncertaintySettings, default_sources
from robocal_uncertainty.uncertainty.model_adequacy import assess_model_adequacy

ROOT = Path(__file__).resolve().parents[1]
UR10_CSV = ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv"
TEST_JOINTS = ["0.934319", "-1.79251", "1.5196", "0.272862", "0.934269", "-1.57075"]
QUICK = ["--trials", "300", "--no-budget", "--no-sweeps", "--no-progress"]


@pytest.fixture(scope="module")
def ur10():
    return load_robot_model(resolve_robot_config("ur10")), read_tracker_csv(UR10_CSV)


@pytest.fixture(scope="module")
def ur10_subsets(ur10, tmp_path_factory: pytest.TempPathFactory) -> dict[int, Path]:
    """10- and 53-pose campaigns drawn from the UR10 series, as campaign files."""
    _, campaign = ur10
    rng = np.random.default_rng(18)
    out = {}
    for n in (10, 53):
        path = tmp_path_factory.mktemp("h18") / f"ur10_{n}.mcap"
        write_campaign(path, campaign.subset(np.sort(rng.choice(campaign.n_poses, n, replace=False))))
        out[n] = path
    return out


def _evaluate(path: Path, out: Path, *extra: str) -> list[str]:
    return ["evaluate", str(path), "--robot", "ur10", "--test-joints", *TEST_JOINTS, "--out", str(out), *QUICK, *extra]


# ----------------------------------------------------------------- 1. one default source set


def test_default_sources_are_the_validated_set() -> None:
    assert default_sources() == ("tracker", "encoder", "residual")
    assert default_sources(True) == ("tracker", "encoder", "residual", "tracker_orientation")
    assert UncertaintySettings().sources == default_sources()
    config = yaml.safe_load((ROOT / "config" / "robocal.yaml").read_text())
    node = config["uncertainty_node"]["ros__parameters"]
    assert tuple(node["sources"].split(",")) == default_sources()
    node_source = (ROOT / "robocal_uncertainty" / "nodes" / "uncertainty_node.py").read_text()
    assert '",".join(default_sources())' in node_source  # the node's parameter default


@pytest.mark.parametrize("verb", ["evaluate", "replay", "validate", "map", "suggest"])
def test_every_verb_states_the_validated_default(verb: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main([verb, "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "default tracker,encoder,residual: the validated set" in help_text


def test_evaluate_default_is_the_validated_statement(
    ur10_subsets: dict[int, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = ur10_subsets[53]
    assert main(_evaluate(path, tmp_path / "default")) == 0
    out = capsys.readouterr().out
    assert "model error u = (" in out and ", included" in out
    assert main(_evaluate(path, tmp_path / "explicit", "--sources", "tracker,encoder,residual")) == 0
    assert main(_evaluate(path, tmp_path / "noise", "--sources", "tracker,encoder")) == 0
    capsys.readouterr()
    reports = {k: json.loads((tmp_path / k / "report.json").read_text()) for k in ("default", "explicit", "noise")}
    assert reports["default"]["settings"]["sources"] == ["tracker", "encoder", "residual"]

    def u(name: str) -> np.ndarray:
        return np.array(reports[name]["test_configurations"][0]["standard_uncertainty_m"])

    np.testing.assert_array_equal(u("default"), u("explicit"))
    # The noise-only statement is several times smaller on this robot (model error ~0.2 mm).
    assert (u("default") > 3.0 * u("noise")).all()
    assert (u("default") > 1.5e-4).all()


# ----------------------------------------------------------------- 2. small campaigns


def test_small_campaign_is_flagged_not_trustworthy(
    ur10_subsets: dict[int, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(_evaluate(ur10_subsets[10], tmp_path / "r10")) == 0
    out = capsys.readouterr().out
    line = next(s for s in out.splitlines() if "NOT TRUSTWORTHY" in s)
    assert line.startswith("warning: NOT TRUSTWORTHY: ")
    assert "fewer than the 96 needed" in line
    report = json.loads((tmp_path / "r10" / "report.json").read_text())
    ad = report["model_adequacy"]
    assert ad["trustworthy"] is False and ad["min_residual_dof"] == 96
    assert 0 < ad["residual_dof"] < 30  # 30 equations less the effective parameters
    assert any("NOT TRUSTWORTHY" in w for w in report["warnings"])
    assert "NOT TRUSTWORTHY" in (tmp_path / "r10" / "report.md").read_text()

    assert main(_evaluate(ur10_subsets[53], tmp_path / "r53")) == 0
    assert "NOT TRUSTWORTHY" not in capsys.readouterr().out
    ad = json.loads((tmp_path / "r53" / "report.json").read_text())["model_adequacy"]
    assert ad["trustworthy"] is True and ad["residual_dof"] >= 96


def test_diagnostics_warn_on_an_untrustworthy_statement() -> None:
    common = {
        "name": "u: Monte Carlo",
        "hardware_id": "ur10",
        "now_ns": 2_000_000_000,
        "state": "done",
        "samples": 10,
        "trials": 1000,
        "converged": True,
        "max_standard_uncertainty_m": 1e-4,
        "last_evaluation_ns": 1_000_000_000,
        "last_evaluation_s": 0.5,
    }
    ok = uncertainty_status(**common)
    assert ok.level == DiagnosticLevel.OK and ok.value("trustworthy") == "true"
    note = "NOT TRUSTWORTHY: 5 residual degrees of freedom"
    flagged = uncertainty_status(**common, trust_note=note)
    assert flagged.level == DiagnosticLevel.WARN and flagged.message == note
    assert flagged.value("trustworthy") == "false"


def test_leave_one_out_errors_match_refits(ur10) -> None:
    """(I - H_ii)^-1 r_i is the error of predicting pose i from a fit without it: compare
    with real refits (same lambda) on a 15-pose campaign."""
    model, campaign = ur10
    sub = campaign.reorder_joints(model.joint_names).subset(np.arange(0, 600, 40))
    cal = identify(model, sub)
    layout = cal.model.layout
    est = np.flatnonzero(cal.estimated)
    n = sub.n_poses
    _, jac = cal.measurement.predict_and_jacobian(layout, cal.estimate, sub.joint_positions)
    a = jac.reshape(3 * n, layout.size)[:, est] / cal.column_scale[est]
    penalty = cal.lambda_**2 * np.diag(cal.penalized[est].astype(float))
    gain = np.linalg.solve(a.T @ a + penalty, a.T)
    lever = np.eye(3) - (a.reshape(n, 3, -1) @ gain.reshape(-1, n, 3).transpose(1, 0, 2))
    for i in (0, 7, 14):
        predicted = np.linalg.solve(lever[i], cal.residuals[i])
        keep = np.delete(np.arange(n), i)
        refit = identify(model, sub.subset(keep), lambda_=cal.lambda_)
        actual = sub.points[i] - refit.measurement.predict(layout, refit.estimate, sub.joint_positions[i : i + 1])[0]
        assert np.linalg.norm(predicted - actual) < 0.1 * np.linalg.norm(actual) + 5e-6


def test_model_error_of_a_small_campaign_is_cross_validated(ur10) -> None:
    """On 15 poses the in-sample residuals underrate the error at a new pose; the model error
    stated is at least the leave-one-out one and the statement is flagged."""
    model, campaign = ur10
    sub = campaign.reorder_joints(model.joint_names).subset(np.arange(0, 600, 40))
    cal = identify(model, sub)
    s = UncertaintySettings()
    ad = assess_model_adequacy(
        cal, sub.joint_positions, s.tracker_noise, s.encoder_noise, np.linalg.norm(sub.points, axis=1)
    )
    assert not ad.adequate and not ad.trustworthy
    assert ad.residual_dof == pytest.approx(45 - cal.effective_parameters)
    in_sample = np.sqrt(np.sum(cal.residuals**2) / max(45 - cal.effective_parameters, 1.0))
    assert np.sqrt(np.trace(ad.inadequacy_covariance)) > in_sample


# ----------------------------------------------------------------- 3. held by regularisation


def test_tool_z_is_held_by_the_regularisation(ur10) -> None:
    model, campaign = ur10
    cal = identify(model, campaign)
    names = list(cal.parameter_names)
    held = {names[i] for i in np.flatnonzero(cal.held_by_regularisation)}
    assert held == {"tool.z", "base.x", "base.y"}  # base.x/y follow tool.z along the tracker's line
    z = names.index("tool.z")
    assert cal.linearized_std[z] < 1e-6  # the regularised fit's 0.36 um
    # Independent reference: the unregularised fit (lambda = 0) states +-22 mm for tool.z.
    free = identify(model, campaign, lambda_=0.0)
    assert not free.held_by_regularisation.any()
    assert 0.8 < cal.data_only_std[z] / free.linearized_std[z] < 1.3
    assert free.linearized_std[z] > 0.015
    # A parameter the data determine keeps a data-only u close to its stated one.
    a3 = names.index("joint3.a")
    assert cal.data_only_std[a3] < 2.0 * cal.linearized_std[a3]
    assert 0.85 < cal.data_share[a3] <= 1.0 and cal.data_share[z] < 0.01


def test_calibrate_names_held_parameters(ur10, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _, campaign = ur10
    path = tmp_path / "ur10.mcap"
    write_campaign(path, campaign)
    out_json = tmp_path / "cal.json"
    assert main(["calibrate", str(path), "--robot", "ur10", "--json", str(out_json)]) == 0
    out = capsys.readouterr().out
    row = next(s for s in out.splitlines() if s.strip().startswith("tool.z"))
    assert "held by regularisation; data-only u = 25 mm" in row
    assert "0.36" not in row and "109.00102" not in row
    assert "held by regularisation (tool.z, base.x, base.y)" in out
    params = {p["name"]: p for p in json.loads(out_json.read_text())["parameters"]}
    assert params["tool.z"]["held_by_regularisation"] is True
    assert params["tool.z"]["data_only_std"] == pytest.approx(0.0253, rel=0.05)
    assert params["joint3.a"]["held_by_regularisation"] is False
