"""Names that moved keep working for at least one release, with a :class:`DeprecationWarning`.

A plugin written against a documented name of an earlier release must import and run
(docs/plugins.md, "The public API"). :func:`moved` gives a module the ``__getattr__`` that
finds such a name where it lives now, and says where that is.
"""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable, Mapping
from typing import Any


def moved(module: str, names: Mapping[str, str], since: str, fallback: Callable[[str], Any] | None = None
          ) -> Callable[[str], Any]:
    """The module ``__getattr__`` of ``module`` for ``names`` (old name → its module now).

    Other names go to ``fallback`` (a lazy-export ``__getattr__``) or raise AttributeError.
    """

    def __getattr__(name: str) -> Any:
        target = names.get(name)
        if target is None:
            if fallback is not None:
                return fallback(name)
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        warnings.warn(f"{module}.{name} moved to {target}.{name} in earthbench {since}; import it from there "
                      f"(the old name goes in a later release)", DeprecationWarning, stacklevel=2)
        return getattr(importlib.import_module(target), name)

    return __getattr__


def moved_module(old: str, new: str, since: str) -> Callable[[str], Any]:
    """``__getattr__`` of a module that moved as a whole to ``new``: warns once, on import, and forwards."""
    warnings.warn(f"the module {old} moved to {new} in earthbench {since}; import from there "
                  f"(the old module goes in a later release)", DeprecationWarning, stacklevel=3)

    def __getattr__(name: str) -> Any:
        target = importlib.import_module(new)
        try:
            return getattr(target, name)
        except AttributeError:
            raise AttributeError(f"module {old!r} (now {new!r}) has no attribute {name!r}") from None

    return __getattr__
