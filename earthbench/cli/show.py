"""``earthbench show``: the terrain before and after a plan as the referee replays it, or an animation of it."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import EarthbenchError
from ..plan import Plan
from ..referee import judge
from ._common import add_scenario_args, load_scenario

#: The image ``show`` writes when neither -o nor --animate says where.
DEFAULT_OUT = "earthbench-show.png"


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
    p.add_argument("-o", "--out", metavar="FILE.png",
                   help=f"output image, any format matplotlib writes (default: {DEFAULT_OUT}, unless only --animate is given)")
    p.add_argument("--animate", metavar="OUT.gif|OUT.mp4",
                   help="write the replay as an animation (one frame per change); with -o, the image too")
    p.add_argument("--frames", type=int, default=80, metavar="N", help="with --animate: evenly spaced frames (default: 80)")
    return p


def run(args: argparse.Namespace) -> int:
    from ..running.figures import animate, animation_writer, terrain_before_after

    for out in (args.out, args.animate):  # every output checked before any work
        if out and not Path(out).resolve().parent.is_dir():
            raise EarthbenchError(f"cannot write {out!r}: the folder {str(Path(out).parent)!r} does not exist")
    if args.animate:
        animation_writer(args.animate)
    scenario = load_scenario(args)
    plan = Plan.from_json(Path(args.plan)) if args.plan else Plan()
    verdict = judge(scenario, plan)
    image = args.out or (None if args.animate else DEFAULT_OUT)
    if image:
        fig = terrain_before_after(scenario, plan, verdict)
        fig.savefig(image, dpi=110)
        where = "" if args.out else " (no -o given: the default file name)"
        print(f"wrote {Path(image).resolve()}{where} ({verdict.summary()}, loaded {verdict.loaded_volume:.3f} m³)")
    if args.animate:
        n = animate(scenario, plan, args.animate, frames=max(2, args.frames))
        print(f"wrote {Path(args.animate).resolve()} ({n} frames; {verdict.summary()}, loaded {verdict.loaded_volume:.3f} m³)")
    return 0
