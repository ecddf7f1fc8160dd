"""Which stored stl-tamp and separate plans ``hierarchy.nlp_start`` could change, from the stores alone.

stl-tamp 0.12.2 and separate 0.5.2 show their NLPs a truck that stands nearer the base than
Eq. (23)'s clearance plus ``Shape.col_margin``, less ``NODE0_TOLERANCE``, a centimetre beyond
that distance (planners/stl_tamp/NOTES.md, "0.12.2"). Every NLP starts where the plan's actions
so far leave both machines, which is where they stand once the last of those actions ends. A
plan whose machines are never that near at its start or at the end of an action is the version
before's, action for action. This lists the plans that are: only they need planning again.

    python scripts/node0_bound.py leaderboard/standard.db leaderboard/20t/board-20t.db
"""

from __future__ import annotations

import argparse
import math
from dataclasses import astuple

from earthbench.plan import Plan
from earthbench.results.store import Store, load_runs
from earthbench.running.playback.geometry import machine_paths, pose_at
from earthbench.world import Scenario
from earthbench_planners.stl_tamp.hierarchy import NODE0_TOLERANCE
from earthbench_planners.stl_tamp.problem import Shape


def nearest_state(scenario: Scenario, plan: Plan) -> float:
    """The smallest base–truck distance at the start of the plan and at the end of every action:
    an NLP starts where the actions before it leave both machines, which is where they stand once
    the last of those actions ends."""
    paths = machine_paths(scenario, plan)
    m = scenario.machines
    exc, truck = astuple(m.excavator_pose), astuple(m.truck_pose)
    ends = [0.0] + [a.t_end for a in plan.actions]
    return min(math.dist(pose_at(exc, paths["excavator"], t)[:2], pose_at(truck, paths["truck"], t)[:2]) for t in ends)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("stores", nargs="+")
    ap.add_argument("--tolerance", type=float, default=NODE0_TOLERANCE,
                    help=f"m inside the distance that counts (default: nlp_start's, {NODE0_TOLERANCE}; 0: any state inside it)")
    a = ap.parse_args()
    margin = Shape.__dataclass_fields__["col_margin"].default
    for db in a.stores:
        runs = load_runs(db)
        store = Store(db, create=False)
        runs = runs[runs["planner"].isin(["stl-tamp", "separate"])]
        for (planner, version), group in runs.groupby(["planner", "planner_version"]):
            kept, near = 0, []
            for rid, digest, sid in zip(group["id"], group["scenario_digest"], group["scenario_id"]):
                text = store.plan_json(int(rid))
                if not text:
                    continue
                kept += 1
                sc = store.scenario(digest)
                d = nearest_state(sc, Plan.from_json(text))
                if d < sc.machines.excavator.clearance + margin - a.tolerance + 1e-6:
                    near.append(f"{sid} ({d:.6f} m)")
            print(f"{db}: {planner} {version}: {kept} plans, {len(near)} with the truck within the NLP's clearance"
                  f"{': ' + ', '.join(near) if near else ''}")


if __name__ == "__main__":
    main()
