"""The ``robocal-uncertainty`` parser and entry point: the verb list, and one place that turns a
:class:`CalibError` into one line on stderr and exit status 1."""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence
from types import ModuleType

from robocal_uncertainty.cli._checks import check_options, check_outputs
from robocal_uncertainty.cli._common import in_cli_words
from robocal_uncertainty.errors import CalibError

VERB_MODULES = (
    "demo",
    "simulate",
    "import_csv",
    "calibrate",
    "fk",
    "evaluate",
    "replay",
    "validate",
    "verify",
    "map",
    "suggest",
    "section",
    "export",
    "compensate",
)
"""The commands, in the order ``--help`` lists them: one module of this package each, with
``register(subparsers)`` (its options) and ``run(args) -> int`` (its work and printing). A new
command is a new module and one name here."""


def _verbs() -> list[ModuleType]:
    return [importlib.import_module(f"robocal_uncertainty.cli.{name}") for name in VERB_MODULES]


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("robocal_uncertainty")
    except PackageNotFoundError:
        return "(not installed)"


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="robocal-uncertainty",
        description="Robot arm calibration from laser-tracker points and its Monte Carlo uncertainty (JCGM 101).",
        epilog="Exit status: 0 success, 1 error (one line on stderr), 2 usage error (argparse), "
        "130 interrupted, 141 output pipe closed (e.g. | head).",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for verb in _verbs():
        verb.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit status."""
    parser = _build_parser()
    args = parser.parse_args(argv)
    try:
        check_options(args)
        check_outputs(args)
        return int(args.func(args))
    except CalibError as err:
        print(f"robocal-uncertainty {args.command}: error: {in_cli_words(str(err))}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"robocal-uncertainty {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (e.g. `| head`): stop quietly, as command-line tools do.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141
    except OSError as err:
        # The checks before the work cannot foresee everything (a full disk, a directory
        # removed or made read-only during the run): still one line, naming the file.
        where = f" {err.filename}" if err.filename is not None else ""
        print(
            f"robocal-uncertainty {args.command}: error: cannot access{where}: {err.strerror or err}", file=sys.stderr
        )
        return 1
    finally:
        from robocal_uncertainty.app.output_paths import release_report_directories

        release_report_directories()
