"""The referee's cost of two installs side by side (docs/referee.md's goals: a 30-dig plan ≤ 10 ms,
a loader plan ≤ 30 ms): the cases of ``tests/bench/test_bench_referee.py`` (greedy's 30-dig plan
on ``rbf`` seed 0, singh-cannon-loader's plan on ``pile`` seed 0), judged ``--calls`` times in a
fresh process of each install, the two installs in turn for ``--rounds`` rounds. Times are
``time.process_time`` around ``judge`` (CPU, robust to a machine shared with other jobs); each
line is one process's median, then the medians over the rounds and their ratio new/old.

    python scripts/referee_side_by_side.py OLD_PYTHON NEW_PYTHON [--rounds 5] [--calls 60]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess

#: What each process runs: only names every install since the bench's cases existed has.
ONE_CASE = """
import json, statistics, sys, time
from earthbench import judge
case, calls = sys.argv[1], int(sys.argv[2])
if case == "backhoe":
    from earthbench_planners.greedy.backhoe import GreedyPlanner
    from earthbench_terrains.rbf import rbf
    sc = rbf(0, 30 * 0.28 * 0.97, n_bases=30)
    plan = GreedyPlanner().plan(sc)
else:
    from earthbench_planners.singh_cannon.loader import SinghCannonLoader
    from earthbench_terrains.pile import pile
    sc = pile(0, 4.0)
    plan = SinghCannonLoader().plan(sc)
v = judge(sc, plan)
ts = []
for _ in range(calls):
    t = time.process_time()
    judge(sc, plan)
    ts.append(time.process_time() - t)
print(json.dumps({"ms": 1000 * statistics.median(ts), "valid": v.valid, "rules": sorted({x.rule for x in v.violations})}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old")
    ap.add_argument("new")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--calls", type=int, default=60)
    args = ap.parse_args()
    got: dict[tuple[str, str], list[float]] = {}
    for r in range(args.rounds):
        for case in ("backhoe", "loader"):
            for side in (("old", "new") if r % 2 == 0 else ("new", "old")):
                out = subprocess.run([getattr(args, side), "-c", ONE_CASE, case, str(args.calls)], capture_output=True, text=True,
                                     check=True, cwd="/")
                line = json.loads(out.stdout)
                print(json.dumps({"round": r, "case": case, "side": side, **line}), flush=True)
                got.setdefault((case, side), []).append(line["ms"])
    for case in ("backhoe", "loader"):
        old, new = statistics.median(got[(case, "old")]), statistics.median(got[(case, "new")])
        print(f"{case}: old {old:.2f} ms, new {new:.2f} ms (medians of {args.rounds} process medians); new/old {new / old:.2f}")


if __name__ == "__main__":
    main()
