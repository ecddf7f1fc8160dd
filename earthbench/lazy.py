"""Lazy package exports (PEP 562): a package names its public objects without importing them.

A case's process imports only what its planner needs; the packages that re-export many
modules' names (``earthbench``, ``earthbench.harness``) load each module on first use
(docs/DESIGN.md §10, start-up).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any


def lazy_getattr(package: str, exports: Mapping[str, str], namespace: dict[str, Any]) -> Callable[[str], Any]:
    """The module ``__getattr__`` of ``package``: ``exports`` maps a public name to its module
    (relative to the package); the first use imports it and caches the object in ``namespace``."""

    def __getattr__(name: str) -> Any:
        module = exports.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f".{module}", package), name)
        namespace[name] = value
        return value

    return __getattr__
