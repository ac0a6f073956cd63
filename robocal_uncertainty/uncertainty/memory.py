"""Will it fit? Memory estimates checked before a large computation starts.

A Monte Carlo with two million trials, or a workspace map on a full 6-joint grid, can need
more memory than the machine has; without a check it ends, after minutes, in an allocation
traceback or the kernel's out-of-memory kill. :func:`check_fits` compares an estimate of
the bytes a run needs with the memory available to this process (``MemAvailable`` of
``/proc/meminfo``, and the address-space and data limits of ``ulimit -v`` / ``-d`` less
what the process already uses) and refuses with one line naming the size, before any work.

The estimates (:func:`evaluation_bytes`, :func:`map_bytes`, :func:`grid_bytes`) count the
arrays the runs hold at their peak, with a factor measured on this code (see each function);
they are meant to catch sizes that cannot fit, not to fine-tune sizes that nearly do: a run
is refused only when the estimate exceeds :data:`USABLE_FRACTION` of what is available.
"""

from __future__ import annotations

import math
import resource
from pathlib import Path

from robocal_uncertainty.errors import ConfigError

__all__ = [
    "USABLE_FRACTION",
    "available_memory",
    "check_fits",
    "evaluation_bytes",
    "format_bytes",
    "grid_bytes",
    "grid_size",
    "map_bytes",
    "validation_bytes",
]

USABLE_FRACTION = 0.9
"""Share of the available memory a run may plan to use."""
_FLOAT = 8


def _meminfo_available() -> int | None:
    try:
        for line in Path("/proc/meminfo").read_text(encoding="ascii").splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _status_bytes(key: str) -> int:
    """A ``/proc/self/status`` size (VmSize, VmData) in bytes; 0 when unknown."""
    try:
        for line in Path("/proc/self/status").read_text(encoding="ascii").splitlines():
            if line.startswith(key + ":"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return 0
    return 0


def available_memory() -> int | None:
    """Bytes this process can still allocate: the machine's available memory, lowered by the
    soft address-space (``ulimit -v``) and data (``ulimit -d``) limits less their current use.

    Returns
    -------
    int or None
        None where none of these can be read (then nothing is refused).
    """
    bounds: list[int] = []
    machine = _meminfo_available()
    if machine is not None:
        bounds.append(machine)
    for limit, used in ((resource.RLIMIT_AS, "VmSize"), (resource.RLIMIT_DATA, "VmData")):
        soft, _ = resource.getrlimit(limit)
        if soft != resource.RLIM_INFINITY:
            bounds.append(max(0, soft - _status_bytes(used)))
    return min(bounds) if bounds else None


def format_bytes(n: float) -> str:
    """``1.2 GiB``-style size."""
    for unit, scale in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{int(n)} B"


def check_fits(n_bytes: float, what: str, hint: str, *, available: int | None = None) -> None:
    """Refuse a run whose estimated memory exceeds what is available.

    Parameters
    ----------
    n_bytes : float
        Estimated peak memory of the run.
    what : str
        The size in the user's words (e.g. ``"--trials 2000000 at 1 test configuration"``).
    hint : str
        What to do instead (e.g. ``"use fewer --trials"``).
    available : int, optional
        Bytes available; default :func:`available_memory`.

    Raises
    ------
    ConfigError
        One line naming the size, the estimate and the memory available.
    """
    free = available_memory() if available is None else available
    if free is None or n_bytes <= USABLE_FRACTION * free:
        return
    msg = (
        f"{what} needs about {format_bytes(n_bytes)} of memory, more than the {format_bytes(free)} "
        f"available to this process: {hint}"
    )
    raise ConfigError(msg)


def evaluation_bytes(
    n_trials: int,
    n_test: int,
    n_parameters: int,
    *,
    n_poses: int,
    n_joints: int,
    block_rows: int,
    workers: int = 1,
    orientation: bool = True,
) -> int:
    """Peak memory of :func:`~robocal_uncertainty.uncertainty.calibration.evaluation.evaluate_uncertainty`.

    The run keeps every trial's row (positions, parameters and, with orientation, rotations:
    ``3 n_test + k + 3 n_test`` values) and the summary sorts a copy (2 copies); each worker
    holds one block of ``block_rows`` trials with every source's draws for the campaign
    and the test configurations (``n_poses (2 n_joints + 6) + n_test (n_joints + 3)``
    values per trial). Measured with ``evaluate --trials 200000 --no-budget --no-sweeps`` of
    a simulated paper_arm campaign (1 test configuration): peak RSS 81 MB above that of
    2 000 trials, 1.5 copies of the rows; ``test/uncertainty/test_memory_checks.py`` checks
    the estimate against the allocation tracemalloc measures.
    """
    columns = 3 * n_test + n_parameters + (3 * n_test if orientation else 0)
    per_block = n_poses * (2 * n_joints + 6) + n_test * (n_joints + 3) + columns
    return int(_FLOAT * (2 * n_trials * columns + max(1, workers) * min(block_rows, n_trials) * per_block))


def validation_bytes(n_trials: int, n_chunk: int, n_parameters: int, *, n_poses: int, n_joints: int) -> int:
    """Peak memory of one chunk of :func:`~robocal_uncertainty.uncertainty.holdout.validate_holdout`.

    Per trial and held-out pose of the chunk: the Monte Carlo's rows and draws and the
    statistics' copies (the prediction plus noise, the sorted quantiles, the centred region
    samples). Measured with ``benchmarks/bench_validate_memory.py`` (5 000 trials): 1.26 MB
    per held-out pose, 31.5 values per trial and pose; the estimate counts 40, plus the
    campaign's part of :func:`evaluation_bytes`.
    """
    campaign = evaluation_bytes(n_trials, 0, n_parameters, n_poses=n_poses, n_joints=n_joints, block_rows=10_000)
    return int(_FLOAT * 40 * n_trials * n_chunk + campaign)


def grid_bytes(n_configurations: int, n_joints: int) -> int:
    """Memory of a full joint grid: the mesh (one array per joint) and the stacked rows."""
    return int(2 * _FLOAT * n_configurations * n_joints)


def map_bytes(
    n_configurations: int,
    n_joints: int,
    n_poses: int,
    *,
    block_rows: int,
    workers: int,
    n_trials: int,
    n_regions: int,
) -> int:
    """Peak memory of a workspace map's Monte Carlo.

    Each worker holds a block of ``block_rows`` trials: per trial and configuration the tool
    position, the test joints' encoder draws, the residual draws and the forward-kinematics
    temporaries and the reduction's centred copies (``3 + 2 n_joints + 32`` values); the
    campaign's draws per trial; the
    reduction keeps the configurations' means and 3x3 covariances, and every trial of the
    configurations with a coverage region. Also the grid of configurations itself. Measured
    with ``map --configurations 4000 --trials 2000`` of a simulated paper_arm tracker campaign
    (1 000 trials per block): peak RSS 852 MB above that of 100 configurations, 27.3 values
    per trial and configuration; tracemalloc's peak of 1 500 configurations at 500 trials
    per block was 35 (``test/uncertainty/test_memory_checks.py``), and 44 since the map draws
    the residual source by default and predicts through the nearby-point walk; the estimate
    counts 47 (6 joints).
    """
    per_row = n_configurations * (3 + 2 * n_joints + 32) + n_poses * (2 * n_joints + 6)
    blocks = max(1, workers) * block_rows * per_row
    kept = n_trials * 3 * n_regions + 12 * n_configurations
    return int(_FLOAT * (blocks + kept) + grid_bytes(n_configurations, n_joints))


def grid_size(steps: list[int]) -> int:
    """Number of grid configurations (exact, any size)."""
    return math.prod(int(s) for s in steps)
