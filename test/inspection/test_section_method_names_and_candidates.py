"""The method once named ``seed`` (the reference paper's) is ``perturbed``; ``seed`` still works as a
deprecated alias in the API, the app function and the CLI, with the same numbers. The frozen
model's thickness and chord candidates, found without the full distance matrices, equal those
of the brute-force search."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.app.section_inspection import inspect_section, load_section_nominal
from robocal_uncertainty.cli import main
from robocal_uncertainty.core.instruments.cmm import CmmInstrument
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.inspection.frozen_model import (
    _chord_candidates,
    _point_bounds,
    _segment_distance,
    _thickness_candidates,
)
from robocal_uncertainty.inspection.point_cloud import PointCloud
from robocal_uncertainty.inspection.section import evaluate_section, point_to_polyline
from robocal_uncertainty.inspection.section_mc import METHODS, canonical_method, section_sources
from robocal_uncertainty.inspection.segmentation import PRESSURE_SIDE, SUCTION_SIDE
from robocal_uncertainty.inspection.simulate import simulate_section_scan


@pytest.fixture(scope="module")
def scan() -> PointCloud:
    curve = load_section_nominal("rotor37")
    return simulate_section_scan(curve, 400, offset=(-0.1e-3, 0.05e-3), twist=math.radians(0.05), form_amplitude=5e-6)


def test_method_names() -> None:
    assert METHODS == ("perturbed", "denoised")
    assert canonical_method("denoised") == "denoised"
    with pytest.warns(DeprecationWarning, match="'seed' is deprecated: use 'perturbed'"):
        assert canonical_method("seed") == "perturbed"
    with pytest.raises(ConfigError, match="method must be one of"):
        canonical_method("paper")


def test_seed_alias_in_the_app_gives_the_perturbed_method(scan: PointCloud) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        new = inspect_section(scan, "rotor37", trials=1000, seed=5, method="perturbed")
    with pytest.warns(DeprecationWarning):
        old = inspect_section(scan, "rotor37", trials=1000, seed=5, method="seed")
    assert old.result.method == new.result.method == "perturbed"
    for a, b in zip(old.result.monte_carlo.outputs, new.result.monte_carlo.outputs):
        assert a.probabilistically_symmetric == b.probabilistically_symmetric


def test_seed_alias_on_the_command_line(scan: PointCloud, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "scan.txt"
    assert scan.probe_vectors is not None
    np.savetxt(path, np.column_stack([scan.points * 1e3, scan.probe_vectors]), fmt="%.9f", header="unit: mm")
    argv = ["section", str(path), "--nominal", "rotor37", "--trials", "1000", "--no-progress"]
    assert main([*argv, "--method", "seed", "--out", str(tmp_path / "old")]) == 0
    assert "--method seed is deprecated, use --method perturbed" in capsys.readouterr().err
    assert main([*argv, "--method", "perturbed", "--out", str(tmp_path / "new")]) == 0
    assert "deprecated" not in capsys.readouterr().err
    old = json.loads((tmp_path / "old" / "section.json").read_text())
    new = json.loads((tmp_path / "new" / "section.json").read_text())
    assert old["method"] == new["method"] == "perturbed"
    assert old["parameters"] == new["parameters"]


@pytest.mark.parametrize("scale", [1.0, 20.0])
def test_frozen_model_candidates_equal_the_brute_force_search(scan: PointCloud, scale: float) -> None:
    curve = load_section_nominal("rotor37")
    evaluation = evaluate_section(scan, curve)
    sources = section_sources(evaluation, CmmInstrument())
    per_point, _ = _point_bounds(sources, evaluation.registration.normal)
    bound = float(per_point.max()) * scale  # 20x: many more candidates than a real CMM gives
    p = evaluation.points
    seg = evaluation.segmentation
    pressure, suction = seg.indices(PRESSURE_SIDE), seg.indices(SUCTION_SIDE)
    points, segments, starts, ends = _thickness_candidates(p, pressure, suction, bound)
    # Brute force: every pressure point against every suction segment.
    distance = _segment_distance(
        p[pressure][:, np.newaxis, :], p[suction[:-1]][np.newaxis, :, :], p[suction[1:]][np.newaxis, :, :]
    )
    reach = distance.min(axis=1)
    _, _, interior = point_to_polyline(p[pressure], p[suction])
    keep = np.flatnonzero(reach >= reach[interior].max() - 4.0 * bound)
    assert np.array_equal(points, pressure[keep])
    for row, k in zip(segments, keep):
        assert np.array_equal(np.unique(row), np.flatnonzero(distance[k] <= reach[k] + 4.0 * bound))
    assert np.array_equal(starts, suction[segments]) and np.array_equal(ends, suction[segments + 1])
    pairs = _chord_candidates(p, evaluation.chord_points, bound)
    chord = np.linalg.norm(p[evaluation.chord_points[0]] - p[evaluation.chord_points[1]])
    all_d = np.sqrt(((p[:, np.newaxis, :] - p[np.newaxis, :, :]) ** 2).sum(axis=-1))
    ends_ok = np.flatnonzero(all_d.max(axis=1) >= chord - 4.0 * bound)
    ii, jj = np.nonzero(np.triu(all_d[np.ix_(ends_ok, ends_ok)] >= chord - 4.0 * bound, k=1))
    assert pairs.shape[0] >= 1
    assert np.array_equal(pairs, np.column_stack([ends_ok[ii], ends_ok[jj]]))
