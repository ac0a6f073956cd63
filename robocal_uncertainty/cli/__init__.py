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

from robocal_uncertainty._threads import limit_threads

limit_threads()  # before numpy loads its BLAS (see robocal_uncertainty._threads)

from typing import TYPE_CHECKING

from robocal_uncertainty._lazy import lazy_exports

# The parser and the dask address pattern stay importable from here for tests and tools.
from robocal_uncertainty.cli._checks import _DASK_ADDRESS as _DASK_ADDRESS
from robocal_uncertainty.cli._main import _build_parser as _build_parser

if TYPE_CHECKING:
    from robocal_uncertainty.cli._main import main
    from robocal_uncertainty.report.references import PAPER_TEST_JOINTS_DEG

__all__ = ["PAPER_TEST_JOINTS_DEG", "main"]
__getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)
