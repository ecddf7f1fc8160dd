"""Helpers shared by the CLI commands: loading scenarios and planners by name or file."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..registry import TERRAINS, load_plugin_file
from ..world import Scenario


def add_scenario_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("scenario (a file, or a generator with a seed and target)")
    g.add_argument("--scenario", metavar="FILE", help="scenario JSON file")
    g.add_argument("--terrain", metavar="GENERATOR", default="rbf", help="terrain generator name (default: rbf)")
    g.add_argument("--seed", type=int, default=0, help="generator seed (default: 0)")
    g.add_argument("--target", type=float, default=1.12, help="target volume in m³ (default: 1.12)")
    g.add_argument("--param", action="append", default=[], metavar="KEY=JSON", help="generator parameter, e.g. n_bases=30 (repeatable)")


def load_scenario(args: argparse.Namespace) -> Scenario:
    if args.scenario:
        return Scenario.from_json(Path(args.scenario))
    params = {}
    for item in args.param:
        key, _, raw = item.partition("=")
        try:
            params[key] = json.loads(raw)
        except json.JSONDecodeError:
            params[key] = raw
    return TERRAINS.get(args.terrain)(args.seed, args.target, **params)


def add_plugin_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--plugin", action="append", default=[], metavar="FILE.py", help="load planners from a Python file (repeatable)")


def load_plugins(args: argparse.Namespace) -> None:
    for path in getattr(args, "plugin", []) or []:
        load_plugin_file(path)
