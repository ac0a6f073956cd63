"""Layer order of the package, read from every import statement (function-level ones too).

Each subpackage imports only its own layer's peers and the layers below it, and the
subpackages form no import cycle. Bottom to top::

    errors, _lazy, _threads
    core, montecarlo, kernels
    uncertainty, inspection
    bagio, importers
    pipeline
    report
    app
    cli, nodes, __main__

Also: the lazy exports of every subpackage ``__init__.py`` name exactly its ``__all__``, no
export shares its name with a submodule (importing the submodule would hide it), and
importing a small module loads few modules of the package.
"""

from __future__ import annotations

import ast
import importlib
import json
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import pytest

import robocal_uncertainty
from robocal_uncertainty._lazy import type_checking_imports

PACKAGE = "robocal_uncertainty"
PACKAGE_DIR = Path(robocal_uncertainty.__file__).resolve().parent
RANK = {
    "errors": 0,
    "_lazy": 0,
    "_threads": 0,  # the thread policy, set before numpy loads
    "msg": 0,  # interfaces rosidl generates in a colcon build
    "srv": 0,
    "core": 1,
    "montecarlo": 1,
    "kernels": 1,  # trial-kernel backends: the chain walk (core) compiled or on an array module
    "uncertainty": 2,
    "inspection": 2,
    "bagio": 3,
    "importers": 3,
    "pipeline": 4,
    "report": 5,
    "app": 6,
    "cli": 7,
    "nodes": 7,
    "__main__": 8,
}


def _modules() -> list[tuple[str, Path]]:
    out = []
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        rel = path.relative_to(PACKAGE_DIR)
        if "__pycache__" in rel.parts or rel.parts[0] == "msg":
            continue
        parts = [PACKAGE, *rel.with_suffix("").parts]
        is_package = parts[-1] == "__init__"
        if is_package:
            parts.pop()
        out.append((".".join(parts), path))
    return out


def _layer(module: str) -> str | None:
    """The subpackage (or top-level module) of `module`; None for the package root."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def imports_of(name: str, path: Path) -> list[tuple[str, int]]:
    """(imported package module, line) of every import statement in the file, anywhere."""
    is_package = path.name == "__init__.py"
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            found += [(alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".")
                base = base if is_package else base[:-1]
                base = base[: len(base) - node.level + 1]
                module = ".".join([*base, node.module] if node.module else base)
            else:
                module = node.module or ""
            found.append((module, node.lineno))
            # "from package import submodule"
            found += [(f"{module}.{alias.name}", node.lineno) for alias in node.names if module == PACKAGE]
    return [(m, line) for m, line in found if m == PACKAGE or m.startswith(PACKAGE + ".")]


def _graph() -> tuple[dict[str, set[str]], list[str]]:
    edges: dict[str, set[str]] = defaultdict(set)
    violations = []
    for name, path in _modules():
        source = _layer(name)
        if source is None:
            continue
        if source not in RANK:
            violations.append(f"{name}: subpackage {source!r} has no place in RANK (add it to test_layers.py)")
            continue
        for target_module, line in imports_of(name, path):
            target = _layer(target_module)
            if target is None or target == source:
                continue
            if target not in RANK:
                violations.append(f"{name}:{line} imports {target_module}, a subpackage with no place in RANK")
                continue
            edges[source].add(target)
            if RANK[target] > RANK[source]:
                violations.append(f"{name}:{line} ({source}) imports {target_module} ({target}), a higher layer")
    return edges, violations


def test_every_import_goes_down_or_sideways() -> None:
    _, violations = _graph()
    assert not violations, "layer order broken:\n" + "\n".join(violations)


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    cycles, state, stack = [], {}, []

    def visit(node: str) -> None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(edges.get(node, ())):
            if state.get(nxt) == 1:
                cycles.append([*stack[stack.index(nxt) :], nxt])
            elif nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = 2

    for node in sorted(edges):
        if node not in state:
            visit(node)
    return cycles


def test_no_import_cycle_between_subpackages() -> None:
    edges, _ = _graph()
    assert edges["cli"] and edges["pipeline"]  # the graph was read
    cycles = _cycles(edges)
    assert not cycles, "import cycles between subpackages: " + "; ".join(" -> ".join(c) for c in cycles)


def test_checker_sees_function_level_and_relative_imports(tmp_path: Path) -> None:
    source = (
        "def f():\n    from robocal_uncertainty.cli import main\n"
        "from . import sweeps\nfrom ..app import evaluate\nimport robocal_uncertainty.nodes.common\n"
    )
    path = tmp_path / "mod.py"
    path.write_text(source, encoding="utf-8")
    found = sorted(m for m, _ in imports_of("robocal_uncertainty.uncertainty.mod", path))
    assert found == [
        "robocal_uncertainty.app",
        "robocal_uncertainty.cli",
        "robocal_uncertainty.nodes.common",
        "robocal_uncertainty.uncertainty",
    ]
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == [["a", "b", "c", "a"]]


SUBPACKAGES = sorted(p.parent.name for p in PACKAGE_DIR.glob("*/__init__.py") if p.parent.name not in ("nodes", "msg"))


@pytest.mark.parametrize("subpackage", SUBPACKAGES)
def test_lazy_exports_match_all(subpackage: str) -> None:
    init = PACKAGE_DIR / subpackage / "__init__.py"
    module = importlib.import_module(f"{PACKAGE}.{subpackage}")
    if not hasattr(module, "__all__"):
        pytest.skip(f"{subpackage} exports nothing yet")
    lazy = type_checking_imports(init)
    assert sorted(lazy) == sorted(module.__all__), f"{subpackage}: TYPE_CHECKING imports differ from __all__"
    submodules = {p.stem for p in init.parent.glob("*.py")} | {p.parent.name for p in init.parent.glob("*/__init__.py")}
    assert not set(module.__all__) & submodules, f"{subpackage}: an export is named like a submodule"
    for name in module.__all__:
        assert getattr(module, name) is not None
        assert name in dir(module)
    with pytest.raises(AttributeError, match="no attribute"):
        getattr(module, "no_such_name")  # noqa: B009


def _fresh_import_count(module: str) -> int:
    code = (
        f"import json, sys; import {module}; "
        f"print(json.dumps(sorted(m for m in sys.modules if m.startswith('{PACKAGE}'))))"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    return len(json.loads(proc.stdout))


def test_importing_a_value_type_stays_small() -> None:
    """``pipeline.sample`` loaded 37 package modules before the exports became lazy."""
    assert _fresh_import_count("robocal_uncertainty.pipeline.sample") <= 8
    assert _fresh_import_count("robocal_uncertainty.core.sample") <= 6
