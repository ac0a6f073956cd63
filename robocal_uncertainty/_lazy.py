"""Lazy exports of a subpackage (PEP 562): ``from robocal_uncertainty.core import identify``
works, but importing one module of a subpackage no longer imports all of its siblings.

A subpackage's ``__init__.py`` lists its exports once, as ordinary imports inside
``if TYPE_CHECKING:`` (so type checkers and editors see the real objects), and hands its
module-level ``__getattr__`` and ``__dir__`` to :func:`lazy_exports`::

    from typing import TYPE_CHECKING

    from robocal_uncertainty._lazy import lazy_exports

    if TYPE_CHECKING:
        from robocal_uncertainty.core.campaign import Campaign

    __all__ = ["Campaign"]
    __getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)

On the first access to a name, the ``TYPE_CHECKING`` block of that ``__init__.py`` is read
with :mod:`ast` (the way ``lazy_loader.attach_stub`` reads a ``.pyi`` stub), and the
defining module is imported then. One list, read by both the type checker and the loader,
so the two cannot drift apart; a test checks that it equals ``__all__``.
"""

from __future__ import annotations

import ast
import importlib
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

__all__ = ["lazy_exports", "type_checking_imports"]


def type_checking_imports(path: str | Path) -> dict[str, tuple[str, str]]:
    """Exported name -> (defining module, name there), from the ``if TYPE_CHECKING:`` block.

    Only absolute ``from module import name [as alias]`` statements count.
    """
    tree = ast.parse(Path(path).read_text(encoding="utf-8"), filename=str(path))
    out: dict[str, tuple[str, str]] = {}
    for node in tree.body:
        if not (isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING"):
            continue
        for statement in node.body:
            if isinstance(statement, ast.ImportFrom) and statement.module and statement.level == 0:
                for alias in statement.names:
                    out[alias.asname or alias.name] = (statement.module, alias.name)
    return out


def lazy_exports(
    package: str, init_file: str, names: Sequence[str]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """Module ``__getattr__`` and ``__dir__`` of `package` exporting `names` lazily.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    init_file : str
        The package's ``__file__`` (its ``__init__.py``), whose ``TYPE_CHECKING`` imports
        say where each name is defined.
    names : sequence of str
        The package's ``__all__``.
    """
    exported = frozenset(names)
    table: dict[str, tuple[str, str]] = {}

    def __getattr__(name: str) -> Any:
        if name not in exported:
            msg = f"module {package!r} has no attribute {name!r}"
            raise AttributeError(msg)
        if not table:
            table.update(type_checking_imports(init_file))
        module, attribute = table[name]
        value = getattr(importlib.import_module(module), attribute)
        importlib.import_module(package).__dict__[name] = value  # later lookups skip __getattr__
        return value

    def __dir__() -> list[str]:
        return sorted(set(importlib.import_module(package).__dict__) | exported)

    return __getattr__, __dir__
