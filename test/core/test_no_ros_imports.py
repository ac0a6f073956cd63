"""Everything outside ``robocal_uncertainty.nodes`` must work without ROS 2 installed.

Dynamic check: a fresh interpreter with a ``sys.meta_path`` finder that refuses ``rclpy``,
``rosidl*``, ``launch*`` and ``message_filters`` imports every module of the package.
Static check: no module outside ``nodes/`` mentions those in an import statement or in an
``importlib.import_module`` / ``__import__`` call.
"""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

import robocal_uncertainty

PACKAGE_DIR = Path(robocal_uncertainty.__file__).resolve().parent
FORBIDDEN = re.compile(r"^(rclpy|rosidl\w*|launch\w*|message_filters)$")
# nodes/: the ROS 2 layer. msg/: interfaces rosidl generates into the package in a colcon
# build (not our source). __main__: a script that runs the command line when imported.
EXCLUDED_DIRS = ("nodes", "msg")
EXCLUDED_MODULES = ("robocal_uncertainty.__main__",)
# Modules that are an optional extra's implementation and import it at module level (the
# registry imports them only when that backend is asked for): without the extra installed
# they may fail with exactly "No module named <extra>", and nothing else may.
OPTIONAL_EXTRA_MODULES = {
    "robocal_uncertainty.kernels._numba_walk": "numba",
    "robocal_uncertainty.kernels.section_numba": "numba",
    "robocal_uncertainty.kernels.section_denoise_numba": "numba",
}


def package_modules() -> list[tuple[str, Path]]:
    out = []
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        rel = path.relative_to(PACKAGE_DIR)
        if rel.parts[0] in EXCLUDED_DIRS or "__pycache__" in rel.parts:
            continue
        parts = ["robocal_uncertainty", *rel.with_suffix("").parts]
        if parts[-1] == "__init__":
            parts.pop()
        name = ".".join(parts)
        if name not in EXCLUDED_MODULES:
            out.append((name, path))
    return out


_CHILD = r"""
import importlib, json, re, sys, traceback

FORBIDDEN = re.compile(r"^(rclpy|rosidl\w*|launch\w*|message_filters)$")
attempts = []

class RefuseRos:
    def find_spec(self, name, path=None, target=None):
        if FORBIDDEN.match(name.split(".")[0]):
            attempts.append({"name": name, "stack": "".join(traceback.format_stack(limit=8))})
            raise ImportError(f"ROS import {name!r} refused outside robocal_uncertainty.nodes")
        return None

sys.meta_path.insert(0, RefuseRos())
modules = json.loads(sys.argv[1])
guard_ok = False
try:
    import rclpy  # noqa: F401
except ImportError as err:
    guard_ok = "refused" in str(err)
attempts.clear()
errors = {}
by_module = {}
for name in modules:
    before = len(attempts)
    try:
        importlib.import_module(name)
    except BaseException as err:  # noqa: BLE001 - report everything
        errors[name] = f"{type(err).__name__}: {err}"
    if len(attempts) > before:
        by_module[name] = attempts[before:]
print(json.dumps({"guard_ok": guard_ok, "errors": errors, "attempts": by_module}))
"""


@pytest.fixture(scope="module")
def import_report() -> dict:
    names = [name for name, _ in package_modules()]
    assert "robocal_uncertainty.core.identification" in names
    assert "robocal_uncertainty.errors" in names
    assert not any(n.startswith("robocal_uncertainty.nodes") for n in names)
    proc = subprocess.run(
        [sys.executable, "-c", _CHILD, json.dumps(names)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = json.loads(proc.stdout.strip().splitlines()[-1])
    report["modules"] = names
    return report


def test_guard_refuses_ros(import_report: dict) -> None:
    assert import_report["guard_ok"], "the meta_path finder did not refuse 'import rclpy'"


def test_no_module_attempts_a_ros_import(import_report: dict) -> None:
    attempts = import_report["attempts"]
    detail = "\n".join(f"{m}: {[a['name'] for a in lst]}\n{lst[0]['stack']}" for m, lst in attempts.items())
    assert not attempts, f"ROS imports outside nodes/:\n{detail}"


def test_every_module_imports_without_ros(import_report: dict) -> None:
    import importlib.util

    errors = dict(import_report["errors"])
    for module, extra in OPTIONAL_EXTRA_MODULES.items():
        absent = importlib.util.find_spec(extra) is None
        if absent and errors.get(module) == f"ModuleNotFoundError: No module named {extra!r}":
            del errors[module]  # the extra is not installed: its backend is simply not offered
    assert not errors, "modules failing to import with ROS refused:\n" + "\n".join(
        f"{m}: {e}" for m, e in errors.items()
    )


def ros_imports_in(source: str, filename: str = "<src>") -> list[str]:
    """Names of forbidden modules imported by `source` (statements and dynamic calls)."""
    found = []
    for node in ast.walk(ast.parse(source, filename=filename)):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant):
            func = node.func
            called = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            if called in ("import_module", "__import__") and isinstance(node.args[0].value, str):
                names = [node.args[0].value]
        found += [f"{n} (line {node.lineno})" for n in names if FORBIDDEN.match(n.split(".")[0])]
    return found


def test_static_checker_detects_ros_imports() -> None:
    src = (
        "import numpy\nimport rclpy.node\nfrom rosidl_runtime_py import x\n"
        "from launch_ros.actions import Node\nimport message_filters\n"
        "import importlib\nimportlib.import_module('rclpy')\nfrom .launch import y\n"
        "import launchpad_helpers_is_not_ros\n"
    )
    found = sorted(f.split(" ")[0] for f in ros_imports_in(src))
    # 'launch\w*' also matches names like launchpad_*: the rule errs on the strict side.
    assert found == sorted(
        [
            "rclpy.node",
            "rosidl_runtime_py",
            "launch_ros.actions",
            "message_filters",
            "rclpy",
            "launchpad_helpers_is_not_ros",
        ]
    )


def test_no_static_ros_imports_outside_nodes() -> None:
    modules = package_modules()
    assert len(modules) > 10
    offenders = {}
    for name, path in modules:
        found = ros_imports_in(path.read_text(encoding="utf-8"), str(path))
        if found:
            offenders[name] = found
    assert not offenders, f"ROS imports outside nodes/: {offenders}"
