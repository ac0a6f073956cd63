"""Sizes that do not fit are refused before the work, naming the size (issue 18).

The estimates are checked against the memory the runs really allocate (tracemalloc counts
numpy's buffers): never below it, and not so far above that feasible runs are refused.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.cli import main
from robocal_uncertainty.core.identification import identify
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model
from robocal_uncertainty.core.simulation import SimulationSettings, simulate_campaign
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty.calibration import evaluate_uncertainty
from robocal_uncertainty.uncertainty.memory import (
    available_memory,
    check_fits,
    evaluation_bytes,
    map_bytes,
)
from robocal_uncertainty.uncertainty.workspace_map import map_workspace, sample_configurations

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "config" / "paper_arm.yaml"


@pytest.fixture(scope="module")
def model():
    return load_robot_model(PAPER)


@pytest.fixture(scope="module")
def campaign(model):
    return simulate_campaign(model, SimulationSettings(frame="tracker"), seed=2).campaign


def test_check_fits_names_the_size_and_what_is_available() -> None:
    check_fits(0.89 * 2**30, "x", "y", available=2**30)
    with pytest.raises(ConfigError) as exc:
        check_fits(3 * 2**30, "--trials 9", "use fewer --trials", available=2**30)
    assert str(exc.value) == (
        "--trials 9 needs about 3 GiB of memory, more than the 1 GiB available to this process: use fewer --trials"
    )


def _peak(run) -> int:
    tracemalloc.start()
    try:
        run()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_evaluation_estimate_bounds_the_real_allocation(model, campaign) -> None:
    calibration = identify(model, campaign)
    q = campaign.joint_positions[:2]
    trials = 40_000
    peak = _peak(lambda: evaluate_uncertainty(model, campaign, q, calibration=calibration, trials=trials))
    k = int(np.count_nonzero(calibration.estimated))
    estimate = evaluation_bytes(trials, 2, k, n_poses=campaign.n_poses, n_joints=model.n_joints, block_rows=10_000)
    assert peak <= estimate <= 3 * peak, (peak, estimate)


def test_map_estimate_bounds_the_real_allocation(model, campaign) -> None:
    calibration = identify(model, campaign)
    q = sample_configurations(model, 1500, rng=np.random.default_rng(1))
    peak = _peak(lambda: map_workspace(model, campaign, q, calibration=calibration, trials=1000, block_size=500))
    estimate = map_bytes(1500, model.n_joints, campaign.n_poses, block_rows=500, workers=1, n_trials=1000, n_regions=10)
    assert peak <= estimate <= 3 * peak, (peak, estimate)


def test_map_grid_that_cannot_fit_is_refused_before_any_work(tmp_path, capsys) -> None:
    """--grid 50 on 6 joints is 1.6e10 configurations: it used to end in a 116 GiB allocation traceback."""
    path = tmp_path / "c.mcap"
    assert main(["simulate", "--robot", "paper_arm", "--frame", "tracker", "--out", str(path), "--seed", "1"]) == 0
    capsys.readouterr()
    assert main(["map", str(path), "--robot", "paper_arm", "--grid", "50", "--out", str(tmp_path / "m")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith(
        "robocal-uncertainty map: error: a grid of 50 x 50 x 50 x 50 x 50 x 50 = 15 625 000 000 configurations "
        "needs about 1.36 TiB of memory, more than the "
    )
    assert err.endswith("use fewer values per joint (--grid), or --configurations N random ones")
    assert "\n" not in err
    assert not (tmp_path / "m").exists()


LIMIT = 1 << 30  # 1 GiB of address space, as `ulimit -v 1048576`


def _limited(argv: list[str]) -> subprocess.CompletedProcess[str]:
    import resource

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (LIMIT, LIMIT))

    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    return subprocess.run(
        [sys.executable, "-m", "robocal_uncertainty", *argv],
        cwd=ROOT,
        env=env,
        preexec_fn=limit,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


def test_trials_that_cannot_fit_under_a_memory_limit_are_refused(tmp_path) -> None:
    """evaluate --trials 2000000 under a 1 GiB limit used to end in a traceback; now one line,
    and 20 000 trials under the same limit still run."""
    path = tmp_path / "c.mcap"
    assert main(["simulate", "--robot", "paper_arm", "--out", str(path), "--seed", "1"]) == 0
    joints = ["--test-joints", "0.5", "-1.9", "1.2", "0.3", "1.0", "0.2", "--no-budget", "--no-sweeps"]
    big = _limited(["evaluate", str(path), "--robot", "paper_arm", "--trials", "2000000", *joints, "--out", "b"])
    assert big.returncode == 1, big.stderr
    (line,) = big.stderr.strip().splitlines()
    assert line.startswith(
        "robocal-uncertainty evaluate: error: --trials 2000000 at 1 test configuration needs about 961 MiB of "
        "memory, more than the "
    )
    assert line.endswith("available to this process: use fewer --trials (or fewer test configurations)")
    out = tmp_path / "small"
    small = _limited(["evaluate", str(path), "--robot", "paper_arm", "--trials", "20000", *joints, "--out", str(out)])
    assert small.returncode == 0, small.stderr
    assert (out / "report.json").is_file()


def test_available_memory_follows_the_address_space_limit() -> None:
    code = "from robocal_uncertainty.uncertainty.memory import available_memory; print(available_memory())"
    import resource

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (LIMIT, LIMIT))

    got = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        preexec_fn=limit,
        capture_output=True,
        text=True,
        check=True,
    )
    value = int(got.stdout)
    assert 0 < value < LIMIT
    assert available_memory() is not None


def test_validate_and_map_trials_that_cannot_fit_are_refused(tmp_path, capsys) -> None:
    """validate holds every trial of a chunk of held-out poses (at least 16, or all of them);
    map --regions N keeps every trial of N configurations: 10^8 and 10^9 trials cannot fit.
    (A map without regions streams its trials: its memory does not grow with --trials.)"""
    path = tmp_path / "c.mcap"
    assert main(["simulate", "--robot", "paper_arm", "--frame", "tracker", "--out", str(path), "--seed", "1"]) == 0
    capsys.readouterr()
    argv = ["validate", str(path), "--robot", "paper_arm", "--trials", "100000000", "--out", str(tmp_path / "v")]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith(
        "robocal-uncertainty validate: error: --trials 100000000 with 13 held-out poses per Monte Carlo needs about "
    )
    assert err.endswith("available to this process: use fewer --trials")
    argv = ["map", str(path), "--robot", "paper_arm", "--configurations", "100", "--regions", "50"]
    assert main([*argv, "--trials", "1000000000", "--out", str(tmp_path / "m")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith(
        "robocal-uncertainty map: error: a map of 100 configurations x 1 000 000 000 trials (1 000 trials per block, "
        "1 worker, 50 with a region) needs about 1.09 TiB of memory"
    )
    assert err.endswith("or fewer --trials or --regions")
    assert not (tmp_path / "v").exists() and not (tmp_path / "m").exists()
