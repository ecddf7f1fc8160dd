"""Inside a planner probe's fences: import a plugin's code and describe its planners.

The other half of :mod:`.probe` (docs/DESIGN.md §6 "Plugin code"): :func:`answer` runs in the
probe's process (:mod:`.child` calls it), never in the harness's; the harness reads what it
returns as hostile data. :func:`settings_of` also describes a class already in the harness's
process (a built-in planner), so both describe a planner the same way.
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from importlib import metadata
from typing import Any


@dataclass(frozen=True)
class Setting:
    """One field of a planner's ``Config``: its name, default (JSON; absent: ``has_default`` False)
    and type (``float``, ``list[int]``, ``union[float,none]``, ``any``, …)."""

    name: str
    type: str = "any"
    default: Any = None
    has_default: bool = False


def overrides_key(overrides: Mapping[str, Any]) -> str:
    """The canonical text of a configuration's overrides: the key of its resolved configuration."""
    return json.dumps(overrides, sort_keys=True, separators=(",", ":"))


def answer(spec: Mapping[str, Any], payload: Mapping[str, Any]) -> dict[str, Any]:
    """Inside the probe's fences: import the plugin's code, describe its planners, resolve the
    configurations asked for. Runs plugin code; never called in the harness's process."""
    from ...planner import Planner
    from ...registry import plugin_module

    probe = spec.get("probe") or {}
    classes: dict[str, type[Planner]] = {}
    failures: dict[str, str] = {}
    if "file" in probe:
        module, run = plugin_module(probe["file"])
        try:
            run()
        except SystemExit as exc:  # told as what it is, not as a traceback of the probe
            raise RuntimeError(f"plugin file {probe['file']} called sys.exit({exc.code!r}) while being imported; "
                               f"a plugin must only define planners") from None
        for obj in list(vars(module).values()):
            if isinstance(obj, type) and issubclass(obj, Planner) and obj.__module__ == module.__name__ and obj.name:
                if inspect.isabstract(obj):
                    failures[obj.name] = f"planner {obj.name!r} cannot run: {obj.__name__} does not implement plan()"
                else:
                    classes[obj.name] = obj
    for name, value in probe.get("entry_points", ()):
        try:
            obj = metadata.EntryPoint(name, value, "earthbench.planners").load()
        except BaseException as exc:  # noqa: BLE001 - one broken entry point must not hide the others
            failures[name] = f"{value}: {type(exc).__name__}: {exc}"
            continue
        if isinstance(obj, type) and issubclass(obj, Planner) and not inspect.isabstract(obj):
            classes[name] = obj
        else:
            failures[name] = f"{value}: not a subclass of earthbench.Planner that implements plan()"
    asked = payload.get("configs") or {}
    planners, configs = [], {}
    for name, klass in classes.items():
        doc = (klass.__doc__ or "").strip().splitlines()
        planners.append({"name": name, "version": str(klass.version), "tracks": list(klass.tracks),
                         "prepares": bool(klass.prepares()), "doc": doc[0] if doc else "",
                         "reads": [[getattr(r, "env", None), getattr(r, "default", None)] for r in klass.reads],
                         "settings": [dataclasses.asdict(s) for s in settings_of(klass)]})
        configs[name] = {overrides_key(o): _config(klass, o) for o in [*asked.get(name, []), *asked.get("", [])]}
    return {"planners": planners, "configs": configs, "failures": failures}


def _config(klass: type, overrides: dict[str, Any]) -> dict[str, Any]:
    from ...planner import Planner

    try:
        probe: Planner = object.__new__(klass)  # the base initialiser only, as PlannerRef.resolve
        Planner.__init__(probe, **overrides)
        return {"config": probe.config_dict}
    except Exception as exc:  # noqa: BLE001 - a bad setting is the user's error, told as one line
        return {"error": str(exc).splitlines()[0] if str(exc) else type(exc).__name__}


def settings_of(klass: type) -> list[Setting]:
    """The fields of a planner's ``Config``: name, type (the probe's type language) and JSON default."""
    config = getattr(klass, "Config", None)
    if not (dataclasses.is_dataclass(config) and isinstance(config, type)):
        return []
    try:
        hints = typing.get_type_hints(config)
    except Exception:  # noqa: BLE001 - unresolvable annotations: values are read as JSON
        hints = {}
    out = []
    for f in dataclasses.fields(config):
        default: Any = dataclasses.MISSING
        if f.default is not dataclasses.MISSING:
            default = f.default
        elif f.default_factory is not dataclasses.MISSING:
            try:
                default = f.default_factory()
            except Exception:  # noqa: BLE001
                default = dataclasses.MISSING
        try:
            plain = json.loads(json.dumps(default)) if default is not dataclasses.MISSING else dataclasses.MISSING
        except (TypeError, ValueError):
            plain = repr(default)
        out.append(Setting(f.name, _type_text(hints.get(f.name, Any)), None if plain is dataclasses.MISSING else plain,
                           plain is not dataclasses.MISSING))
    return out


def _type_text(hint: Any, depth: int = 0) -> str:  # read back by earthbench.running.harness.probe
    """A type hint as the probe's small type language (the harness converts ``--config`` values with it)."""
    if depth > 3:
        return "any"
    if hint in (bool, int, float, str):
        return hint.__name__
    if hint is type(None):
        return "none"
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return "union[" + ",".join(_type_text(a, depth + 1) for a in args) + "]"
    if origin in (tuple, list):
        return f"{origin.__name__}[{_type_text(args[0], depth + 1) if args else 'any'}]"
    return "any"
