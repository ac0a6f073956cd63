"""Command line: ``robocal-uncertainty <command>`` (also ``python -m robocal_uncertainty``).

One module per command (``evaluate.py``, ``validate.py``, ...), as ros2cli has one per verb:
each declares its options and does its printing; what several commands share lives in
``_options`` (option groups), ``_common`` (reading robots, campaigns and joint values),
``_evaluation`` (the Monte Carlo commands' run and printing) and ``_checks`` (every option and
output path checked before any work). Every command is a thin shell over the library: it
parses arguments, calls the same functions the tests and the ROS nodes call, and prints. A
:class:`~robocal_uncertainty.errors.CalibError` ends the command with its one-line message on
stderr and exit status 1.
"""

import os

# Trials are batched into many small matrix products; BLAS threads only add synchronisation
# there (measured 2.7x slower on 2 cores). Parallelism comes from --workers processes.
# Must be set before numpy loads its BLAS; a user's explicit setting wins. The numba
# backend's kernels likewise run on one thread per process (its threads waiting between the
# many short kernel calls cost more than they gave on the shared 2-core machine).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from typing import TYPE_CHECKING

from robocal_uncertainty._lazy import lazy_exports

# The parser and the dask address pattern stay importable from here for tests and tools.
from robocal_uncertainty.cli._checks import _DASK_ADDRESS as _DASK_ADDRESS
from robocal_uncertainty.cli._main import _build_parser as _build_parser

if TYPE_CHECKING:
    from robocal_uncertainty.cli._main import main
    from robocal_uncertainty.cli.demo import PAPER_TEST_JOINTS_DEG

__all__ = ["PAPER_TEST_JOINTS_DEG", "main"]
__getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)
