"""``earthbench plan PLANNER``: run one planner on one scenario and write its plan."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ..running.harness.probe import info, resolve
from ..running.harness.steps import run_closed_loop
from ..plan import Plan
from ..registry import PLANNERS
from ..sensing import observe
from ._common import add_config_arg, add_plugin_arg, add_scenario_args, load_plugins, load_scenario, parse_config


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "plan",
        help="run a planner on one scenario and write the plan JSON",
        description="Run PLANNER on a scenario (a file, or a generator, seed and target) and write its plan. "
        "A built-in planner runs in-process, without the runner's budget; a plugin's planner (--plugin, an "
        "installed package) runs fenced as a case does. Use `earthbench run` for benchmarking.",
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
    if args.planner not in PLANNERS:  # a plugin file's or another distribution's: never imported here
        return _fenced(args)
    cls = PLANNERS.get(args.planner)
    resolve(args.planner)  # a plugin file of the same name is a clash
    overrides = parse_config(args.config, cls)
    scenario = load_scenario(args)
    if args.save_scenario:
        scenario.to_json(args.save_scenario)
    view = observe(scenario)  # the planner sees the scan and the nominal soil, as under the harness
    t0 = time.perf_counter()
    planner = cls(**overrides)
    if cls.prepares():  # its preparation on this machine, if there is one (never run here: `earthbench prepare`)
        from ..results.records import PlannerRef
        from ..running.harness.prepare import find

        found = find(PlannerRef.resolve(args.planner, overrides))
        planner.prepared = Path(found.path) if found is not None else None
    # a closed-loop configuration is run step by step, each step executed on the truth as the harness does
    plan = run_closed_loop(planner, scenario) if planner.closed_loop else planner.plan(view)
    dt = time.perf_counter() - t0
    return _write(args, plan, dt, scenario.id)


def _write(args: argparse.Namespace, plan: Plan, dt: float, scenario_id: str) -> int:
    text = plan.to_json(args.out)
    if not args.out:
        print(text)
    print(f"{args.planner}: {len(plan.actions)} actions in {dt:.2f} s for scenario {scenario_id}", file=sys.stderr)
    return 0


def _fenced(args: argparse.Namespace) -> int:
    """A plugin's planner runs as a case does (its fences and the scenario's budget), its preparation found
    on this machine if there is one; the plan it returns is written as it is (invalid ones too)."""
    from ..errors import EarthbenchError
    from ..running.harness.prepare import find
    from ..running.harness.run import run_case
    from ..results.records import Case

    ref = resolve(args.planner, parse_config(args.config, info(args.planner)))
    scenario = load_scenario(args)
    if args.save_scenario:
        scenario.to_json(args.save_scenario)
    res = run_case(Case("plan", "", 0.0, scenario, ref), prepared=find(ref) if ref.prepares else None)
    if res.plan_json is None:
        raise EarthbenchError(f"planner {args.planner!r} returned no plan ({res.reason}): "
                              + (res.error.strip().splitlines() or [""])[-1])
    return _write(args, Plan.from_json(res.plan_json), res.solve_time_s or 0.0, scenario.id)
