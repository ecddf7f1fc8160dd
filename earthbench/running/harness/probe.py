"""Planner metadata from a fenced probe: the harness never imports a plugin's code.

docs/DESIGN.md §6 "Plugin code". A plugin file (``--plugin FILE.py``) or another distribution's
planner entry points are imported only inside a job that runs through the same fences as a case
(:func:`.sandbox.run_job`): the *probe* imports the code, describes each planner (name, version,
tracks, settings, whether it prepares, the folders it reads) and resolves the configurations asked for, and answers
with one JSON document. The harness reads that answer as hostile data (:func:`_validate`: types,
sizes, names), recomputes every configuration hash itself, and keeps it in a cache keyed by a
digest of the code (the file's bytes, or the distribution's files), the Python version and
earthbench's, in a folder only the harness writes (``$EARTHBENCH_PROBES``, default
``~/.cache/earthbench/probes``). The built-in planners (the earthbench distribution's own entry
points) and planners a script registered in its own process are read from their classes.

:func:`resolve` is the one way the commands turn a planner name and settings into a
:class:`~earthbench.results.records.PlannerRef`; :func:`catalogue` lists every planner.
"""

from __future__ import annotations

import functools
import hashlib
import json
import operator
import os
import platform
import re
import sys
import tempfile
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any, NamedTuple

from ...errors import PluginError, UnknownNameError
from ...planner import SharedFolder
from ...registry import PLANNERS, class_digest, distribution_of, file_digest
from ...results.records import PlannerRef
from ...world import TRACKS, Budget, canonical_json
from .describe import Setting, overrides_key, settings_of
from .environment import cache_folder
from .visible import MAX_SHARED, check_shared

ENV = "EARTHBENCH_PROBES"
#: The probe's protocol: a change of what it answers makes every cached answer stale.
PROTOCOL = 2  # 2: each planner's ``reads``
#: A probe imports a plugin and describes it: a minute, one core and 2 GB are plenty.
BUDGET = Budget(wall_s=60.0, cores=1, memory_mb=2048)
MAX_ANSWER = 1 << 20
MAX_PLANNERS = 64
MAX_SETTINGS = 256
MAX_TEXT = 200
MAX_CONFIG = 64 << 10
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]{0,63}\Z")
SETTING = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,63}\Z")
VERSION = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+!-]{0,63}\Z")
TYPE = re.compile(r"[a-z_\[\],]{1,200}\Z")
CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")


@dataclass(frozen=True)
class PlannerInfo:
    """What the harness knows of a planner without its code: the probe's validated answer."""

    name: str
    version: str
    tracks: tuple[str, ...]
    prepares: bool
    doc: str
    settings: tuple[Setting, ...]
    #: How a case finds it: a plugin file's path or ``module:qualname``.
    source: str
    code_digest: str
    origin: str
    #: Resolved configurations: canonical JSON of the overrides -> the configuration (or an error text).
    configs: Mapping[str, Any] = field(default_factory=dict, compare=False)
    #: The folders outside its own files its cases read (``Planner.reads``, checked: :func:`.visible.check_shared`).
    reads: tuple[SharedFolder, ...] = ()

    def hints(self) -> dict[str, Any]:
        """Each setting's type as a ``typing`` hint, for converting ``--config KEY=VALUE``."""
        return {s.name: _hint(s.type) for s in self.settings}


@dataclass(frozen=True)
class Source:
    """Code the harness does not import: a plugin file, or another distribution's planner entry points."""

    kind: str  # "file" | "dist"
    ident: str  # the file's resolved path, or the distribution's name
    entry_points: tuple[tuple[str, str], ...] = ()
    digest: str = ""

    @property
    def label(self) -> str:
        return f"plugin file {self.ident}" if self.kind == "file" else f"distribution {self.ident}"


# -- which code provides which planner ------------------------------------------------------------

_FILES: list[str] = []


def use_plugin_files(paths: Iterable[str | Path]) -> list[str]:
    """The plugin files of this command (``--plugin``): checked to exist, never imported here."""
    out = []
    for path in paths:
        p = Path(path)
        if not p.is_file():
            raise PluginError(f"plugin file {str(p)!r} not found")
        out.append(str(p.resolve()))
    _FILES[:] = list(dict.fromkeys(out))
    return list(_FILES)


def plugin_files() -> list[str]:
    return list(_FILES)


def _foreign_sources() -> list[Source]:
    """Another distribution's planner entry points, one source per distribution."""
    by_dist: dict[str, list[tuple[str, str]]] = {}
    dists: dict[str, Any] = {}
    for name, ep in sorted(PLANNERS.foreign_entry_points().items()):
        d = distribution_of(ep) or "unknown"
        by_dist.setdefault(d, []).append((name, ep.value))
        dists[d] = getattr(ep, "dist", None)
    return [Source("dist", d, tuple(eps), _dist_digest(dists[d], eps)) for d, eps in sorted(by_dist.items())]


def _file_source(path: str) -> Source:
    try:
        return Source("file", path, (), file_digest(path))
    except OSError as exc:
        raise PluginError(f"plugin file {path!r} cannot be read: {exc.strerror}") from None


def _dist_digest(dist: Any, eps: Sequence[tuple[str, str]]) -> str:
    """sha256 over the distribution's files (its RECORD) and the folders of its entry points' top-level
    packages (an editable install's code is not in its RECORD); found without importing anything."""
    import importlib.util

    files: dict[str, Path] = {}
    for rel in (getattr(dist, "files", None) or ()) if dist is not None else ():
        p = Path(str(dist.locate_file(rel)))
        if p.suffix != ".pyc":
            files[f"record:{rel}"] = p
    for top in sorted({value.split(":", 1)[0].split(".")[0] for _, value in eps}):
        try:
            spec = importlib.util.find_spec(top)  # a top-level name: finds, imports nothing
        except (ImportError, ValueError):
            spec = None
        if spec is None:
            continue
        for loc in spec.submodule_search_locations or ():
            for p in sorted(Path(loc).rglob("*")):
                if p.is_file() and "__pycache__" not in p.parts:
                    files[f"{top}:{p.relative_to(loc)}"] = p
        if not spec.submodule_search_locations and spec.origin:
            files[f"{top}:"] = Path(spec.origin)
    h = hashlib.sha256()
    for key in sorted(files):
        try:
            h.update(key.encode() + b"\0" + hashlib.sha256(files[key].read_bytes()).digest())
        except OSError:
            h.update(key.encode() + b"\0missing")
    return "sha256:" + h.hexdigest()


# -- the cache ------------------------------------------------------------------------------------


def cache_root() -> Path:
    """Where probe answers are kept: ``$EARTHBENCH_PROBES``, else the user's cache folder."""
    return cache_folder(ENV, "probes")


def _version() -> str:
    try:
        return metadata.version("earthbench")
    except metadata.PackageNotFoundError:
        return "unknown"


def cache_key(source: Source) -> str:
    """What a probe's answer depends on: the code (its digest), the interpreter and earthbench."""
    doc = {"protocol": PROTOCOL, "kind": source.kind, "ident": source.ident, "digest": source.digest,
           "python": platform.python_version(), "executable": sys.executable, "earthbench": _version()}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:32]


def _cache_read(source: Source) -> dict[str, Any] | None:
    try:
        doc = json.loads((cache_root() / f"{cache_key(source)}.json").read_bytes()[:MAX_ANSWER * 4])
    except (OSError, ValueError):
        return None
    return doc if isinstance(doc, dict) else None


def _cache_write(source: Source, doc: dict[str, Any]) -> None:
    folder = cache_root()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".probe-", suffix=".tmp", dir=folder)
        with os.fdopen(fd, "w") as f:
            json.dump(doc, f, sort_keys=True)
        os.replace(tmp, folder / f"{cache_key(source)}.json")
    except OSError:
        pass  # no cache: the next command probes again


# -- probing --------------------------------------------------------------------------------------


class Described(NamedTuple):
    """What a source provides: its planners, and why each of the others failed to load (name -> why)."""

    planners: dict[str, PlannerInfo]
    failures: dict[str, str]


def _described(source: Source, wanted: Mapping[str, Sequence[Mapping[str, Any]]]) -> Described:
    """The planners ``source`` provides, with the configurations ``wanted`` (name -> overrides)
    resolved: from the cache, else from a probe (whose answer is then cached)."""
    cached = _cache_read(source)
    if cached is not None:
        try:
            infos = _validate(source, cached)
        except PluginError:
            infos = None
        if infos is not None and all(overrides_key(o) in infos.planners[n].configs for n, os_ in wanted.items()
                                     if n in infos.planners for o in os_):
            return infos
    asked: dict[str, list[Any]] = {n: [dict(o) for o in os_] for n, os_ in wanted.items()}
    if cached is not None:  # ask again for what was cached too, so the cache keeps growing
        for n, configs in (cached.get("configs") or {}).items():
            if isinstance(configs, dict):
                for k in list(configs)[:MAX_PLANNERS]:
                    try:
                        asked.setdefault(n, []).append(json.loads(k))
                    except ValueError:
                        pass
    doc = _probe(source, asked)
    infos = _validate(source, doc)
    _cache_write(source, doc)
    return infos


def _probe(source: Source, asked: Mapping[str, list[Any]]) -> dict[str, Any]:
    """Run the probe job in its fences and return its answer (unvalidated)."""
    from .isolation import visible_paths
    from .sandbox import run_job

    if source.kind == "file":
        spec = {"job": "probe", "name": "", "source": source.ident, "probe": {"file": source.ident}}
        visible = visible_paths(source.ident)
    else:
        spec = {"job": "probe", "name": "", "source": source.entry_points[0][1],
                "probe": {"entry_points": [list(e) for e in source.entry_points]}}
        visible = tuple(dict.fromkeys(p for _, value in source.entry_points for p in visible_paths(value)))
    payload = json.dumps({"configs": {"": [{}], **{n: list(v) for n, v in asked.items()}}}).encode() + b"\n"
    cores = tuple(sorted(os.sched_getaffinity(0)))[:1] if hasattr(os, "sched_getaffinity") else (0,)
    o = run_job(spec, payload, cores, BUDGET, writable=None, visible=visible, what="a planner probe")
    if o.done is None or o.done.get("outcome") != "probed":
        why = (o.fault or (o.done or {}).get("error") or
               ("it ran past its budget of 60 s" if o.timed_out else f"its process exited with status {o.status}"))
        last = _clean(str(why).strip().splitlines()[-1] if str(why).strip() else "", 400)
        last = re.sub(r"^(RuntimeError|earthbench\.errors\.PluginError): ", "", last)
        raise PluginError(f"{source.label} could not be loaded (in a fenced probe): {last}")
    text = o.done.get("summary")
    if not isinstance(text, str) or len(text) > MAX_ANSWER:
        raise PluginError(f"{source.label}: the probe's answer is malformed or over {MAX_ANSWER} bytes")
    try:
        doc = json.loads(text)
    except ValueError:
        raise PluginError(f"{source.label}: the probe's answer is not JSON") from None
    if not isinstance(doc, dict):
        raise PluginError(f"{source.label}: the probe's answer is not an object")
    return doc


def _clean(text: str, n: int = MAX_TEXT) -> str:
    text = CONTROL.sub("?", text)
    return text if len(text) <= n else text[:n] + "…"


def _validate(source: Source, doc: dict[str, Any]) -> Described:
    """The probe's answer, read as hostile data: every name, type and size checked."""
    def bad(why: str) -> PluginError:
        return PluginError(f"{source.label}: the probe's answer is refused: {why}")

    planners, configs = doc.get("planners"), doc.get("configs") or {}
    if not isinstance(planners, list) or len(planners) > MAX_PLANNERS or not isinstance(configs, dict):
        raise bad("no list of planners")
    failures = doc.get("failures") or {}
    if not isinstance(failures, dict):
        raise bad("failures is not an object")
    failed = {_clean(str(k), 64): _clean(str(v), 400) for k, v in list(failures.items())[:MAX_PLANNERS]}
    if not planners:
        why = "; ".join(f"{k}: {v}" for k, v in list(failed.items())[:3])
        raise PluginError(f"{source.label} defines no Planner subclass with a 'name'" + (f" ({why})" if why else ""))
    allowed = {e[0]: e[1] for e in source.entry_points}
    out: dict[str, PlannerInfo] = {}
    for p in planners:
        if not isinstance(p, dict):
            raise bad("a planner is not an object")
        name, version, tracks = p.get("name"), p.get("version"), p.get("tracks")
        if not isinstance(name, str) or not NAME.match(name):
            raise bad(f"planner name {_clean(repr(name), 80)} (letters, digits, '-', '_', '.', '+'; at most 64)")
        if source.kind == "dist" and name not in allowed:
            raise bad(f"planner {name!r} is not one of the distribution's entry points")
        if name in out:
            raise bad(f"planner {name!r} twice")
        if not isinstance(version, str) or not VERSION.match(version):
            raise bad(f"planner {name!r} has version {_clean(repr(version), 80)}")
        if (not isinstance(tracks, list) or not tracks or len(tracks) > len(TRACKS)
                or any(t not in TRACKS for t in tracks)):
            raise bad(f"planner {name!r} has tracks {_clean(repr(tracks), 80)}, not a list of {', '.join(TRACKS)}")
        if not isinstance(p.get("prepares"), bool):
            raise bad(f"planner {name!r}: 'prepares' is not true or false")
        reads = _reads(name, p.get("reads", []), bad)
        settings = p.get("settings")
        if not isinstance(settings, list) or len(settings) > MAX_SETTINGS:
            raise bad(f"planner {name!r}: settings are not a list of at most {MAX_SETTINGS}")
        out[name] = PlannerInfo(
            name=name, version=version, tracks=tuple(tracks), prepares=p["prepares"],
            doc=_clean(p["doc"] if isinstance(p.get("doc"), str) else ""),
            settings=tuple(_setting(name, s, bad) for s in settings),
            source=source.ident if source.kind == "file" else allowed[name],
            code_digest=source.digest, origin=source.label,
            configs=_configs(name, configs.get(name), bad), reads=reads,
        )
    return Described(out, failed)


def _reads(planner: str, reads: Any, bad: Any) -> tuple[SharedFolder, ...]:
    """A planner's declared folders from the probe's answer (pairs of strings), checked as the harness's own."""
    if not isinstance(reads, list) or len(reads) > MAX_SHARED or \
            not all(isinstance(r, list) and len(r) == 2 and all(isinstance(x, str) for x in r) for r in reads):
        raise bad(f"planner {planner!r}: 'reads' is not a list of at most {MAX_SHARED} pairs of strings")
    out = tuple(SharedFolder(env, default) for env, default in reads)
    why = check_shared(out)
    if why:
        raise bad(f"planner {planner!r}: {_clean(why)}")
    return out


def _setting(planner: str, s: Any, bad: Any) -> Setting:
    if not isinstance(s, dict) or not isinstance(s.get("name"), str) or not SETTING.match(s["name"]):
        raise bad(f"planner {planner!r} has a setting that is not a name")
    kind = s.get("type", "any")
    if not isinstance(kind, str) or not TYPE.match(kind):
        raise bad(f"planner {planner!r}: setting {s['name']!r} has type {_clean(repr(kind), 80)}")
    try:
        _hint(kind)
    except ValueError:
        raise bad(f"planner {planner!r}: setting {s['name']!r} has type {_clean(kind, 80)}") from None
    has = "default" in s
    if has and len(json.dumps(s["default"])) > MAX_CONFIG:
        raise bad(f"planner {planner!r}: setting {s['name']!r} has a default over {MAX_CONFIG} bytes")
    return Setting(s["name"], kind, s.get("default"), has)


def _configs(planner: str, configs: Any, bad: Any) -> dict[str, Any]:
    if configs is None:
        return {}
    if not isinstance(configs, dict) or len(configs) > 4 * MAX_PLANNERS:
        raise bad(f"planner {planner!r}: configurations are not an object")
    out: dict[str, Any] = {}
    for key, value in configs.items():
        if not isinstance(key, str) or len(key) > MAX_CONFIG:
            raise bad(f"planner {planner!r}: a configuration's key is malformed")
        if isinstance(value, dict) and isinstance(value.get("error"), str) and len(value) == 1:
            out[key] = {"error": _clean(value["error"], 400)}
        elif isinstance(value, dict) and isinstance(value.get("config"), dict) and len(json.dumps(value)) <= MAX_CONFIG:
            if not all(isinstance(k, str) and SETTING.match(k) for k in value["config"]):
                raise bad(f"planner {planner!r}: a configuration has a setting that is not a name")
            out[key] = {"config": value["config"]}
        else:
            raise bad(f"planner {planner!r}: a configuration is malformed or over {MAX_CONFIG} bytes")
    return out


# -- what the commands use ------------------------------------------------------------------------


@dataclass
class Catalogue:
    """Every planner this command can run, by name, and the sources that failed to load."""

    planners: dict[str, PlannerInfo] = field(default_factory=dict)
    failures: dict[str, str] = field(default_factory=dict)


def info_of_class(name: str, klass: type) -> PlannerInfo:
    """A class in this process (a built-in planner, or one a script registered), described as the probe would."""
    doc = (klass.__doc__ or "").strip().splitlines()
    module = klass.__module__
    file = getattr(sys.modules.get(module), "__file__", None) or ""
    source = str(Path(file).resolve()) if module.startswith("earthbench_plugin_") and file else f"{module}:{klass.__qualname__}"
    return PlannerInfo(name=name, version=str(getattr(klass, "version", "0")), tracks=tuple(getattr(klass, "tracks", ())),
                       prepares=bool(klass.prepares()), doc=doc[0] if doc else "",  # type: ignore[attr-defined]
                       settings=tuple(settings_of(klass)), source=source, code_digest=class_digest(klass),
                       origin=PLANNERS.origin(name), reads=tuple(getattr(klass, "reads", ())))


def catalogue(*, sources_only: bool = False) -> Catalogue:
    """Every planner: this process's (built-in and registered) and those the plugin files and other
    distributions provide (probed, cached). Two sources of one name are a clash: an error."""
    cat = Catalogue()
    if not sources_only:
        for name, klass in PLANNERS.items():
            cat.planners[name] = info_of_class(name, klass)
    for name, why in PLANNERS.failures.items():
        cat.failures[name] = why
    for source in _sources():
        try:
            infos = _described(source, {})
        except PluginError as exc:
            if source.kind == "file":  # a file the command was given: its failure is the command's error
                raise
            cat.failures[source.label] = str(exc)
            continue
        for described in infos.planners.values():
            _add(cat.planners, described)
        cat.failures.update({f"{n} ({source.label})": why for n, why in infos.failures.items()})
    return cat


def _sources(only: str | None = None) -> list[Source]:
    files = [_file_source(p) for p in _FILES]
    dists = [s for s in _foreign_sources() if only is None or only in dict(s.entry_points)]
    return files + dists


def _add(known: dict[str, PlannerInfo], info: PlannerInfo) -> None:
    old = known.get(info.name)
    if old is not None and old.source != info.source:
        raise PluginError(
            f"{info.origin} provides planner {info.name!r}, but a planner of that name is already registered "
            f"({old.origin}); give one of them another name: runs are stored by name and version, so the two would be mixed up")
    known[info.name] = info


def info(name: str) -> PlannerInfo:
    """The planner ``name`` (this process's, a plugin file's or another distribution's); a clash of two
    sources is an error, an unknown name lists the known ones."""
    found: dict[str, PlannerInfo] = {}
    if name in PLANNERS:
        found[name] = info_of_class(name, PLANNERS.get(name))
    for source in _sources(only=name):
        infos = _described(source, {})
        if name in infos.planners:
            _add(found, infos.planners[name])
        elif name in infos.failures:
            raise PluginError(f"{source.label}: {infos.failures[name]}")
    if name not in found:
        if name in PLANNERS.failures:
            PLANNERS.get(name)  # raises with the failure
        raise UnknownNameError("planner", name, names())
    return found[name]


def known(name: str) -> bool:
    """Whether some planner is called ``name`` (imports at most the built-in planner of that name)."""
    if name in PLANNERS or name in PLANNERS.foreign_entry_points():
        return True
    for source in _sources():
        if source.kind == "file":
            try:
                if name in _described(source, {}).planners:
                    return True
            except PluginError:
                pass
    return False


def names() -> list[str]:
    """The names of every planner, without describing this process's ones (cheap for a message)."""
    out = set(PLANNERS.names()) | set(PLANNERS.foreign_entry_points())
    for source in _sources():
        if source.kind == "file":
            try:
                out.update(_described(source, {}).planners)
            except PluginError:
                pass
    return sorted(out)


def resolve(name: str, overrides: Mapping[str, Any] | None = None) -> PlannerRef:
    """``name`` with ``overrides`` as the harness runs it: a :class:`PlannerRef` whose configuration
    the planner's own ``Config`` made (inside the probe for a plugin's code) and whose hash and code
    digest the harness computed."""
    overrides = dict(overrides or {})
    if name in PLANNERS:
        inproc = PlannerRef.resolve(name, overrides)
        info(name)  # a plugin file or a distribution of the same name is a clash
        why = check_shared(inproc.reads)
        if why:
            raise PluginError(f"planner {name!r} cannot run: {why}")
        return inproc
    base = info(name)
    key = overrides_key(overrides)
    got = base.configs.get(key)
    if got is None:
        source = next(s for s in _sources(only=name) if s.label == base.origin)
        got = _described(source, {name: [overrides]}).planners[name].configs.get(key)
    if got is None or "error" in got:
        raise PluginError((got or {}).get("error") or f"planner {name!r}: the probe did not resolve its configuration")
    config = got["config"]
    return PlannerRef(name=name, version=base.version, source=base.source, config=config,
                      config_hash=hashlib.sha256(canonical_json(config).encode()).hexdigest()[:16],
                      overrides=overrides, tracks=base.tracks, prepares=base.prepares, code_digest=base.code_digest,
                      reads=base.reads)


_SIMPLE: dict[str, Any] = {"bool": bool, "int": int, "float": float, "str": str, "none": type(None), "any": Any}


def _hint(text: str) -> Any:
    """The probe's type language back to a ``typing`` hint (ValueError when malformed)."""
    hint, rest = _parse(text, 0)
    if rest != len(text):
        raise ValueError(text)
    return hint


def _parse(text: str, i: int, depth: int = 0) -> tuple[Any, int]:
    if depth > 4:
        raise ValueError(text)
    m = re.compile(r"[a-z]+").match(text, i)
    if not m:
        raise ValueError(text)
    word, i = m.group(), m.end()
    if word in _SIMPLE:
        return _SIMPLE[word], i
    if word not in ("list", "tuple", "union") or text[i:i + 1] != "[":
        raise ValueError(text)
    args = []
    i += 1
    while True:
        a, i = _parse(text, i, depth + 1)
        args.append(a)
        if text[i:i + 1] == ",":
            i += 1
            continue
        if text[i:i + 1] != "]":
            raise ValueError(text)
        i += 1
        break
    if word == "union":
        return functools.reduce(operator.or_, args), i
    return (list if word == "list" else tuple)[args[0]], i
