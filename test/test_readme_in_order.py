"""The README's examples, run as a new user runs them: one fresh folder, in the README's order.

Every ``robocal-uncertainty`` command of the README's ``bash`` blocks is taken from the README
itself (continuation lines joined, trailing comments dropped), so the test follows the README
when it changes. A command followed by a ``# error: ...`` comment line must fail with that
message; every other one must succeed, so no example is refused because an earlier one left its
output where a later one writes (the output-files rule). Only the trial counts are reduced
(``--trials`` to at most 2 000, the budget's and sweeps' counts too), as the README allows for a
test; nothing else of the command lines is changed.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from robocal_uncertainty.cli import main

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PROGRAM = "robocal-uncertainty"
SCRIPT = "python3 benchmarks/"
"""A README line that runs one of the repository's scripts (e.g. to write an example's inputs)."""
SERIES_B = ROOT.parent / "shared" / "data" / "ur10_laser_tracker" / "series_b"
_TRIALS = 2000
_MONTE_CARLO = ("demo", "evaluate", "validate", "replay", "map", "suggest")


def readme_commands(text: str) -> list[tuple[list[str], str | None]]:
    """The README's commands in order: (argv after the program name, expected error or None)."""
    commands: list[tuple[list[str], str | None]] = []
    for block in re.findall(r"```bash\n(.*?)```", text, flags=re.S):
        joined = re.sub(r"\\\n\s*", " ", block)
        for line in joined.splitlines():
            stripped = line.strip()
            if stripped.startswith("# error:") and commands:
                argv, _ = commands[-1]
                commands[-1] = (argv, stripped[len("# error:") :].strip())
                continue
            for piece in stripped.split("&&"):
                part = piece.split(" #")[0].strip()
                if part.startswith(PROGRAM + " "):
                    commands.append((shlex.split(part)[1:], None))
                elif part.startswith(SCRIPT):
                    commands.append((shlex.split(part), None))
    return commands


def reduced(argv: list[str]) -> list[str]:
    """`argv` with the trial counts reduced (and nothing else changed)."""
    out = list(argv)
    if out[0] not in _MONTE_CARLO:
        return out
    if "--trials" in out:
        i = out.index("--trials") + 1
        if out[i] != "auto" and int(out[i]) > _TRIALS:
            out[i] = str(_TRIALS)
    else:
        out += ["--trials", str(_TRIALS)]
    if out[0] != "validate":
        out += ["--budget-trials", "300", "--sweep-trials", "60"]
    return [*out, "--no-progress"]


def test_readme_commands_are_found() -> None:
    commands = readme_commands(README.read_text(encoding="utf-8"))
    verbs = [argv[0] for argv, _ in commands]
    # The examples the README walks through, in its order (a guard against a parser that
    # silently finds nothing to run).
    for verb in ("demo", "import-csv", "calibrate", "evaluate", "validate", "export", "simulate", "verify"):
        assert verb in verbs
    assert verbs[0] == "demo" and sum(1 for _, err in commands if err) >= 1


@pytest.mark.slow
def test_readme_examples_run_in_one_folder_in_order(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "test").mkdir()
    (tmp_path / "test" / "data").symlink_to(ROOT / "test" / "data")
    (tmp_path / "robocal_uncertainty").symlink_to(ROOT / "robocal_uncertainty")
    (tmp_path / "benchmarks").symlink_to(ROOT / "benchmarks")
    if not SERIES_B.is_dir():
        pytest.skip(f"the README's real-session example reads Series B from {SERIES_B} (shared/ beside the repository)")
    monkeypatch.chdir(tmp_path)
    outputs = {}
    for argv, expected_error in readme_commands(README.read_text(encoding="utf-8")):
        if argv[0] == "python3":  # a repository script, run as the README says, in this folder
            env = {**os.environ, "PYTHONPATH": str(ROOT)}
            done = subprocess.run([sys.executable, *argv[1:]], capture_output=True, text=True, env=env, check=False)
            assert done.returncode == 0, f"README command: {' '.join(argv)}\n{done.stderr[-2000:]}"
            continue
        status = main(reduced(argv))
        captured = capsys.readouterr()
        where = f"README command: {PROGRAM} {' '.join(argv)}\n{captured.err[-2000:]}"
        if expected_error is None:
            # verify's exit status is its verdict: 0 consistent, 3 drifted (the README shows both).
            assert status == 0 or (argv[0] == "verify" and status == 3 and captured.out.startswith("drifted")), where
        else:
            assert status == 1, where
            assert expected_error.split("(...)")[0] in captured.err, where
        outputs[" ".join(argv)] = captured.out
    # Two of the printed lines the README quotes for these commands.
    export = next(out for cmd, out in outputs.items() if cmd.startswith("export cal.json --format ur-kinematics"))
    assert "25 determined by the data; covariance included" in export
    verify = next(out for cmd, out in outputs.items() if cmd.startswith("verify session1_cal.json"))
    assert verify.startswith("drifted:")
