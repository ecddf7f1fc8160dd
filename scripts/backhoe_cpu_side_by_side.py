"""Solve CPU of the fast backhoe planners (greedy, singh-cannon-backhoe) of this checkout beside
those of an older commit, in one process, interleaved scenario by scenario (robust to a shared
machine's load): issue 49's budget (greedy ≤ 0.1 s, singh-cannon-backhoe ≤ 0.3 s at 7 m³).

    python scripts/backhoe_cpu_side_by_side.py OLD_COMMIT [--suite standard] [--target 7] [--repeats 3]

The old commit's ``planners/`` is extracted with ``git archive`` into a temporary folder and
imported as a package of its own (the core, ``earthbench``, is this checkout's). Times are
``time.process_time`` around ``plan()``, never a planner's own figure.
"""

from __future__ import annotations

import argparse
import importlib
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from earthbench.results.suite import load_suite

PLANNERS = {"greedy": ("greedy.backhoe", "GreedyPlanner"), "singh-cannon-backhoe": ("singh_cannon.backhoe", "SinghCannonBackhoe")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old_commit")
    ap.add_argument("--suite", default="standard")
    ap.add_argument("--target", type=float, default=7.0)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    root = Path(__file__).resolve().parent.parent
    with tempfile.TemporaryDirectory() as tmp:
        tar = subprocess.run(["git", "-C", str(root), "archive", args.old_commit, "planners"], check=True, capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", tmp], input=tar, check=True)
        (Path(tmp) / "planners").rename(Path(tmp) / "old_planners")
        sys.path.insert(0, tmp)
        pairs = {name: (getattr(importlib.import_module(f"old_planners.{mod}"), cls),
                        getattr(importlib.import_module(f"earthbench_planners.{mod}"), cls))
                 for name, (mod, cls) in PLANNERS.items()}
        scenarios = [sc for sc in load_suite(args.suite).scenarios if abs(sc.task.target_volume - args.target) < 1e-9]
        times: dict[tuple[str, str], list[float]] = {}
        for _ in range(args.repeats):
            for sc in scenarios:
                for name, (old, new) in pairs.items():
                    for which, cls in (("old", old), ("new", new)):
                        t0 = time.process_time()
                        cls().plan(sc)
                        times.setdefault((name, which), []).append(time.process_time() - t0)
    print(f"{len(scenarios)} scenarios of {args.suite} at {args.target:g} m³, {args.repeats} repeats, interleaved; old = {args.old_commit}")
    for (name, which), v in times.items():
        print(f"{name} {which}: median {np.median(v):.4f} s, p90 {np.percentile(v, 90):.4f} s")


if __name__ == "__main__":
    main()
