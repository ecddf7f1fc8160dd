"""A closed-loop planner in this process on a sample of a realistic suite: success, time per
target m³ and steps per scenario, for comparing two versions of earthbench side by side.

Seeds 0 and 1 of every family at the suite's smallest target, through
``earthbench.running.harness.steps.run_closed_loop`` (the harness's own step loop, without the sandbox)
and judged by ``earthbench.results.scoring.score``. To compare with an older earthbench, put its package
first on the path (the planners stay the installed ones)::

    git archive OLD earthbench | tar -x -C /tmp/old
    PYTHONPATH=/tmp/old python scripts/closed_loop_sample.py --suite standard-realistic --planner greedy
    python scripts/closed_loop_sample.py --suite standard-realistic --planner greedy
"""

from __future__ import annotations

import argparse
import statistics

import earthbench
from earthbench.running.harness.steps import run_closed_loop
from earthbench.registry import PLANNERS
from earthbench.results.scoring import score
from earthbench.results.suite import load_suite


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--suite", default="standard-realistic")
    ap.add_argument("--planner", default="greedy")
    ap.add_argument("--seeds", type=int, default=2, help="seeds 0 … N-1 of each family (default 2)")
    args = ap.parse_args()
    print(f"earthbench {earthbench.__version__} from {earthbench.__file__}")
    suite = load_suite(args.suite)
    smallest = min(sc.task.target_volume for sc in suite.scenarios)
    times = []
    for sc in suite.scenarios:
        if sc.meta["seed"] >= args.seeds or sc.task.target_volume != smallest:
            continue
        plan = run_closed_loop(PLANNERS.get(args.planner)(closed_loop=True), sc)
        _, m = score(sc, plan.to_json(), suite.success_threshold)
        times.append(m["time_per_target_m3"])
        print(f"{sc.id}: success {m['success']}, {m['time_per_target_m3']:.2f} s per target m³, makespan {m['makespan_s']:.1f} s, "
              f"{len(plan.info.get('steps', []))} steps")
    print(f"median time per target m³: {statistics.median(times):.2f} s over {len(times)} scenarios")


if __name__ == "__main__":
    main()
