"""Where a backhoe plan's time goes: the excavator's timeline split into its parts, per family.

For every stored backhoe run of a suite (a board's store, read only), the excavator's makespan
to the target is split into dig strokes at their minimum, swing to the contact, dump at its
minimum, swing to the truck, excavator moves, and idle (waiting for the truck, or nothing); with
the dig count, the mean bucket fill, the swing per dump (degrees, between the last dig's contact
and the truck's centre, seen from the base) and the metres each machine travels. Every figure is
per target m³ (seconds) except the counts, and the table shows each family's median over its
runs, planner by planner, so two planners compare on the same scenarios (issue 49)::

    python scripts/backhoe_timeline.py leaderboard/standard.db [--suite standard] [--planner stl-tamp --planner greedy]
    python scripts/backhoe_timeline.py /tmp/new.db leaderboard/standard.db --planner stl-tamp

With several stores, runs are told apart by the store's place on the command line (``[0]``,
``[1]``) and only scenarios present in every store's runs are counted (a side-by-side
comparison of a new run against the board).
"""

from __future__ import annotations

import argparse
import json
import math
from collections import defaultdict

import numpy as np

from earthbench.plan import Dig, Dump, Move, Plan
from earthbench.results.store import Store, decompress

PARTS = ("stroke", "swing_dig", "dump", "swing_dump", "exc_move", "idle")


def budget(plan: Plan, stroke: float, dump: float) -> dict[str, float]:
    """Seconds of each part of the excavator's timeline, with counts, swing and travel."""
    acts = sorted((a for a in plan.actions if a.machine == "excavator"), key=lambda a: a.t_start)
    out = dict.fromkeys(PARTS, 0.0)
    t, swings, digs = 0.0, [], 0
    truck = [a for a in plan.actions if isinstance(a, Move) and a.machine == "truck"]
    end = max((a.t_end for a in plan.actions), default=0.0)
    for a in acts:
        out["idle"] += max(a.t_start - t, 0.0)
        d = a.t_end - a.t_start
        if isinstance(a, Dig):
            digs += 1
            out["stroke"] += min(stroke, d)
            out["swing_dig"] += max(d - stroke, 0.0)
        elif isinstance(a, Dump):
            out["dump"] += min(dump, d)
            out["swing_dump"] += max(d - dump, 0.0)
            swings.append(d - dump)
        elif isinstance(a, Move):
            out["exc_move"] += d
        t = max(t, a.t_end)
    out["idle"] += max(end - t, 0.0)
    out["digs"] = digs
    out["exc_m"] = sum(_length(a) for a in acts if isinstance(a, Move))
    out["truck_m"] = sum(_length(a) for a in truck)
    out["truck_moves"] = len(truck)
    out["swing_per_dump_s"] = float(np.mean(swings)) if swings else math.nan
    return out


def _length(m: Move) -> float:
    p = np.asarray(m.path)
    return float(np.sum(np.hypot(np.diff(p[:, 1]), np.diff(p[:, 2]))))


def _swing_deg(seconds: float, rate: float) -> float:
    return math.degrees(seconds * rate)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("stores", nargs="+")
    ap.add_argument("--suite", default="standard")
    ap.add_argument("--planner", action="append", default=None)
    args = ap.parse_args()
    rows: dict[tuple[str, str], dict[str, dict[str, object]]] = defaultdict(dict)
    for n, path in enumerate(args.stores):
        store = Store(path, read_only=True)
        tag = f" [{n}]" if len(args.stores) > 1 else ""
        for r in store.runs():
            if r["suite"] != args.suite or r["track"] != "backhoe" or r["plan"] is None:
                continue
            if args.planner and r["planner"] not in args.planner:
                continue
            rows[(r["planner"], r["planner_version"] + tag)][r["scenario_digest"]] = dict(r) | {"store": store}
    common = set.intersection(*(set(v) for v in rows.values())) if rows else set()
    print(f"{len(common)} scenarios in every planner's runs; seconds per target m³, family medians")
    head = ["family", "planner", "n", "t/m3", "valid", *PARTS, "digs", "fill", "swing°", "exc_m", "truck_m", "cpu_s"]
    print(" ".join(f"{h:>12}" for h in head))
    by_family: dict[tuple[str, str, str], list[dict[str, float]]] = defaultdict(list)
    for key, runs in rows.items():
        for digest in common:
            r = runs[digest]
            store = r["store"]
            sc = store.scenario(digest)  # type: ignore[attr-defined]
            spec = sc.machines.excavator
            plan = Plan.from_json(decompress(r["plan"]))
            b = budget(plan, spec.min_stroke_time, spec.min_dump_time)
            v = float(r["target_volume"])
            row = {p: b[p] / v for p in PARTS} | {"digs": b["digs"], "exc_m": b["exc_m"], "truck_m": b["truck_m"],
                                                   "swing°": _swing_deg(b["swing_per_dump_s"], spec.swing_rate),
                                                   "fill": float(r["mean_bucket_fill"] or math.nan),
                                                   "t/m3": json.loads(r["metrics"] or "{}").get("time_per_target_m3", math.nan)
                                                   if r["success"] else math.nan,
                                                   "valid": float(bool(r["valid"])), "cpu_s": float(r["solve_cpu_s"] or math.nan)}
            by_family[(str(r["family"]).split(".")[0], *key)].append(row)
    for (fam, planner, version), rs in sorted(by_family.items()):
        cols = ["t/m3", "valid", *PARTS, "digs", "fill", "swing°", "exc_m", "truck_m", "cpu_s"]
        med = [float(np.nanmedian([x[c] for x in rs])) if c != "valid" else float(np.mean([x[c] for x in rs])) for c in cols]
        print(" ".join([f"{fam:>12}", f"{planner + ' ' + version:>12}", f"{len(rs):>12}"] + [f"{m:12.2f}" for m in med]))


if __name__ == "__main__":
    main()
