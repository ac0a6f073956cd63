"""Workspace uncertainty map: same trials as evaluate_uncertainty, same numbers everywhere."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import SimulationSettings, identify, load_robot_model, simulate_campaign
from robocal_uncertainty.core.robot_formats.robot_yaml import resolve_robot_config
from robocal_uncertainty.errors import ConfigError, InputError
from robocal_uncertainty.montecarlo.executor import open_executor
from robocal_uncertainty.report.map_report import weakest_region, write_map_report
from robocal_uncertainty.uncertainty.calibration import evaluate_uncertainty
from robocal_uncertainty.uncertainty.sources import UncertaintySettings
from robocal_uncertainty.uncertainty.workspace_map import (
    grid_configurations,
    joint_ranges,
    map_workspace,
    sample_configurations,
)

UR10_CSV = Path(__file__).resolve().parents[1] / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv"
SMALL = {"trials": 600, "seed": 5, "block_size": 200}


@pytest.fixture(scope="module")
def paper_arm():
    model = load_robot_model(resolve_robot_config("paper_arm"))
    campaign = simulate_campaign(model, SimulationSettings(frame="tracker"), seed=2).campaign
    campaign = campaign.reorder_joints(model.joint_names)
    return model, campaign, identify(model, campaign)


@pytest.fixture(scope="module")
def configurations(paper_arm):
    model = paper_arm[0]
    return sample_configurations(model, 12, rng=np.random.default_rng(11))


def _assert_same_map(a, b) -> None:
    for name in ("mean", "covariance", "standard_uncertainty", "position_uncertainty", "region_semi_axes"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_map_bit_identical_on_local_processes_and_dask(paper_arm, configurations) -> None:
    pytest.importorskip("distributed")
    model, campaign, calibration = paper_arm
    kwargs = {"calibration": calibration, "regions": [0, 7], **SMALL}
    reference = map_workspace(model, campaign, configurations, **kwargs)
    local = map_workspace(model, campaign, configurations, workers=2, **kwargs)
    with open_executor(workers=2, dask="local") as client:
        remote = map_workspace(model, campaign, configurations, executor=client, **kwargs)
    _assert_same_map(local, reference)
    _assert_same_map(remote, reference)
    assert reference.n_trials == 600 and len(reference) == 12


def test_map_equals_evaluate_uncertainty_at_the_same_configurations(paper_arm, configurations) -> None:
    model, campaign, calibration = paper_arm
    settings = UncertaintySettings(sources=("tracker", "encoder", "residual"))
    wmap = map_workspace(
        model, campaign, configurations[:4], settings=settings, calibration=calibration, regions=[2], **SMALL
    )
    result = evaluate_uncertainty(
        model, campaign, configurations[:4], uncertainty=settings, calibration=calibration, **SMALL
    )
    assert wmap.frame_id == result.frame_id
    for i, pose in enumerate(result.poses):
        np.testing.assert_allclose(wmap.mean[i], pose.mean, rtol=1e-14)
        np.testing.assert_allclose(wmap.covariance[i], pose.covariance, rtol=1e-10, atol=1e-22)
        u = [a.standard_uncertainty for a in pose.axes]
        np.testing.assert_allclose(wmap.standard_uncertainty[i], u, rtol=1e-10)
    # The kept configuration's region is built from the very same model values.
    region = result.poses[2].region
    assert region is not None
    semi = region.coverage_factor * np.sqrt(np.linalg.eigvalsh(region.covariance)[::-1])
    np.testing.assert_allclose(wmap.region_semi_axes[2], semi, rtol=1e-10)
    assert np.isnan(wmap.region_semi_axes[[0, 1, 3]]).all()


def test_one_configuration_of_the_map_equals_evaluate_alone(paper_arm, configurations) -> None:
    # Tracker noise draws nothing per test configuration: the same trials whatever the set.
    model, campaign, calibration = paper_arm
    settings = UncertaintySettings(sources=("tracker",))
    wmap = map_workspace(model, campaign, configurations, settings=settings, calibration=calibration, **SMALL)
    alone = evaluate_uncertainty(
        model, campaign, configurations[5], uncertainty=settings, calibration=calibration, **SMALL
    )
    np.testing.assert_allclose(wmap.covariance[5], alone.poses[0].covariance, rtol=1e-10, atol=1e-22)


def test_map_report_on_the_paper_arm(paper_arm, tmp_path: Path) -> None:
    model, campaign, calibration = paper_arm
    q = grid_configurations(model, [3, 3, 3, 2, 1, 1])
    wmap = map_workspace(model, campaign, q, calibration=calibration, frame="base", regions=[0], **SMALL)
    assert wmap.frame_id == model.base_frame_id and q.shape == (54, model.n_joints)
    files = write_map_report(wmap, tmp_path, worst=5)
    with files.table_csv.open(encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 54 and float(rows[0]["u_pos_um"]) == pytest.approx(wmap.position_uncertainty[0] * 1e6)
    document = json.loads(files.json.read_text(encoding="utf-8"))
    assert document["n_configurations"] == 54 and document["seed"] == 5
    weak = weakest_region(wmap)
    assert document["summary"]["weakest_configurations"][0] == int(wmap.order[0]) + 1
    assert weak.max_u == pytest.approx(float(wmap.position_uncertainty.max()))
    text = files.markdown.read_text(encoding="utf-8")
    assert "Where the calibration is weakest" in text and text.count("\n| ") == 6  # header + 5 rows
    assert files.figure.stat().st_size > 10_000


@pytest.fixture(scope="module")
def ur10():
    if not UR10_CSV.exists():
        pytest.skip("UR10 data not present")
    from robocal_uncertainty.importers.tracker_csv import read_tracker_csv

    model = load_robot_model(resolve_robot_config("ur10"))
    return model, read_tracker_csv(UR10_CSV).reorder_joints(model.joint_names)


def test_map_report_on_the_real_ur10(ur10, tmp_path: Path) -> None:
    model, campaign = ur10
    span = np.column_stack([campaign.joint_positions.min(axis=0), campaign.joint_positions.max(axis=0)])
    q = sample_configurations(model, 20, rng=np.random.default_rng(3), limits=span)
    assert ((q >= span[:, 0]) & (q <= span[:, 1])).all()
    settings = UncertaintySettings(sources=("tracker", "encoder", "residual"))
    wmap = map_workspace(model, campaign, q, settings=settings, trials=300, seed=1, block_size=150)
    assert wmap.frame_id == campaign.frame_id and np.isfinite(wmap.position_uncertainty).all()
    # Real data: tens to hundreds of micrometres, not metres (a lost base would show).
    assert 1e-6 < float(np.median(wmap.position_uncertainty)) < 5e-3
    files = write_map_report(wmap, tmp_path)
    assert "ur10" in files.markdown.read_text(encoding="utf-8")


def test_samplers_stay_inside_the_limits(paper_arm) -> None:
    model = paper_arm[0]
    q = sample_configurations(model, 500, rng=np.random.default_rng(0))
    limits = joint_ranges(model)
    assert q.shape == (500, model.n_joints)
    assert ((q >= limits[:, 0]) & (q <= limits[:, 1])).all()
    grid = grid_configurations(model, 2)
    assert grid.shape == (2**model.n_joints, model.n_joints)
    np.testing.assert_array_equal(grid[0], limits[:, 0])
    np.testing.assert_array_equal(grid[-1], limits[:, 1])
    middle = grid_configurations(model, 1)
    np.testing.assert_allclose(middle[0], limits.mean(axis=1))


def test_map_errors(paper_arm, configurations) -> None:
    model, campaign, calibration = paper_arm
    with pytest.raises(ConfigError, match=r"configurations must have shape \(n, 6\)"):
        map_workspace(model, campaign, configurations[:, :5], calibration=calibration)
    outside = configurations.copy()
    outside[0, 1] = 50.0
    with pytest.raises(InputError, match="map configuration 1 of 12: joint"):
        map_workspace(model, campaign, outside, calibration=calibration)
    with pytest.raises(ConfigError, match=r"region configuration 12 is not a 0-based index in \[0, 12\)"):
        map_workspace(model, campaign, configurations, calibration=calibration, regions=[12])
    with pytest.raises(ConfigError, match="trials must be an integer >= 2"):
        map_workspace(model, campaign, configurations, calibration=calibration, trials=1)
    with pytest.raises(ConfigError, match="output frame must be one of"):
        map_workspace(model, campaign, configurations, calibration=calibration, frame="tool")
    with pytest.raises(ConfigError, match="grid steps must be 6 integers"):
        grid_configurations(model, [2, 2])
    with pytest.raises(ConfigError, match="number of configurations must be an integer >= 1"):
        sample_configurations(model, 0, rng=np.random.default_rng(0))
    with pytest.raises(ConfigError, match=r"joint ranges must be finite \(low, high\) rows"):
        sample_configurations(model, 3, rng=np.random.default_rng(0), limits=[[0.0, 1.0]])


def test_cli_map_on_dask_writes_the_same_table(tmp_path: Path, capsys) -> None:
    pytest.importorskip("distributed")
    from robocal_uncertainty.cli import main

    campaign = tmp_path / "campaign.mcap"
    assert main(["simulate", "--out", str(campaign), "--seed", "1"]) == 0
    common = ["map", str(campaign), "--robot", "paper_arm", "--configurations", "40", "--trials", "400"]
    common += ["--block-size", "100", "--regions", "2", "--no-progress"]
    assert main([*common, "--out", str(tmp_path / "one")]) == 0
    assert main([*common, "--dask", "local", "--workers", "2", "--out", str(tmp_path / "dask")]) == 0
    out = capsys.readouterr().out
    assert "40 configurations x 400 trials" in out and "weakest: configuration" in out
    one = (tmp_path / "one" / "map.csv").read_text(encoding="utf-8")
    assert one == (tmp_path / "dask" / "map.csv").read_text(encoding="utf-8")
    assert len(one.splitlines()) == 41


def test_cli_map_errors(tmp_path: Path, capsys) -> None:
    from robocal_uncertainty.cli import main

    campaign = tmp_path / "campaign.mcap"
    assert main(["simulate", "--out", str(campaign), "--seed", "1"]) == 0
    args = ["map", str(campaign), "--robot", "paper_arm", "--trials", "100", "--no-progress"]
    assert main([*args, "--configurations", "0", "--out", str(tmp_path / "a")]) == 1
    assert "number of configurations must be an integer >= 1" in capsys.readouterr().err
    assert main([*args, "--grid", "2", "3", "--out", str(tmp_path / "b")]) == 1
    assert "grid steps must be 6 integers" in capsys.readouterr().err


def test_map_field_correction_moves_positions_by_the_kriged_mean_and_shows_the_std_ratio(ur10, tmp_path: Path) -> None:
    from robocal_uncertainty.core.field_kriging import krige
    from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
    from robocal_uncertainty.uncertainty.field_kriging import calibration_kriging_basis

    model, campaign = ur10
    campaign = campaign.subset(np.sort(np.random.default_rng(29).permutation(campaign.n_poses)[:80]))
    calibration = identify(model, campaign)
    q_t = campaign.joint_positions
    q = np.vstack((q_t[:3] + 0.01, q_t[3:6] + 0.4))
    settings = UncertaintySettings(sources=("tracker", "encoder", "residual"))
    run = {"trials": 200, "seed": 1, "block_size": 100, "calibration": calibration}
    plain = map_workspace(model, campaign, q, settings=settings, **run)
    fielded = map_workspace(model, campaign, q, settings=settings, field_correction=True, **run)
    basis = calibration_kriging_basis(calibration, campaign, TrackerNoise(), EncoderNoise())
    kriged = krige(basis, model.layout, calibration.estimate, q)
    np.testing.assert_allclose(fielded.positions - plain.positions, kriged.mean, atol=1e-12)
    np.testing.assert_allclose(fielded.field_std_ratio, kriged.std_ratio)
    # The statement: the kriging covariance plus what the Monte Carlo carries beyond the field's prior.
    extra = fielded.covariance - kriged.covariance
    assert np.all(np.linalg.eigvalsh(extra) > -1e-18)
    np.testing.assert_allclose(fielded.position_uncertainty**2, np.trace(fielded.covariance, axis1=1, axis2=2))
    assert kriged.std_ratio[:3].max() < kriged.std_ratio[3:].min()  # next to a pose it knows more
    files = write_map_report(fielded, tmp_path)
    with files.table_csv.open(encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    np.testing.assert_allclose([float(r["field_std_ratio"]) for r in rows], kriged.std_ratio, atol=1e-4)
    assert "The model-error field's correction" in files.markdown.read_text(encoding="utf-8")
