"""``earthbench list``: what is registered, and which plugins failed to load."""

from __future__ import annotations

import argparse
import inspect
import json

from ..running.harness.probe import PlannerInfo, catalogue
from ..registry import METRICS, PLANNERS, TERRAINS, Registry
from ._common import add_plugin_arg, load_plugins

KINDS: dict[str, Registry] = {"planners": PLANNERS, "terrains": TERRAINS, "metrics": METRICS}


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("list", help="list registered planners, terrain generators or metrics")
    p.add_argument("kind", nargs="?", choices=sorted(KINDS), help="what to list (default: everything)")
    p.add_argument("--settings", action="store_true",
                   help="also each planner's settings (its Config fields and defaults, for --config KEY=VALUE) "
                        "and each generator's parameters (for --param KEY=VALUE)")
    add_plugin_arg(p)
    return p


def settings(kind: str, obj: object) -> str:
    """``key=default`` of a planner's settings (its description) or of a generator's keyword parameters."""
    if kind == "planners" and isinstance(obj, PlannerInfo):
        return ", ".join(f"{s.name}={_default(s.default)}" if s.has_default else s.name for s in obj.settings)
    if kind == "terrains":
        try:
            ps = list(inspect.signature(obj).parameters.values())[2:]  # type: ignore[arg-type]
        except (TypeError, ValueError):
            return ""
        return ", ".join(f"{q.name}={q.default!r}" if q.default is not q.empty else q.name
                         for q in ps if q.kind in (q.POSITIONAL_OR_KEYWORD, q.KEYWORD_ONLY))
    return ""


def _default(value: object) -> str:
    """A default as Python writes it (JSON lists were tuples or lists: shown as JSON)."""
    return repr(value) if not isinstance(value, (list, dict)) else json.dumps(value)


def run(args: argparse.Namespace) -> int:
    load_plugins(args)
    for kind in [args.kind] if args.kind else list(KINDS):
        reg = KINDS[kind]
        print(f"{kind}:")
        failures = dict(reg.failures)
        if kind == "planners":
            cat = catalogue()
            failures.update(cat.failures)
            for name, info in sorted(cat.planners.items()):
                print(f"  {name:<24} v{info.version:<6} tracks={','.join(info.tracks):<20} {info.doc}")
                if args.settings and settings(kind, info):
                    print(f"  {'':<24} settings: {settings(kind, info)}")
        else:
            for name, obj in reg.items():
                doc = (getattr(obj, "__doc__", "") or "").strip().splitlines()
                print(f"  {name:<24} {doc[0] if doc else ''}")
                if args.settings and settings(kind, obj):
                    print(f"  {'':<24} params: {settings(kind, obj)}")
            for name in sorted(reg.foreign):
                print(f"  {name:<24} NOT LOADED: {reg.foreign_message(name)}")
        for name, why in sorted(failures.items()):
            print(f"  {name:<24} FAILED TO LOAD: {why}")
    return 0
