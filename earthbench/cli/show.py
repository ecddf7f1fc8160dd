"""``earthbench show``: a PNG of the terrain before and after a plan, with the machines' paths."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..plan import Plan
from ..referee import judge
from ._common import add_scenario_args, load_scenario


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "show",
        help="draw the terrain before and after a plan, with the machines' paths, as a PNG",
        description="Draw a scenario's terrain before and after the plan (as the referee replays it), "
        "the dig area, the machines' paths and the dig and dump positions.",
    )
    add_scenario_args(p)
    p.add_argument("--plan", metavar="PLAN.json", help="plan to replay (default: only the terrain)")
    p.add_argument("-o", "--out", default="earthbench-show.png", metavar="FILE.png", help="output image (default: earthbench-show.png)")
    return p


def run(args: argparse.Namespace) -> int:
    from ..figures import terrain_before_after

    scenario = load_scenario(args)
    plan = Plan.from_json(Path(args.plan)) if args.plan else Plan()
    verdict = judge(scenario, plan)
    fig = terrain_before_after(scenario, plan, verdict)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out} ({verdict.summary()}, loaded {verdict.loaded_volume:.3f} m³)")
    return 0
