"""Digests of what the command line writes, to prove a refactor changes no number.

Runs a fixed set of small, seeded commands (every verb that states a number) in a scratch
folder and prints one SHA-256 per output file, over the file's content with the fields that
legitimately change between runs removed (wall-clock times, compile times, the software
version, paths). Write the digests before a restructuring and compare after every step::

    python tools/behaviour_digests.py --write before.json
    python tools/behaviour_digests.py --compare before.json

The comparison exits 1 and names the files whose digests differ. It takes about two minutes
on two cores. Images are skipped (their bytes carry matplotlib's metadata); the numbers they
show are in the JSON and CSV files beside them.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
UR10_CSV = REPO / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv"
FIXTURES = REPO / "test" / "data" / "compensate"

# Keys whose values are the run's circumstances, not its result.
VOLATILE_KEYS = {
    "elapsed_s",
    "wall_s",
    "seconds",
    "time_s",
    "duration_s",
    "compile_s",
    "compile_time_s",
    "version",
    "created",
    "timestamp",
    "date",
    "path",
    "campaign_source",
    "source_path",
    "host",
    "python",
}

TEST_JOINTS = [
    "--test-joints",
    "0.1",
    "-1.2",
    "1.3",
    "-0.5",
    "1.4",
    "0.2",
    "--test-joints",
    "-0.8",
    "-1.9",
    "1.9",
    "-1.0",
    "-1.1",
    "0.9",
]

# Each entry: (name, argv after `robocal-uncertainty`). Outputs go under the scratch folder.
COMMANDS: list[tuple[str, list[str]]] = [
    ("demo", ["demo", "--trials", "2000", "--out", "demo"]),
    ("simulate", ["simulate", "--robot", "ur10", "--poses", "40", "--out", "sim.mcap", "--seed", "2"]),
    ("calibrate", ["calibrate", "sim.mcap", "--robot", "ur10", "--json", "cal.json"]),
    ("evaluate", ["evaluate", "sim.mcap", "--robot", "ur10", "--trials", "2000", "--out", "evaluate", *TEST_JOINTS]),
    (
        "evaluate_independent",
        [
            "evaluate",
            "sim.mcap",
            "--robot",
            "ur10",
            "--trials",
            "1000",
            "--independent-model-error",
            "--out",
            "evaluate_independent",
            *TEST_JOINTS,
        ],
    ),
    (
        "validate",
        ["validate", "sim.mcap", "--robot", "ur10", "--train-poses", "30", "--trials", "500", "--out", "validate"],
    ),
    ("map", ["map", "sim.mcap", "--robot", "ur10", "--configurations", "60", "--trials", "500", "--out", "map"]),
    ("suggest", ["suggest", "sim.mcap", "--robot", "ur10", "--count", "3", "--json", "suggest.json", *TEST_JOINTS]),
    ("export_urdf", ["export", "cal.json", "--format", "urdf", "--out", "cal.urdf"]),
    ("export_ur", ["export", "cal.json", "--format", "ur-kinematics", "--out", "cal_ur.yaml"]),
    ("simulate_paper", ["simulate", "--robot", "paper_arm", "--out", "paper.mcap", "--seed", "3"]),
    ("calibrate_paper", ["calibrate", "paper.mcap", "--robot", "paper_arm", "--json", "cal_paper.json"]),
    ("export_yaml", ["export", "cal_paper.json", "--format", "yaml", "--out", "cal_paper_robot.yaml"]),
    ("import_csv", ["import-csv", str(UR10_CSV), "--out", "ur10.mcap"]),
    (
        "calibrate_urdf",
        [
            "calibrate",
            "sim.mcap",
            "--robot",
            str(REPO / "robocal_uncertainty" / "data" / "ur10.urdf"),
            "--base-link",
            "base",
            "--tip-link",
            "tool0",
            "--json",
            "cal_urdf.json",
        ],
    ),
    (
        "sessions",
        [
            "simulate",
            "--robot",
            "ur10",
            "--sessions",
            "3",
            "--session-poses",
            "40",
            "40",
            "10",
            "--out",
            "s.mcap",
            "--seed",
            "1",
        ],
    ),
    (
        "calibrate_sessions",
        ["calibrate", "s.session1.mcap", "--robot", "ur10", "--sessions", "s.session2.mcap", "--json", "cal2.json"],
    ),
    (
        "verify",
        ["verify", "cal2.json", "s.session3.mcap", "--robot", "ur10", "--retool", "--effects", "--out", "verify"],
    ),
    (
        "compensate",
        [
            "compensate",
            "cal.json",
            str(FIXTURES / "ur10_fixtures.csv"),
            "--robot",
            "ur10",
            "--campaign",
            "ur10.mcap",
            "--seed-joints-file",
            str(FIXTURES / "ur10_fixture_seeds.txt"),
            "--trials",
            "500",
            "--json",
            "compensation.json",
        ],
    ),
    ("section", ["section", "--demo", "--trials", "2000", "--out", "section"]),
]


def _scrub(value: Any) -> Any:
    """The value with volatile keys removed, recursively."""
    if isinstance(value, dict):
        return {k: _scrub(v) for k, v in value.items() if k not in VOLATILE_KEYS}
    if isinstance(value, list):
        return [_scrub(v) for v in value]
    return value


def _digest(path: Path, workdir: Path) -> str:
    data = path.read_bytes()
    if path.suffix == ".json":
        data = json.dumps(_scrub(json.loads(data)), sort_keys=True).encode()
    # Reports name their inputs by path: the checkout's and the scratch folder's location are
    # circumstances of the run, so both become placeholders (a digest is then the same in any
    # worktree).
    data = data.replace(str(REPO).encode(), b"<repo>").replace(str(workdir).encode(), b"<work>")
    # The software version line of a Markdown report (unknown in a checkout without metadata).
    data = re.sub(rb"(?m)^- software: .*$", b"- software: <version>", data)
    return hashlib.sha256(data).hexdigest()


def run_all(workdir: Path, only: set[str] | None = None) -> dict[str, str]:
    """Run the commands in ``workdir``; return {output file: digest, command: exit status}."""
    env = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    digests: dict[str, str] = {}
    for name, argv in COMMANDS:
        if only and name not in only:
            continue
        proc = subprocess.run(
            [sys.executable, "-m", "robocal_uncertainty", *argv, "--backend", "numpy"]
            if argv[0] in {"evaluate", "validate", "map"}
            else [sys.executable, "-m", "robocal_uncertainty", *argv],
            cwd=workdir,
            env=env,
            capture_output=True,
            text=True,
            check=False,
        )
        digests[f"exit/{name}"] = str(proc.returncode)
        print(f"{name}: exit {proc.returncode}", file=sys.stderr)
        if proc.returncode not in (0, 3):
            print(proc.stderr[-2000:], file=sys.stderr)
    for path in sorted(workdir.rglob("*")):
        if path.is_file() and path.suffix not in {".png", ".html", ".svg"}:
            digests[str(path.relative_to(workdir))] = _digest(path, workdir)
    return digests


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--write", type=Path, help="write the digests to this JSON file")
    group.add_argument("--compare", type=Path, help="compare with digests written earlier")
    parser.add_argument("--keep", type=Path, help="run in this folder (kept) instead of a temporary one")
    parser.add_argument("--only", nargs="*", help="run only these named commands")
    args = parser.parse_args()
    if args.keep:
        args.keep.mkdir(parents=True, exist_ok=True)
        digests = run_all(args.keep, set(args.only) if args.only else None)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            digests = run_all(Path(tmp), set(args.only) if args.only else None)
    if args.write:
        args.write.write_text(json.dumps(digests, indent=1, sort_keys=True) + "\n")
        print(f"{len(digests)} digests written to {args.write}")
        return 0
    before = json.loads(args.compare.read_text())
    if args.only:
        before = {k: v for k, v in before.items() if k in digests}
    differ = sorted(k for k in set(before) | set(digests) if before.get(k) != digests.get(k))
    for key in differ:
        print(f"DIFFERS: {key}: {before.get(key, 'absent')[:12]} -> {digests.get(key, 'absent')[:12]}")
    print(f"{len(digests)} digests, {len(differ)} differ")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
