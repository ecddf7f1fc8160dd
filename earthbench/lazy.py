"""Lazy package exports (PEP 562): a package names its public objects without importing them.

A case's process imports only what its planner needs; the packages that re-export many
modules' names (``earthbench``, ``earthbench.running.harness``) load each module on first use
(docs/DESIGN.md §10, start-up).
"""

from __future__ import annotations

import functools
import importlib
from collections.abc import Callable
from typing import Any


def lazy_getattr(namespace: dict[str, Any]) -> Callable[[str], Any]:
    """The module ``__getattr__`` of the package whose globals are ``namespace``: its public names
    are the ``from .module import name`` lines of its ``if TYPE_CHECKING:`` block (one list, read
    by type checkers as it is and by :func:`exports` at run time), each imported and cached in
    ``namespace`` on first use; ``__all__`` is that list."""
    package, source = namespace["__name__"], namespace["__file__"]

    def __getattr__(name: str) -> Any:
        names = exports(source)
        if name == "__all__":
            return sorted(names)
        module = names.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f".{module}", package), name)
        namespace[name] = value
        return value

    return __getattr__


@functools.cache
def exports(source: str) -> dict[str, str]:
    """Public name → its module, relative to the package, from the ``from .module import name``
    lines of the ``if TYPE_CHECKING:`` block of the package's ``__init__.py`` (``source``)."""
    import ast

    out: dict[str, str] = {}
    with open(source, encoding="utf-8") as f:
        tree = ast.parse(f.read())
    for node in tree.body:
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            for line in node.body:
                if isinstance(line, ast.ImportFrom) and line.level == 1 and line.module:
                    out.update({alias.asname or alias.name: line.module for alias in line.names})
    return out
