"""``earthbench list``: what is registered, and which plugins failed to load."""

from __future__ import annotations

import argparse
import dataclasses
import inspect

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
    """``key=default`` of a planner's ``Config`` or of a generator's keyword parameters."""
    config = getattr(obj, "Config", None)
    if kind == "planners" and dataclasses.is_dataclass(config):
        return ", ".join(f"{f.name}={f.default!r}" if f.default is not dataclasses.MISSING else f.name
                         for f in dataclasses.fields(config))
    if kind == "terrains":
        try:
            ps = list(inspect.signature(obj).parameters.values())[2:]  # type: ignore[arg-type]
        except (TypeError, ValueError):
            return ""
        return ", ".join(f"{q.name}={q.default!r}" if q.default is not q.empty else q.name
                         for q in ps if q.kind in (q.POSITIONAL_OR_KEYWORD, q.KEYWORD_ONLY))
    return ""


def run(args: argparse.Namespace) -> int:
    load_plugins(args)
    for kind in [args.kind] if args.kind else list(KINDS):
        reg = KINDS[kind]
        print(f"{kind}:")
        for name, obj in reg.items():
            if kind == "planners":
                doc = (obj.__doc__ or "").strip().splitlines()
                first = doc[0] if doc else ""
                print(f"  {name:<24} v{obj.version:<6} tracks={','.join(obj.tracks):<20} {first}")
            else:
                doc = (getattr(obj, "__doc__", "") or "").strip().splitlines()
                print(f"  {name:<24} {doc[0] if doc else ''}")
            if args.settings and settings(kind, obj):
                print(f"  {'':<24} settings: {settings(kind, obj)}" if kind == "planners" else f"  {'':<24} params: {settings(kind, obj)}")
        for name, why in sorted(reg.failures.items()):
            print(f"  {name:<24} FAILED TO LOAD: {why}")
    return 0
