"""Issue 49: where a backhoe plan's time to the target goes above the target bound.

For each valid plan it re-judges (a store's runs of one planner, or the best known plans of a
folder), the excavator's timeline up to the end of the dump that reached the target is split
into what the bound charges and what it does not (docs/metrics.md, "What the geometry forces"):

- ``bound``     — ``lower_bound_time_to_target``: ``n`` strokes and dumps at their least time and
                  the travel before the first dump (``S₁ − t_s``);
- ``buckets``   — the digs and dumps beyond ``n`` (part-filled buckets: ``(k − n)(t_s + t_d)``);
- ``dig swing`` — the digs' time above the least stroke (the swing to the contact, and slack);
- ``dump swing``— the dumps' time above the least dump (the swing to the truck, and slack);
- ``exc move``  — the excavator driving (relocations), less the travel the bound already counts;
- ``wait``      — the excavator idle (for the truck, or for nothing).

Each is reported in seconds and as a share of the bound; the rows add up to the plan's time to the
target. Also the truck's driving time, and the number of relocations.

    python scripts/backhoe_time_budget.py STORE.db --planner greedy [--family F] [--limit N]
    python scripts/backhoe_time_budget.py STORE.db --best leaderboard/best/standard [--family F]

(the store supplies the scenarios by digest in both cases).
"""

from __future__ import annotations

import argparse
import json
import math
from collections import defaultdict

import numpy as np

from earthbench.publishing.best import kept
from earthbench.plan import Dig, Dump, Move, Plan
from earthbench.referee import judge
from earthbench.results.scoring import time_to_target
from earthbench.results.store import Store
from earthbench.world import Scenario
from earthbench_metrics.run import lower_bound_time_to_target

PARTS = ("buckets", "dig swing", "dump swing", "exc move", "wait")


def budget(sc: Scenario, plan: Plan) -> dict[str, float] | None:
    """The split of the module docstring (seconds), or None for an invalid plan or one short of the target."""
    v = judge(sc, plan)
    target = sc.task.target_volume
    end = time_to_target(v.load_curve, target)
    if not v.valid or not math.isfinite(end):
        return None
    e = sc.machines.excavator
    assert e is not None
    fill = sc.soil.fill_factor if sc.soil is not None else 1.0
    n = math.ceil(target / (e.bucket_capacity * fill) - 1e-9)
    bound = lower_bound_time_to_target(sc)
    s1_travel = max(bound - e.min_dump_time - (n - 1) * (e.min_stroke_time + e.min_dump_time) - e.min_stroke_time, 0.0)
    digs = [a for a in plan.actions if isinstance(a, Dig) and a.machine == "excavator" and a.t_end <= end + 1e-9]
    dumps = [a for a in plan.actions if isinstance(a, Dump) and a.machine == "excavator" and a.t_end <= end + 1e-9]
    moves = [a for a in plan.actions if isinstance(a, Move)]
    exc_move = sum(min(m.path[-1][0], end) - m.path[0][0] for m in moves if m.machine == "excavator" and m.path[0][0] < end)
    truck_move = sum(min(m.path[-1][0], end) - m.path[0][0] for m in moves if m.machine == "truck" and m.path[0][0] < end)
    relocations = sum(1 for m in moves if m.machine == "excavator" and m.path[0][0] < end)
    dig_t = sum(d.t_end - d.t_start for d in digs)
    dump_t = sum(d.t_end - d.t_start for d in dumps)
    k = min(len(digs), len(dumps))
    out = {
        "time": end,
        "bound": bound,
        "buckets": (k - n) * (e.min_stroke_time + e.min_dump_time),
        "dig swing": dig_t - len(digs) * e.min_stroke_time - max(len(digs) - k, 0) * e.min_stroke_time,
        "dump swing": dump_t - len(dumps) * e.min_dump_time,
        "exc move": exc_move - min(s1_travel, exc_move),
        "truck move": truck_move,
        "relocations": float(relocations),
        "digs": float(len(digs)),
        "n": float(n),
    }
    out["wait"] = end - bound - sum(out[p] for p in PARTS[:-1])
    return out


def _rows(args: argparse.Namespace, store: Store) -> list[tuple[str, str, str, str]]:
    """(scenario id, family, plan JSON, scenario digest) to study."""
    rows = []
    if args.best:
        ids = {r["scenario_digest"]: (r["scenario_id"], r["family"]) for r in store.runs()}
        for digest, doc in kept(args.best.rsplit("/", 1)[0], args.best.rsplit("/", 1)[1]).items():
            if digest in ids:
                plan = doc["plan"]
                rows.append((*ids[digest], plan if isinstance(plan, str) else json.dumps(plan), digest))
    else:
        for r in store.runs():
            text = store.plan_json(int(r["id"])) if r["planner"] == args.planner and r["reason"] == "ok" else None
            if text is not None:
                rows.append((r["scenario_id"], r["family"], text, r["scenario_digest"]))
    rows = [r for r in rows if not args.family or r[1] == args.family]
    return sorted(rows)[: args.limit or None]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("store")
    ap.add_argument("--planner", default="greedy")
    ap.add_argument("--best", default="", help="a best-known suite folder (ROOT/SUITE) instead of a planner's runs")
    ap.add_argument("--family", default="")
    ap.add_argument("--limit", type=int, default=0)
    ap.add_argument("--quiet", action="store_true", help="only the per-family medians")
    args = ap.parse_args()
    store = Store(args.store, read_only=True)
    per_family: dict[str, list[dict[str, float]]] = defaultdict(list)
    for sid, family, plan_json, digest in _rows(args, store):
        sc = store.scenario(digest)
        b = budget(sc, Plan.from_json(plan_json))
        if b is None:
            continue
        per_family[family].append(b)
        if not args.quiet:
            parts = ", ".join(f"{p} {b[p] / b['bound']:+.2f}" for p in PARTS)
            print(f"{sid}: {b['time'] / b['bound']:.2f} × bound = 1 {parts}; {b['digs']:.0f} digs for n={b['n']:.0f}, "
                  f"{b['relocations']:.0f} relocations, truck driving {b['truck move']:.0f} s")
    for family, bs in sorted(per_family.items()):
        med = {p: float(np.median([b[p] / b["bound"] for b in bs])) for p in (*PARTS, "time")}
        mean = {p: float(np.mean([b[p] / b["bound"] for b in bs])) for p in PARTS}
        print(f"{family} ({len(bs)} plans): median {med['time']:.2f} × bound; mean share of the bound above it: "
              + ", ".join(f"{p} {mean[p]:.3f}" for p in PARTS)
              + f"; median relocations {np.median([b['relocations'] for b in bs]):.0f}")


if __name__ == "__main__":
    main()
