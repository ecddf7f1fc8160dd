"""Lazy package exports (PEP 562): a package names its public objects without importing them.

A case's process imports only what its planner needs; the packages that re-export many
modules' names (``earthbench``, ``earthbench.harness``) load each module on first use
(docs/DESIGN.md §10, start-up).
"""

from __future__ import annotations

import importlib
import warnings
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


def moved_getattr(module: str, moved: Mapping[str, str], fallback: Callable[[str], Any] | None = None) -> Callable[[str], Any]:
    """The module ``__getattr__`` of ``module`` for names that moved: ``moved`` maps an old name
    to the module that now defines it. Plugins written against the old place keep importing
    (docs/plugins.md, the API promise), with a :class:`DeprecationWarning` that names the new
    place; names not in ``moved`` go to ``fallback`` (or raise ``AttributeError``)."""

    def __getattr__(name: str) -> Any:
        target = moved.get(name)
        if target is None:
            if fallback is not None:
                return fallback(name)
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        warnings.warn(f"{module}.{name} moved to {target}.{name}; import it from there", DeprecationWarning, stacklevel=2)
        return getattr(importlib.import_module(target), name)

    return __getattr__


def moved_module(old: str, new: str) -> Callable[[str], Any]:
    """The ``__getattr__`` of a module that moved as a whole to ``new``: it warns once, when the old
    module is imported, and forwards every name (the API promise, as :func:`moved_getattr`)."""
    warnings.warn(f"the module {old} moved to {new}; import from there", DeprecationWarning, stacklevel=3)

    def __getattr__(name: str) -> Any:
        try:
            return getattr(importlib.import_module(new), name)
        except AttributeError:
            raise AttributeError(f"module {old!r} (now {new!r}) has no attribute {name!r}") from None

    return __getattr__

