"""Every test runs in its own empty working directory.

A user runs the README's two commands from the project directory: the demo leaves
``robocal_report/`` there, and a test that relied on the working directory (a default
``--out``, a relative path) would then meet it. Tests locate the project's files from their
own path, so the working directory can be a fresh one.
"""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(autouse=True)
def _fresh_working_directory(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> Path:
    cwd = tmp_path_factory.mktemp("cwd")
    monkeypatch.chdir(cwd)
    return cwd
