"""``earthbench show``: the terrain before and after a plan as the referee replays it, or an animation of it."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..plan import Plan
from ..referee import judge
from ._common import add_scenario_args, load_scenario


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "show",
        help="draw the terrain before and after a plan (or animate it), with paths, digs, dumps and violations",
        description="Draw a scenario's terrain before and after the plan as the referee replays it, cropped to the map: "
        "the dig area, each machine's moves (a jump between moves is a red dashed line), start (○) and end (▲) poses, "
        "the excavator's reach annulus at each station it dug from, bucket footprints, dumps (■) and every violation "
        "in red at its action. With --animate, write the replay as a GIF (or an MP4, with ffmpeg on PATH).",
    )
    add_scenario_args(p)
    p.add_argument("--plan", metavar="PLAN.json", help="plan to replay (default: only the terrain)")
    p.add_argument("-o", "--out", default="earthbench-show.png", metavar="FILE.png",
                   help="output image, any format matplotlib writes (default: earthbench-show.png)")
    p.add_argument("--animate", metavar="OUT.gif|OUT.mp4", help="also write the replay as an animation (one frame per change)")
    p.add_argument("--frames", type=int, default=80, metavar="N", help="with --animate: evenly spaced frames (default: 80)")
    return p


def run(args: argparse.Namespace) -> int:
    from ..figures import animate, terrain_before_after

    scenario = load_scenario(args)
    plan = Plan.from_json(Path(args.plan)) if args.plan else Plan()
    verdict = judge(scenario, plan)
    fig = terrain_before_after(scenario, plan, verdict)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out} ({verdict.summary()}, loaded {verdict.loaded_volume:.3f} m³)")
    if args.animate:
        n = animate(scenario, plan, args.animate, frames=max(2, args.frames))
        print(f"wrote {args.animate} ({n} frames)")
    return 0
