"""Issue 48: how many excavator dumps would swing the bucket over the truck's cab.

Not a rule of the referee (docs/referee.md, "Measured, not a rule: the swing over the cab"): for
every stored plan, each dump's swing from the bearing the arm last pointed at (the last dig's
contact, or the last dump's truck) to the truck's centre, with the bucket at the truck's centre
distance from the base, is checked against the truck's front ``--cab`` metres (its pose's yaw is
its front), on the copy of a store it reads.

    python scripts/cab_swing_audit.py STORE.db [--cab 0.8]
"""

from __future__ import annotations

import argparse
import math
from collections import Counter

import numpy as np
import shapely

from earthbench.motion import wrap
from earthbench.plan import Dig, Dump, Plan
from earthbench.referee.state import Replay
from earthbench.results.store import Store, decompress
from earthbench.world import Scenario, rectangle


def cab_swings(sc: Scenario, plan: Plan, cab: float) -> tuple[int, int]:
    """(dumps whose swing passes over the cab, dumps) of one plan."""
    r = Replay(sc, plan)
    exc, truck, spec = r.timelines["excavator"], r.timelines["truck"], sc.machines.truck
    pointing: float | None = None
    over = dumps = 0
    for a in sorted(plan.actions, key=lambda a: a.t_start):
        base = exc.pose(a.t_start)
        if isinstance(a, Dig):
            pointing = math.atan2(a.contact[1] - base.y, a.contact[0] - base.x)
        elif isinstance(a, Dump) and pointing is not None:
            p = truck.pose(a.t_start)
            d, goal = math.hypot(p.x - base.x, p.y - base.y), math.atan2(p.y - base.y, p.x - base.x)
            th = pointing + np.linspace(0.0, wrap(goal - pointing), 200)
            front = rectangle(np.array([p.x]), np.array([p.y]), np.array([p.yaw]), -(spec.length / 2 - cab), spec.length / 2, spec.width)
            dumps += 1
            over += bool(shapely.contains_xy(shapely.Polygon(front[0]), base.x + d * np.cos(th), base.y + d * np.sin(th)).any())
            pointing = goal
    return over, dumps


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("store")
    ap.add_argument("--cab", type=float, default=0.8, help="length (m) of the truck's front that is its cab")
    args = ap.parse_args()
    store = Store(args.store, read_only=True)
    over, dumps, runs, hit = Counter(), Counter(), Counter(), Counter()
    for row in store.query():
        if row["plan"] is None or row["track"] != "backhoe":
            continue
        o, d = cab_swings(store.scenario(row["scenario_digest"]), Plan.from_json(decompress(row["plan"])), args.cab)
        key = f"{row['planner']} {row['planner_version']}"
        over[key] += o
        dumps[key] += d
        runs[key] += 1
        hit[key] += o > 0
    for key in sorted(runs):
        print(f"{key}: {over[key]} of {dumps[key]} dumps swing over the cab; {hit[key]} of {runs[key]} runs have one")


if __name__ == "__main__":
    main()
