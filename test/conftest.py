"""Every test runs in its own empty working directory.

A user runs the README's two commands from the project directory: the demo leaves
``robocal_report/`` there, and a test that relied on the working directory (a default
``--out``, a relative path) would then meet it. Tests locate the project's files from their
own path, so the working directory can be a fresh one.
"""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass
from pathlib import Path

import pytest

from robocal_uncertainty._threads import limit_threads

# BLAS single-threaded, as the command line and the nodes run it (robocal_uncertainty/_threads.py):
# the Monte Carlo is many small batched products, where BLAS threads only add synchronisation.
# On the loaded 2-core development machine (load average 14-17) the pooled simulated hold-out
# test (6 campaigns of 253 poses, 2000 trials) took 81-98 s with two BLAS threads and 23-27 s
# with one (CPU 20-22 s and 6-7 s). Set before any test module loads numpy; an explicit
# setting in the environment wins.
# numba's thread count too: importing the command line sets it to 1 (limit_threads), and numba
# refuses a thread count that changes after its threads started, so a kernel test run on its own
# (`pytest test/kernels`) failed at its first compile after a command-line test had run.
limit_threads()

REAL_UR10_CSV = Path(__file__).resolve().parent / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv"


@dataclass(frozen=True)
class CommandLineCalibration:
    """What ``import-csv`` then ``calibrate --json`` left behind, for tests that read it."""

    campaign: Path
    calibration: Path
    printed: str
    errors: str


@pytest.fixture(scope="session")
def real_ur10_calibration(tmp_path_factory: pytest.TempPathFactory) -> CommandLineCalibration:
    """The README's real UR10 series imported and calibrated once, by the command line.

    A calibration with its session record of the 632 poses takes ~30 s; five test modules read
    one, and CI runs the suite three times (current, Jazzy-era and Humble-era numpy). Tests must
    treat the files as read-only and write their own outputs to their own ``tmp_path``.
    """
    from robocal_uncertainty.cli import main

    if not REAL_UR10_CSV.exists():
        pytest.skip("UR10 data not present")
    folder = tmp_path_factory.mktemp("real_ur10")
    campaign, calibration = folder / "ur10.mcap", folder / "cal.json"
    printed, errors = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(printed), contextlib.redirect_stderr(errors):
        assert main(["import-csv", str(REAL_UR10_CSV), "--out", str(campaign)]) == 0
        start = printed.tell()
        assert main(["calibrate", str(campaign), "--robot", "ur10", "--json", str(calibration)]) == 0
    return CommandLineCalibration(campaign, calibration, printed.getvalue()[start:], errors.getvalue())


@pytest.fixture(autouse=True)
def _fresh_working_directory(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> Path:
    cwd = tmp_path_factory.mktemp("cwd")
    monkeypatch.chdir(cwd)
    return cwd
