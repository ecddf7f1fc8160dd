"""Helpers shared by the CLI commands: loading scenarios and planners by name or file."""

from __future__ import annotations

import argparse
import inspect
import json
import re
import types
import typing
from pathlib import Path
from typing import Any, TextIO

from ..errors import EarthbenchError, UnknownNameError, not_stored, printable
from ..running.harness.probe import PlannerInfo, info_of_class, use_plugin_files
from ..planner import Planner
from ..registry import TERRAINS
from ..world import Scenario


def plural(n: int, word: str, many: str | None = None) -> str:
    """``1 case``, ``2 cases`` (``many`` for irregular plurals)."""
    return f"{n} {word if n == 1 else (many or word + 's')}"


def refuse_unstored(kind: str, names: typing.Iterable[str], stored: typing.Iterable[str], db: object) -> None:
    """Refuse a ``--suite`` or ``--planner`` that names nothing in the store ``db``, with close matches."""
    known = set(stored)
    for name in names:
        if name not in known:
            raise EarthbenchError(not_stored(kind, name, known, db))


def check_filters(store: Any, db: object, suite: str | None, planners: typing.Iterable[str]) -> None:
    """Refuse a ``--suite`` or ``--planner`` filter that matches nothing in ``store`` (:func:`refuse_unstored`)."""
    if suite:
        refuse_unstored("suite", [suite], [*store.suite_names(), *store.run_suites()], db)
    refuse_unstored("planner", planners, store.planner_names(), db)


def add_scenario_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("scenario (a file, or a generator with a seed and target)")
    g.add_argument("--scenario", metavar="FILE", help="scenario JSON file")
    g.add_argument("--terrain", metavar="GENERATOR", default="rbf", help="terrain generator name (default: rbf)")
    g.add_argument("--seed", type=int, default=0, help="generator seed (default: 0)")
    g.add_argument("--target", type=float, default=1.12, help="target volume in m³ (default: 1.12)")
    g.add_argument("--param", action="append", default=[], metavar="KEY=JSON", help="generator parameter, e.g. n_bases=30 (repeatable)")


def _key_value(item: str, option: str) -> tuple[str, str]:
    key, eq, raw = item.partition("=")
    if not eq or not key.strip():
        raise EarthbenchError(f"{option} {item!r}: expected KEY=VALUE")
    return key.strip(), raw


def load_scenario(args: argparse.Namespace) -> Scenario:
    if args.scenario:
        return Scenario.from_json(Path(args.scenario))
    gen = TERRAINS.get(args.terrain)
    params = {}
    for item in args.param:
        key, raw = _key_value(item, "--param")
        try:
            params[key] = json.loads(raw)
        except json.JSONDecodeError:
            params[key] = raw
    check_params(args.terrain, gen, params)
    return gen(args.seed, args.target, **params)


def check_params(name: str, gen: Any, params: dict[str, Any]) -> None:
    """Refuse a parameter the generator ``gen(seed, target_volume, **params)`` does not take, with close matches."""
    try:
        sig = inspect.signature(gen)
    except (TypeError, ValueError):  # not introspectable: the generator checks for itself
        return
    ps = list(sig.parameters.values())
    if any(p.kind is p.VAR_KEYWORD for p in ps):
        return
    known = [p.name for p in ps[2:] if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
    for key in params:
        if key not in known:
            raise UnknownNameError(f"{name} parameter", key, known)


def parse_config(items: list[str], planner: PlannerInfo | type[Planner]) -> dict[str, Any]:
    """``--config KEY=VALUE`` items as overrides of the planner's ``Config``: known fields only, values of
    the field's type (read from the planner's description, :mod:`earthbench.running.harness.probe`: no plugin code runs)."""
    if isinstance(planner, type):
        planner = info_of_class(planner.name, planner)
    hints = planner.hints()
    fields = list(hints)
    out: dict[str, Any] = {}
    for item in items:
        key, raw = _key_value(item, "--config")
        if key not in fields:
            raise UnknownNameError(f"{planner.name} setting", key, fields)
        out[key] = _convert(raw, hints.get(key, Any), f"--config {key}={raw}")
    return out


def _convert(raw: str, hint: Any, where: str) -> Any:
    """``raw`` as a value of type ``hint`` (bool, int, float, str, tuples and lists of them, optionals)."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if type(None) in args and raw.strip().lower() in ("none", "null"):
            return None
        errors = []
        for a in (a for a in args if a is not type(None)):
            try:
                return _convert(raw, a, where)
            except EarthbenchError as exc:
                errors.append(str(exc))
        raise EarthbenchError(errors[0] if errors else f"{where}: cannot convert")
    if hint is bool:
        low = raw.strip().lower()
        if low in ("true", "yes", "1", "on"):
            return True
        if low in ("false", "no", "0", "off"):
            return False
        raise EarthbenchError(f"{where}: expected true or false")
    if hint in (int, float):
        try:
            v = float(raw) if hint is float else int(raw)
        except ValueError:
            raise EarthbenchError(f"{where}: expected {'a number' if hint is float else 'an integer'}") from None
        return v
    if hint is str:
        return raw
    if origin in (tuple, list):
        try:
            seq = json.loads(raw)
        except json.JSONDecodeError:
            seq = [s for s in raw.split(",") if s.strip()]
        if not isinstance(seq, list):
            seq = [seq]
        item = args[0] if args else Any
        vals = [_convert(json.dumps(v) if not isinstance(v, str) else v, item, where) for v in seq]
        return tuple(vals) if origin is tuple else vals
    try:
        return json.loads(raw)
    except json.JSONDecodeError:
        return raw


def add_config_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", action="append", default=[], metavar="KEY=VALUE",
                   help="planner setting, a field of its Config (repeatable; `earthbench list planners --settings` lists them), "
                        "converted to the field's type, e.g. --config min_fill=0.5")


def add_plugin_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--plugin", action="append", default=[], metavar="FILE.py", help="load planners from a Python file (repeatable)")


def load_plugins(args: argparse.Namespace) -> None:
    """The command's ``--plugin`` files: checked, and described by a fenced probe when a planner is
    looked up (docs/DESIGN.md §6 "Plugin code"); never imported into this process."""
    use_plugin_files(getattr(args, "plugin", []) or [])


def plain(doc: str | None) -> str:
    """A module docstring as help text: reStructuredText roles and double backquotes become `code`."""
    text = re.sub(r":(?:func|class|mod|meth|data|attr|exc):`~?([^`]+)`", r"`\1`", doc or "")
    return text.replace("``", "`")


class PrintableStream:
    """A command's stdout or stderr that writes everything as :func:`~earthbench.errors.printable`
    text: the one place printed text is made safe, so no print of a planner's name, an error, a
    log tail or a suite name can reach the terminal as a control sequence. ``raw`` is the
    stream underneath, for earthbench's own progress line (which escapes what it prints)."""

    def __init__(self, raw: TextIO):
        self.raw = raw

    def write(self, text: str) -> int:
        return self.raw.write(printable(text))

    def writelines(self, lines: Any) -> None:
        for line in lines:
            self.write(line)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.raw, name)
