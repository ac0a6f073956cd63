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

Two commands must not write one report directory at once (the later one would silently
replace the earlier's files, or mix them): :func:`claim_report_directory` creates the
directory and, atomically (``O_CREAT | O_EXCL``), a lock file :data:`LOCK_NAME` holding the
process id, before the work starts; a second command finds it and refuses, ``--force`` or
not. :func:`release_report_directories` removes the lock when the command ends (and the
directory, if the claim created it and nothing was written). A lock whose process is gone
(a killed run) is stale and taken over.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from robocal_uncertainty.errors import ConfigError

__all__ = [
    "LOCK_NAME",
    "REPORT_FILE_PATTERNS",
    "check_output_file",
    "check_report_directory",
    "claim_report_directory",
    "clear_earlier_report",
    "release_report_directories",
]

LOCK_NAME = ".robocal-uncertainty.lock"
"""Lock file of a report directory being written (holds the writer's process id)."""

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
        _refuse_foreign_lock(out, option)
        if any(p.name != LOCK_NAME for p in out.iterdir()) and not force:
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


_CLAIMS: list[tuple[Path, Path, bool]] = []
"""This process's claims: (lock file, directory, whether the claim created the directory)."""


def _lock_owner(lock: Path) -> int | None:
    """Process id written in `lock`, or None when unreadable (being written, or garbage)."""
    try:
        text = lock.read_text(encoding="utf-8").strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def _alive(pid: int) -> bool:
    """Whether process `pid` exists (signal 0 sends nothing)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # exists, another user's
    except OSError:
        return False
    return True


def _refuse_foreign_lock(out: Path, option: str) -> None:
    """Raise when another live process holds `out`'s lock; remove a stale lock."""
    lock = out / LOCK_NAME
    if not lock.exists():
        return
    owner = _lock_owner(lock)
    if owner == os.getpid():
        return
    if owner is None or _alive(owner):
        who = f"process {owner}" if owner is not None else "another process"
        msg = (
            f"report directory {_where(option)}{out} is being written by another command ({who}, lock file "
            f"{LOCK_NAME}): wait for it to finish, or give another --out"
        )
        raise ConfigError(msg)
    lock.unlink(missing_ok=True)  # its writer is gone


def claim_report_directory(path: str | Path, *, option: str = "--out") -> Path:
    """Create report directory `path` if needed and lock it for this process; return it.

    Call after :func:`check_report_directory`, before the work; the claim lasts until
    :func:`release_report_directories`.

    Raises
    ------
    ConfigError
        Another live process holds the directory's lock (one line naming it), or the
        directory cannot be created.
    """
    out = Path(path)
    created = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        msg = f"cannot create the report directory {_where(option)}{out}: {err.strerror or err}"
        raise ConfigError(msg) from err
    lock = out / LOCK_NAME
    for _ in range(2):
        _refuse_foreign_lock(out, option)
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            if _lock_owner(lock) == os.getpid():
                return out
            continue  # a stale lock just removed, or a writer that won the race: look again
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(f"{os.getpid()}\n")
        _CLAIMS.append((lock, out, created))
        return out
    _refuse_foreign_lock(out, option)
    msg = f"cannot lock the report directory {_where(option)}{out}: its lock file {LOCK_NAME} keeps reappearing"
    raise ConfigError(msg)


def release_report_directories() -> None:
    """Remove this process's locks (and the directories a claim created that stayed empty)."""
    while _CLAIMS:
        lock, out, created = _CLAIMS.pop()
        if _lock_owner(lock) == os.getpid():
            lock.unlink(missing_ok=True)
        if created and out.is_dir() and not any(out.iterdir()):
            out.rmdir()
