"""Median time per target m³ over the best known plan's, per family and planner (issue 49).

Reads the kept best known plans of a suite (``leaderboard/best/<suite>/``, `earthbench best`) and
the runs of one or more stores; each run's time per target m³ is divided by its scenario's best
known one (a run short of the target counts as infinite). Stores are told apart by their place
on the command line, as in ``scripts/backhoe_timeline.py``::

    python scripts/best_known_ratio.py new.db leaderboard/standard.db --planner stl-tamp --planner greedy
"""

from __future__ import annotations

import argparse
import gzip
import json
import math
import statistics
from collections import defaultdict
from pathlib import Path

from earthbench.results.store import Store


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("stores", nargs="+")
    ap.add_argument("--suite", default="standard")
    ap.add_argument("--best", default=None, help="folder of best known plans (default leaderboard/best/<suite>)")
    ap.add_argument("--planner", action="append", default=None)
    args = ap.parse_args()
    folder = Path(args.best or f"leaderboard/best/{args.suite}")
    best = {}
    for f in folder.glob("*.json.gz"):
        d = json.loads(gzip.open(f).read())
        best[d["scenario_digest"]] = float(d["time_per_target_m3"])
    ratios: dict[tuple[str, str], list[float]] = defaultdict(list)
    for n, path in enumerate(args.stores):
        for r in Store(path, read_only=True).runs():
            if r["suite"] != args.suite or r["scenario_digest"] not in best:
                continue
            if args.planner and r["planner"] not in args.planner:
                continue
            t = json.loads(r["metrics"] or "{}").get("time_per_target_m3") if r["success"] else None
            key = (str(r["family"]).split(".")[0], f"{r['planner']} {r['planner_version']} [{n}]")
            ratios[key].append(float(t) / best[r["scenario_digest"]] if t else math.inf)
    print(f"{'family':>16} {'planner':>32} {'runs':>5} {'x best known (median)':>22}")
    for who in sorted({w for _, w in ratios}):
        ratios[("all", who)] = [x for (f, w), xs in list(ratios.items()) if w == who for x in xs]
    for (fam, who), xs in sorted(ratios.items()):
        print(f"{fam:>16} {who:>32} {len(xs):>5} {statistics.median(xs):>22.3f}")


if __name__ == "__main__":
    main()
