"""The thread policy the command line and the nodes share: one BLAS/numba thread per process
unless the user says otherwise, set before numpy loads (so the policy module imports no numpy)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from robocal_uncertainty._threads import THREAD_VARIABLES

REPO = Path(__file__).resolve().parents[1]


def _environment_after(code: str, preset: dict[str, str]) -> dict[str, object]:
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES}
    env.update(preset, PYTHONPATH=str(REPO))
    script = (
        f"import json, os, sys; {code}; "
        f"print(json.dumps({{'env': {{k: os.environ.get(k) for k in {THREAD_VARIABLES!r}}}, "
        "'numpy': 'numpy' in sys.modules}))"
    )
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
    return dict(json.loads(proc.stdout))


def test_the_command_line_runs_one_thread_unless_told_otherwise() -> None:
    got = _environment_after("import robocal_uncertainty.cli", {"OMP_NUM_THREADS": "3"})
    assert got["env"] == {
        "OPENBLAS_NUM_THREADS": "1",
        "OMP_NUM_THREADS": "3",
        "MKL_NUM_THREADS": "1",
        "NUMBA_NUM_THREADS": "1",
    }


def test_the_policy_loads_no_numpy() -> None:
    got = _environment_after("from robocal_uncertainty._threads import limit_threads; limit_threads()", {})
    assert got["numpy"] is False
    assert got["env"] == dict.fromkeys(THREAD_VARIABLES, "1")
