"""Output paths, checked before any work starts: one overwrite rule for every command.

The rule: an output file that exists, or a report directory that exists and is not empty,
is refused unless the caller passes ``force`` (the command line's ``--force``). With
``force`` a file is replaced and a report directory is reused after the files of an
earlier report (:data:`REPORT_FILE_PATTERNS`, e.g. sweep plots a ``--no-sweeps`` run would
not rewrite) are removed; files that no report writes are left alone.

:func:`check_output_file` and :func:`check_report_directory` only look; they raise
:class:`~robocal_uncertainty.errors.ConfigError` with one line naming the path and the
option, so a command fails before its computation instead of after it.
:func:`clear_earlier_report` removes the stale files and is called just before the new
report is written (a run that fails keeps the earlier report).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from robocal_uncertainty.errors import ConfigError

__all__ = ["REPORT_FILE_PATTERNS", "check_output_file", "check_report_directory", "clear_earlier_report"]

REPORT_FILE_PATTERNS: tuple[str, ...] = (
    "report.json",
    "report.md",
    "report.html",
    "configurations.csv",
    "configurations.png",
    "uncertainty_vs_reach.png",
    "histograms_*.png",
    "position_error_*.png",
    "rotation_histograms_*.png",
    "lcurve.png",
    "parameters.png",
    "sweep_*.png",
    "validation.json",
    "validation.md",
    "reliability.png",
    "map.csv",
    "map.json",
    "map.md",
    "map.png",
)
"""File names (glob patterns) written by the uncertainty, validation and map reports."""


def _where(option: str) -> str:
    return f"{option} " if option else ""


def _writable(directory: Path) -> bool:
    """Whether a file can be created in `directory`: the permission bits, then a real
    (anonymous, removed at once) temporary file, for what the bits do not show (a read-only
    mount, ``/proc``, or any directory when running as root)."""
    if not os.access(directory, os.W_OK | os.X_OK):
        return False
    try:
        with tempfile.TemporaryFile(dir=directory):
            pass
    except OSError:
        return False
    return True


def _check_parent(path: Path, option: str) -> None:
    parent = path.parent if str(path.parent) else Path()
    probe = parent
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        msg = f"cannot write {_where(option)}{path}: {probe} is a file, not a directory"
        raise ConfigError(msg)
    if not parent.exists():
        msg = f"cannot write {_where(option)}{path}: directory {parent} does not exist"
        raise ConfigError(msg)
    if not _writable(parent):
        msg = f"cannot write {_where(option)}{path}: directory {parent} is not writable"
        raise ConfigError(msg)


def check_output_file(path: str | Path, *, force: bool, option: str = "") -> Path:
    """Refuse an output file that cannot or must not be written; return it as a Path.

    Parameters
    ----------
    path : str or Path
        File to be written.
    force : bool
        Replace an existing file.
    option : str
        How the caller named the path (e.g. ``"--json"``), used in the message.

    Raises
    ------
    ConfigError
        `path` is a directory; exists and `force` is False; its directory is missing, is a
        file or is not writable.
    """
    out = Path(path)
    if out.is_dir():
        msg = f"cannot write {_where(option)}{out}: it is a directory"
        raise ConfigError(msg)
    if out.exists() and not force:
        msg = f"{_where(option)}{out} exists already (give --force to replace it)"
        raise ConfigError(msg)
    if out.exists() and not os.access(out, os.W_OK):
        msg = f"cannot write {_where(option)}{out}: the file is not writable"
        raise ConfigError(msg)
    _check_parent(out, option)
    return out


def check_report_directory(path: str | Path, *, force: bool, option: str = "--out") -> Path:
    """Refuse a report directory that cannot or must not be written; return it as a Path.

    A missing directory is fine (it is created with its parents, which must lie under a
    writable existing directory); an empty one too; a non-empty one only with `force`.

    Raises
    ------
    ConfigError
        `path` is a file; a non-empty directory and `force` is False; not writable; a
        component of its parents is a file.
    """
    out = Path(path)
    if out.exists() and not out.is_dir():
        msg = f"cannot write the report to {_where(option)}{out}: it is a file, not a directory"
        raise ConfigError(msg)
    if out.is_dir():
        if any(out.iterdir()) and not force:
            msg = (
                f"report directory {_where(option)}{out} exists and is not empty "
                "(give --force to replace the earlier report, or another --out)"
            )
            raise ConfigError(msg)
        if not _writable(out):
            msg = f"cannot write the report to {_where(option)}{out}: the directory is not writable"
            raise ConfigError(msg)
        return out
    probe = out.parent
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if not probe.is_dir():
        msg = f"cannot write the report to {_where(option)}{out}: {probe} is a file, not a directory"
        raise ConfigError(msg)
    if not _writable(probe):
        msg = f"cannot write the report to {_where(option)}{out}: directory {probe} is not writable"
        raise ConfigError(msg)
    return out


def clear_earlier_report(path: str | Path) -> list[Path]:
    """Remove the files an earlier report left in directory `path`; return them.

    Only regular files matching :data:`REPORT_FILE_PATTERNS` directly in `path` are
    removed; anything else stays. A missing directory is fine.
    """
    out = Path(path)
    removed: list[Path] = []
    if not out.is_dir():
        return removed
    for pattern in REPORT_FILE_PATTERNS:
        for stale in sorted(out.glob(pattern)):
            if stale.is_file() and not stale.is_symlink():
                stale.unlink()
                removed.append(stale)
    return removed
