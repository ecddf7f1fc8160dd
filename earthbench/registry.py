"""Registries of planners, terrain generators and metrics.

Built-ins and third-party packages register the same way, through entry-point groups
(``earthbench.planners``, ``earthbench.terrains``, ``earthbench.metrics``); scripts and
notebooks use :func:`register_planner`; a single plugin file is loaded with
:func:`load_plugin_file`. Entry points are read lazily on first use. A plugin that fails to
import is recorded in ``failures`` (and shown by ``earthbench list``) without hiding the rest.
Unknown names raise :class:`UnknownNameError` with the known names and close matches.

Only the earthbench distribution's own entry points are imported into this process
(docs/DESIGN.md §6 "Plugin code"): another distribution's planners are recorded in ``foreign``
and read by a fenced probe (:mod:`earthbench.running.harness.probe`), its terrains and metrics are not
loaded unless ``$EARTHBENCH_TRUST`` names the distribution.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import inspect
import sys
import traceback
from collections.abc import Callable, Iterator
import os
from importlib.metadata import EntryPoint, entry_points
from pathlib import Path
from types import ModuleType
from typing import Any, Generic, TypeVar

from .errors import PluginError, UnknownNameError
from .planner import Planner

T = TypeVar("T")

#: The distribution whose entry points are the harness's own code (docs/DESIGN.md §6 "Plugin code").
OWN_DISTRIBUTION = "earthbench"
#: Comma-separated distribution names whose terrains and metrics may be imported into earthbench's
#: own process (they run there: a suite's terrain, a run's scoring); planners never are.
TRUST_ENV = "EARTHBENCH_TRUST"


def distribution_of(ep: EntryPoint) -> str:
    """The normalised name of the distribution that declares ``ep`` ('' if unknown)."""
    dist = getattr(ep, "dist", None)
    if dist is None:
        return ""
    where = getattr(dist, "_path", None)  # its metadata folder: reading its name parses a file, so once each
    if where is None:
        return _normalise(dist.name or "")
    if where not in _DIST_NAMES:
        _DIST_NAMES[where] = _normalise(dist.name or "")
    return _DIST_NAMES[where]


_DIST_NAMES: dict[Any, str] = {}


def _normalise(name: str) -> str:
    return name.strip().lower().replace("_", "-").replace(".", "-")


def trusted_distributions() -> set[str]:
    """The distributions this process may import plugin code from: earthbench and ``$EARTHBENCH_TRUST``."""
    return {OWN_DISTRIBUTION} | {_normalise(n) for n in os.environ.get(TRUST_ENV, "").split(",") if n.strip()}


class Registry(Generic[T]):
    """Name → object, filled from an entry-point group and by explicit registration."""

    def __init__(self, group: str, kind: str, check: Callable[[Any], str | None] | None = None, *, trust: bool = False):
        self.group, self.kind = group, kind
        self._check = check
        self._items: dict[str, T] = {}
        self._origin: dict[str, str] = {}
        self.failures: dict[str, str] = {}
        #: Entry points of other distributions, never imported here: name -> the entry point.
        self.foreign: dict[str, EntryPoint] = {}
        self._trust = trust  # whether $EARTHBENCH_TRUST may admit another distribution's entry points
        self._loaded = False

    def _load_entry_points(self, only: str | None = None) -> None:
        """Load the group's entry points, or only those named ``only`` (cheap lookups by name)."""
        if self._loaded:
            return
        if only is None:
            self._loaded = True
        for ep in entry_points(group=self.group):
            if (only is not None and ep.name != only) or ep.name in self._items or ep.name in self.failures:
                continue
            if distribution_of(ep) not in (trusted_distributions() if self._trust else {OWN_DISTRIBUTION}):
                self.foreign.setdefault(ep.name, ep)
                continue
            try:
                obj = ep.load()
            except SystemExit as exc:  # an installed plugin must not end the process that loads it
                self.failures[ep.name] = f"{ep.value}: called sys.exit({exc.code!r}) while being imported"
                continue
            except Exception:  # noqa: BLE001 - one broken plugin must not hide the others
                self.failures[ep.name] = f"{ep.value}: " + traceback.format_exc(limit=3).strip().splitlines()[-1]
                continue
            problem = self._check(obj) if self._check else None
            if problem:
                self.failures[ep.name] = f"{ep.value}: {problem}"
                continue
            self._items[ep.name] = obj
            dist = getattr(ep, "dist", None)
            self._origin[ep.name] = f"entry point {ep.value}" + (f" ({dist.name} {dist.version})" if dist else "")

    def register(self, name: str, obj: T, *, origin: str = "", replace: bool = False) -> T:
        self._load_entry_points(only=name)
        problem = self._check(obj) if self._check else None
        if problem:
            raise PluginError(f"cannot register {self.kind} {name!r}: {problem}")
        if name in self._items and self._items[name] is not obj and not replace:
            raise PluginError(f"a {self.kind} named {name!r} is already registered ({self._origin.get(name, '?')})")
        self._items[name] = obj
        self._origin[name] = origin or f"{getattr(obj, '__module__', '?')}.{getattr(obj, '__qualname__', name)}"
        self.failures.pop(name, None)
        return obj

    def unregister(self, name: str) -> None:
        """Forget ``name`` (a planner registered for one notebook session or test)."""
        self._items.pop(name, None)
        self._origin.pop(name, None)

    def get(self, name: str) -> T:
        if name not in self._items:
            self._load_entry_points(only=name)
        try:
            return self._items[name]
        except KeyError:
            if name in self.failures:
                raise PluginError(f"{self.kind} {name!r} failed to load: {self.failures[name]}") from None
            if name in self.foreign:
                raise PluginError(self.foreign_message(name)) from None
            self._load_entry_points()  # every name, for the list of known ones
            raise UnknownNameError(self.kind, name, self._items) from None

    def foreign_entry_points(self) -> dict[str, EntryPoint]:
        """Other distributions' entry points of the group (name -> entry point), found without
        importing anything (the group's own entry points are loaded only when asked for)."""
        if self._loaded:  # every entry point was read: the foreign ones are known
            return dict(self.foreign)
        allowed = trusted_distributions() if self._trust else {OWN_DISTRIBUTION}
        for ep in entry_points(group=self.group):
            if ep.name not in self._items and distribution_of(ep) not in allowed:
                self.foreign.setdefault(ep.name, ep)
        return dict(self.foreign)

    def foreign_message(self, name: str) -> str:
        """Why ``name``, another distribution's entry point, is not loaded in this process."""
        ep = self.foreign[name]
        dist = distribution_of(ep) or "an unknown distribution"
        if self.kind == "planner":
            return (f"planner {name!r} comes from the distribution {dist}, whose code earthbench imports only inside "
                    f"a fenced process (earthbench.running.harness.probe)")
        return (f"{self.kind} {name!r} comes from the distribution {dist}, and earthbench loads only its own "
                f"{self.kind}s in its own process (they run there, unfenced); set {TRUST_ENV}={dist} to trust it")

    def origin(self, name: str) -> str:
        self.get(name)
        return self._origin.get(name, "")

    def names(self) -> list[str]:
        self._load_entry_points()
        return sorted(self._items)

    def items(self) -> Iterator[tuple[str, T]]:
        for n in self.names():
            yield n, self._items[n]

    def __contains__(self, name: object) -> bool:
        if isinstance(name, str):
            self._load_entry_points(only=name)
        return name in self._items


def _check_planner(obj: Any) -> str | None:
    if not (inspect.isclass(obj) and issubclass(obj, Planner)):
        return f"{obj!r} is not a subclass of earthbench.Planner"
    if inspect.isabstract(obj):
        return f"{obj.__name__} does not implement plan()"
    return None


def _check_callable(obj: Any) -> str | None:
    return None if callable(obj) else f"{obj!r} is not callable"


PLANNERS: Registry[type[Planner]] = Registry("earthbench.planners", "planner", _check_planner)
TERRAINS: Registry[Callable[..., Any]] = Registry("earthbench.terrains", "terrain generator", _check_callable, trust=True)
METRICS: Registry[Callable[..., Any]] = Registry("earthbench.metrics", "metric", _check_callable, trust=True)


def register_planner(cls: type[Planner] | None = None, *, name: str | None = None, replace: bool = True) -> Any:
    """Class decorator: ``@register_planner`` or ``@register_planner(name="mine")``."""

    def deco(c: type[Planner]) -> type[Planner]:
        n = name or c.name
        if not n:
            raise PluginError(f"planner class {c.__name__} needs a 'name' class attribute or register_planner(name=...)")
        if not c.name:
            c.name = n
        return PLANNERS.register(n, c, replace=replace)

    return deco(cls) if cls is not None else deco


def file_digest(path: str | Path) -> str:
    """The code digest of a plugin file: sha256 of its bytes (docs/DESIGN.md §6 "Plugin code")."""
    return "sha256:" + hashlib.sha256(Path(path).read_bytes()).hexdigest()


def class_digest(klass: type) -> str:
    """The code digest of a planner class in this process: ``earthbench`` for the distribution's own
    planners (their versions are pinned with their plans), else the digest of its module's file."""
    module = klass.__module__
    if module.split(".")[0] in ("earthbench", "earthbench_planners"):
        return OWN_DISTRIBUTION
    file = getattr(sys.modules.get(module), "__file__", None)
    try:
        return file_digest(file) if file else ""
    except OSError:
        return ""


def plugin_module_name(path: str | Path) -> str:
    """The module a plugin file is imported as, the same in the harness and in every case process:
    ``earthbench_plugin_STEM_DIGEST``, the digest of its resolved path, so two files of one name
    (``planner.py`` in two folders) never share a module."""
    p = Path(path).resolve()
    return f"earthbench_plugin_{p.stem}_{hashlib.sha256(str(p).encode()).hexdigest()[:8]}"


def plugin_module(path: str | Path) -> tuple[ModuleType, Callable[[], None]]:
    """A plugin file's module, named :func:`plugin_module_name` and entered in ``sys.modules``,
    and the call that runs the file in it: the harness and every case process import a file so."""
    mod_name = plugin_module_name(path)
    spec = importlib.util.spec_from_file_location(mod_name, path)
    if spec is None or spec.loader is None:
        raise PluginError(f"{path} is not an importable Python file")
    module = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = module
    return module, functools.partial(spec.loader.exec_module, module)


def load_plugin_file(path: str | Path) -> list[str]:
    """Import one Python file and register every named Planner subclass defined in it.

    Returns the names of the planners it provides (registered by decorator or found).
    """
    p = Path(path)
    if not p.is_file():
        raise PluginError(f"plugin file {str(p)!r} not found")
    module, run = plugin_module(p)
    mod_name = module.__name__
    before = {n: PLANNERS.get(n) for n in PLANNERS.names()}
    origins = {n: PLANNERS.origin(n) for n in before}
    try:
        run()
    except SystemExit as exc:  # a plugin must not end the process that loads it
        del sys.modules[mod_name]
        raise PluginError(
            f"plugin file {p} called sys.exit({exc.code!r}) while being imported; a plugin must only define planners"
        ) from None
    except Exception as exc:
        del sys.modules[mod_name]
        raise PluginError(f"plugin file {p} failed to import: {type(exc).__name__}: {exc}") from exc

    def ours(origin: str) -> bool:  # registered by this same file (loaded again): it may replace itself
        return origin == str(p) or origin.startswith(mod_name + ".")

    found = set(PLANNERS.names()) - set(before)
    for n, old in before.items():  # a decorator in the file replaced a planner registered elsewhere
        if PLANNERS.get(n) is not old:
            if not ours(origins[n]):
                PLANNERS.register(n, old, origin=origins[n], replace=True)
                raise PluginError(_shadow_message(p, n, origins[n]))
            found.add(n)
    for obj in vars(module).values():
        if inspect.isclass(obj) and obj.__module__ == mod_name and issubclass(obj, Planner) and obj.name:
            problem = _check_planner(obj)
            if problem:
                raise PluginError(f"plugin file {p}: planner {obj.name!r} cannot run: {problem}")
            if obj.name in before and not ours(origins[obj.name]):
                raise PluginError(_shadow_message(p, obj.name, origins[obj.name]))
            if obj.name not in found:  # not registered by a decorator in the file
                PLANNERS.register(obj.name, obj, origin=str(p), replace=True)
                found.add(obj.name)
    if not found:
        raise PluginError(f"plugin file {p} defines no Planner subclass with a 'name'")
    return sorted(found)


def _shadow_message(path: Path, name: str, origin: str) -> str:
    return (f"plugin file {path} defines planner {name!r}, but a planner of that name is already registered ({origin}); "
            f"give the file's planner another name: runs are stored by name and version, so the two would be mixed up")
