"""What a fenced job may read: the Python environment, earthbench, the planner's own files, and
the folders the planner declares it reads (docs/DESIGN.md §6 "Isolation").

Everything else of the machine is out of a sandboxed case's sight. The harness knows no planner
by name: a planner that reads a folder outside its own files (a cache its runs fill, say)
declares it (:attr:`earthbench.planner.Planner.reads`, a :class:`~earthbench.planner.SharedFolder`),
as it declares its preparation, and :func:`shared_folders` resolves the declaration on the
machine that runs the case.
"""

from __future__ import annotations

import functools
import importlib.machinery
import importlib.util
import os
import re
import sys
from collections.abc import Iterable, Sequence
from importlib import metadata

from ...planner import SharedFolder
from ...results.records import PlannerRef

#: The most folders a planner may declare it reads.
MAX_SHARED = 8
#: A declared folder's variable: earthbench's namespace, never one of the harness's own (:data:`OWN_VARS`).
SHARED_ENV = re.compile(r"EARTHBENCH_[A-Z0-9_]{1,48}\Z")
#: The harness's own variables, which no declaration may name (where the store is, which fences, …).
OWN_VARS = frozenset({"EARTHBENCH_DB", "EARTHBENCH_CASE", "EARTHBENCH_CASE_ENV", "EARTHBENCH_ISOLATION",
                      "EARTHBENCH_PREPARE", "EARTHBENCH_PREPARED", "EARTHBENCH_PROBES", "EARTHBENCH_SLOT_DIR",
                      "EARTHBENCH_TRUST"})
_PART = re.compile(r"[A-Za-z0-9_+-][A-Za-z0-9_.+-]{0,63}\Z")
#: earthbench's own caches under the user's cache folder: never shown through a declaration.
_OWN_CACHES = ("prepared", "probes")


def check_shared(reads: Sequence[object]) -> str:
    """Why a planner's declaration of the folders it reads is refused ('' when it is not):
    at most :data:`MAX_SHARED`, each a :class:`SharedFolder` whose variable matches
    :data:`SHARED_ENV` outside :data:`OWN_VARS` and whose default is a folder of earthbench's
    part of the user's cache folder, ``earthbench/NAME[/…]`` in plain names (no ``..``, nothing
    hidden), outside earthbench's own caches there: the rest of that folder is the user's other
    programs' (tokens among them), which no planner may declare its way into."""
    if len(reads) > MAX_SHARED:
        return f"it declares {len(reads)} folders it reads, more than {MAX_SHARED}"
    for r in reads:
        if not isinstance(r, SharedFolder) or not isinstance(r.env, str) or not isinstance(r.default, str):
            return "a folder it reads is not an earthbench.planner.SharedFolder of two strings"
        if not SHARED_ENV.match(r.env) or r.env in OWN_VARS:
            return (f"the variable {r.env[:80]!r} of a folder it reads is not EARTHBENCH_ and capitals, digits, '_' "
                    f"(at most 48), or is one of the harness's own")
        parts = r.default.split("/")
        if len(r.default) > 256 or len(parts) < 2 or parts[0] != "earthbench" or parts[1] in _OWN_CACHES or \
                not all(_PART.match(p) for p in parts):
            return (f"the default {r.default[:80]!r} of a folder it reads is not earthbench/NAME in plain names "
                    "(under the user's cache folder, outside earthbench's own prepared and probes)")
    return ""


def shared_folders(reads: Iterable[SharedFolder]) -> tuple[dict[str, str], tuple[str, ...]]:
    """The variables a case of a planner that ``reads`` these folders is given, and the folders it
    may read: each variable as this machine's user set it (``off`` stays ``off``; a path is
    resolved) or, unset, its default under ``$XDG_CACHE_HOME`` (default ``~/.cache``); resolved
    here, since the case has no ``HOME`` of the user's. A folder that does not exist is not shown,
    nor anything of a declaration :func:`check_shared` refuses (resolving a planner refuses it first)."""
    reads = tuple(reads)
    env: dict[str, str] = {}
    if check_shared(reads):
        return env, ()
    seen: list[str] = []
    for r in reads:
        chosen = os.environ.get(r.env, "").strip()
        if chosen.lower() == "off":
            env[r.env] = "off"
            continue
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        path = os.path.realpath(os.path.expanduser(chosen) if chosen else os.path.join(base, r.default))
        env[r.env] = path
        if os.path.isdir(path):
            seen.append(path)
    return env, tuple(seen)


def under(path: str, roots: Iterable[str]) -> bool:
    """Whether ``path`` is one of ``roots`` or lies inside one."""
    return any(path == r or path.startswith(r.rstrip(os.sep) + os.sep) for r in roots)


def _prefixes() -> list[str]:
    return sorted({os.path.realpath(p) for p in (sys.prefix, sys.base_prefix, sys.exec_prefix)})


@functools.lru_cache(maxsize=64)
def visible_paths(planner_source: str = "") -> tuple[str, ...]:
    """What a case may read: the interpreter's environment (its prefixes and every site folder
    on the path), earthbench's packages and the planner's own files."""
    prefixes = _prefixes()
    paths = set(prefixes)
    # site folders added to the path (a .pth's addsitedir, a --system-site-packages venv): installed
    # packages, whole; a source folder on the path is not (it may hold anything), only the packages used
    paths.update(os.path.realpath(p) for p in sys.path
                 if os.path.basename(p.rstrip(os.sep)) in ("site-packages", "dist-packages") and os.path.isdir(p))
    mods = set(_own_packages())
    if planner_source.endswith(".py"):
        paths.update(_plugin_files(os.path.realpath(planner_source)))
    elif ":" in planner_source:
        module = planner_source.split(":", 1)[0]
        mods.add(module)
        parts = module.split(".")
        for i in range(1, len(parts)):  # the enclosing packages' __init__ files
            spec = _find(".".join(parts[:i]))
            if spec is not None and spec.origin and os.path.exists(spec.origin):
                paths.add(os.path.realpath(spec.origin))
    for m in mods:
        spec = _find(m)
        if spec is None:
            continue
        if spec.submodule_search_locations:
            paths.update(os.path.realpath(p) for p in spec.submodule_search_locations)
        elif spec.origin and os.path.exists(spec.origin):
            paths.add(os.path.realpath(spec.origin))
    # drop whatever an environment folder already holds
    keep = sorted(p for p in paths if p in prefixes or not under(p, prefixes))
    out: list[str] = []
    for p in keep:
        if not under(p, out):
            out.append(p)
    return tuple(out)


def _plugin_files(path: str) -> tuple[str, ...]:
    """A plugin file's own files: the outermost package folder it sits in; or, for a file in a
    plain folder, the file and the modules beside it that it can import (``*.py``, compiled
    modules, package folders), never anything else of that folder (it may hold anything, e.g.
    the store a user runs beside it)."""
    top = ""
    d = os.path.dirname(path)
    while os.path.isfile(os.path.join(d, "__init__.py")):
        top, d = d, os.path.dirname(d)
    if top:
        return (top,)
    suffixes = tuple(importlib.machinery.all_suffixes())
    out = [path]
    try:
        entries = list(os.scandir(d))
    except OSError:
        return tuple(out)
    for e in entries:
        if e.name.startswith("."):
            continue
        if e.name.endswith(suffixes) and e.is_file(follow_symlinks=False):
            out.append(os.path.join(d, e.name))
        elif e.is_dir(follow_symlinks=False) and e.name.isidentifier() and os.path.isfile(os.path.join(e.path, "__init__.py")):
            out.append(os.path.join(d, e.name))
    return tuple(dict.fromkeys(out))


def store_exposure(db: str, planners: Iterable[str | PlannerRef]) -> str:
    """Why a case of one of ``planners`` (each a :class:`PlannerRef`, or the source of one) could
    read the results store at ``db`` (its ``-wal``, ``-shm``, ``-journal`` files too), or '' when
    none can: the harness refuses to run then (the store holds the truth of every scenario,
    sealed ones too)."""
    files = [os.path.realpath(str(db) + s) for s in ("", "-wal", "-shm", "-journal")]
    for p in dict.fromkeys(planners):
        source = p if isinstance(p, str) else p.source
        shared = () if isinstance(p, str) else shared_folders(p.reads)[1]
        for seen in (*visible_paths(source), *shared):
            if any(under(f, [seen]) for f in files):
                return (f"the results store {db} lies inside {seen}, which the cases of {source or 'every planner'} can read; "
                        "keep the store out of the planner's package and of the Python environment "
                        "(e.g. --db in a folder of its own)")
    return ""


@functools.lru_cache(maxsize=1)
def _own_packages() -> tuple[str, ...]:
    """earthbench's top-level packages (its planners, terrains and metrics are packages of their own)."""
    try:
        text = metadata.distribution("earthbench").read_text("top_level.txt") or ""
    except metadata.PackageNotFoundError:
        text = ""
    return tuple(dict.fromkeys(["earthbench", *text.split()]))


def _find(module: str) -> importlib.machinery.ModuleSpec | None:
    """The module's spec, found without importing it or its parent packages (a plugin's
    ``__init__`` is code the harness must not run: docs/DESIGN.md §6 "Plugin code")."""
    if module in sys.modules:
        return getattr(sys.modules[module], "__spec__", None)
    parts = module.split(".")
    try:
        spec = importlib.util.find_spec(parts[0])  # a top-level name: found, not imported
        for i in range(1, len(parts)):
            if spec is None or not spec.submodule_search_locations:
                return None
            spec = importlib.machinery.PathFinder.find_spec(".".join(parts[:i + 1]), list(spec.submodule_search_locations))
        return spec
    except (ImportError, ValueError):
        return None


