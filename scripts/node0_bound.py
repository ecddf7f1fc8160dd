"""Which stored stl-tamp and separate plans ``hierarchy.nlp_start`` could change, from the stores alone.

stl-tamp 0.12.2 and separate 0.5.2 show their NLPs a truck that stands nearer the base than
Eq. (23)'s clearance plus ``Shape.col_margin``, less ``NODE0_TOLERANCE``, a centimetre beyond
that distance (planners/stl_tamp/NOTES.md, "0.12.2"). Every NLP starts where the plan's actions
so far leave both machines, which is where they stand once the last of those actions ends. A
plan whose machines are never that near at the start or the end of an action is the version
before's, action for action. This lists the plans that are: only they need planning again.

    python scripts/node0_bound.py leaderboard/standard.db leaderboard/20t/board-20t.db
"""

from __future__ import annotations

import argparse
import json
import math

from earthbench.results.store import Store, load_runs
from earthbench_planners.stl_tamp.hierarchy import NODE0_TOLERANCE
from earthbench_planners.stl_tamp.problem import Shape



def _pose_at(moves: list[list[list[float]]], t: float, start: tuple[float, float]) -> tuple[float, float]:
    """Where a machine stands at ``t``: on the move under way (linear between samples), else
    where its last move before ``t`` ended (``start`` before any)."""
    at = start
    for path in moves:
        if path[0][0] > t:
            break
        if path[-1][0] <= t:
            at = (path[-1][1], path[-1][2])
            continue
        for a, b in zip(path, path[1:]):
            if a[0] <= t <= b[0]:
                f = (t - a[0]) / (b[0] - a[0]) if b[0] > a[0] else 1.0
                return (a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]))
    return at


def nearest_state(plan: dict, exc: tuple[float, float], truck: tuple[float, float]) -> float:
    """The smallest base–truck distance at the start and at the end of every action: an NLP
    starts where the actions before it leave both machines, which is where they stand once the
    last of those actions ends."""
    moves: dict[str, list] = {"excavator": [], "truck": []}
    ends = [0.0]
    for action in plan["actions"]:
        if action["type"] == "move":
            moves.setdefault(action["machine"], []).append(action["path"])
            ends.append(action["path"][-1][0])
        elif "t_end" in action:
            ends.append(action["t_end"])
    for path_list in moves.values():
        path_list.sort(key=lambda p: p[0][0])
    return min(math.dist(_pose_at(moves["excavator"], t, exc), _pose_at(moves["truck"], t, truck)) for t in ends)


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
                m = store.scenario(digest).machines
                e, t = m.excavator_pose, m.truck_pose
                d = nearest_state(json.loads(text), (e.x, e.y), (t.x, t.y))
                if d < m.excavator.clearance + margin - a.tolerance + 1e-6:
                    near.append(f"{sid} ({d:.6f} m)")
            print(f"{db}: {planner} {version}: {kept} plans, {len(near)} with the truck within the NLP's clearance"
                  f"{': ' + ', '.join(near) if near else ''}")


if __name__ == "__main__":
    main()
