"""``suggest --check`` runs its Monte Carlo checks on the chosen trial kernels (``--backend``),
records them, and gives the numpy backend's numbers to rounding; an unavailable backend stops
with one line before any work."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.app import suggest_poses
from robocal_uncertainty.cli import main
from robocal_uncertainty.core import SimulationSettings, load_robot_model, simulate_campaign
from robocal_uncertainty.core.robot_formats.robot_yaml import resolve_robot_config
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.kernels import CupyBackend, NumbaBackend

TEST_Q = np.radians([[-7.5, -234.5, -106.7, -92.4, -61.5, 20.7]])


def test_monte_carlo_checks_on_each_backend_agree() -> None:
    model = load_robot_model(resolve_robot_config("paper_arm"))
    campaign = simulate_campaign(model, SimulationSettings(n_poses=20), seed=3).campaign
    backends = ["numpy", "numba"] if NumbaBackend().available() else ["numpy"]
    results = {
        name: suggest_poses(
            model, campaign, TEST_Q, n_candidates=40, count=2, monte_carlo_check=1, trials=400, backend=name
        )
        for name in backends
    }
    want = results["numpy"]
    assert want.backend is not None
    assert want.backend.name == "numpy"
    for name, got in results.items():
        assert got.backend is not None
        assert got.backend.name == name
        assert got.monte_carlo_current_u_m == pytest.approx(want.monte_carlo_current_u_m, rel=1e-12, abs=0.0)
        assert got.suggestions[0].monte_carlo_u_m == pytest.approx(
            want.suggestions[0].monte_carlo_u_m, rel=1e-12, abs=0.0
        )
    # No check: no Monte Carlo, no backend recorded.
    plain = suggest_poses(model, campaign, TEST_Q, n_candidates=40, count=2, backend="numpy")
    assert plain.backend is None
    with pytest.raises(ConfigError, match="backend must be one of"):
        suggest_poses(model, campaign, TEST_Q, n_candidates=40, count=2, backend="fortran")


def test_cli_suggest_backend(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from robocal_uncertainty.kernels import registry

    campaign = tmp_path / "c.mcap"
    assert main(["simulate", "--robot", "paper_arm", "--out", str(campaign), "--poses", "20", "--seed", "3"]) == 0
    common = ["suggest", str(campaign), "--robot", "paper_arm", "--candidates", "40", "--count", "2"]
    common += ["--test-joints", "0.1", "-1.9", "-1.2", "-1.6", "-1.1", "0.4", "--check", "1", "--trials", "400"]
    monkeypatch.setitem(registry._REGISTRY, "cupy", CupyBackend(module="no_such_array_module"))
    capsys.readouterr()
    assert main([*common, "--backend", "cupy", "--json", str(tmp_path / "gpu.json")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("robocal-uncertainty suggest: error: backend 'cupy' is not available")
    assert not (tmp_path / "gpu.json").exists()
    name = "numba" if NumbaBackend().available() else "numpy"
    assert main([*common, "--backend", "auto", "--json", str(tmp_path / "s.json")]) == 0
    assert f"; backend {name} " in capsys.readouterr().out
    data = json.loads((tmp_path / "s.json").read_text())
    assert data["monte_carlo_backend"]["name"] == name
    assert data["monte_carlo_backend"]["requested"] == "auto"
