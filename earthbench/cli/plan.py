"""``earthbench plan PLANNER``: run one planner on one scenario and write its plan."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ..harness.steps import run_closed_loop
from ..registry import PLANNERS
from ..sensing import observe
from ._common import add_config_arg, add_plugin_arg, add_scenario_args, load_plugins, load_scenario, parse_config


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "plan",
        help="run a planner on one scenario and write the plan JSON",
        description="Run PLANNER on a scenario (a file, or a generator, seed and target) and write its plan. "
        "This runs in-process, without the runner's budget; use `earthbench run` for benchmarking.",
    )
    p.add_argument("planner", help="planner name (see `earthbench list planners`)")
    add_scenario_args(p)
    add_plugin_arg(p)
    add_config_arg(p)
    p.add_argument("-o", "--out", metavar="PLAN.json", help="where to write the plan (default: standard output)")
    p.add_argument("--save-scenario", metavar="FILE", help="also write the scenario JSON (to validate the plan later)")
    return p


def run(args: argparse.Namespace) -> int:
    load_plugins(args)
    cls = PLANNERS.get(args.planner)
    overrides = parse_config(args.config, cls)
    scenario = load_scenario(args)
    if args.save_scenario:
        scenario.to_json(args.save_scenario)
    view = observe(scenario)  # the planner sees the scan and the nominal soil, as under the harness
    t0 = time.perf_counter()
    planner = cls(**overrides)
    if cls.prepares():  # its preparation on this machine, if there is one (never run here: `earthbench prepare`)
        from ..records import PlannerRef
        from ..harness.prepare import find

        found = find(PlannerRef.resolve(args.planner, overrides))
        planner.prepared = Path(found.path) if found is not None else None
    # a closed-loop configuration is run step by step, each step executed on the truth as the harness does
    plan = run_closed_loop(planner, scenario) if planner.closed_loop else planner.plan(view)
    dt = time.perf_counter() - t0
    text = plan.to_json(args.out)
    if not args.out:
        print(text)
    print(f"{args.planner}: {len(plan.actions)} actions in {dt:.2f} s for scenario {scenario.id}", file=sys.stderr)
    return 0
