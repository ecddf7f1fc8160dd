"""``earthbench list``: what is registered, and which plugins failed to load."""

from __future__ import annotations

import argparse

from ..registry import METRICS, PLANNERS, TERRAINS, Registry
from ._common import add_plugin_arg, load_plugins

KINDS: dict[str, Registry] = {"planners": PLANNERS, "terrains": TERRAINS, "metrics": METRICS}


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("list", help="list registered planners, terrain generators or metrics")
    p.add_argument("kind", nargs="?", choices=sorted(KINDS), help="what to list (default: everything)")
    add_plugin_arg(p)
    return p


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
        for name, why in sorted(reg.failures.items()):
            print(f"  {name:<24} FAILED TO LOAD: {why}")
    return 0
