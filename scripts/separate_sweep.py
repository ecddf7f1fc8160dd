"""The STL-TAMP paper's sweep of the "Separate" method: local-area divisions 5–12 (Fig. 7a).

Runs the ``separate`` planner once per division count on the ``paper-separate-sweep`` suite
(the paper-extensive maps, one scenario per seed) through the ordinary harness — fresh process
per case, 2-core slots, the suite's budget, the referee — and stores every run in ``--db``.
Each division count is its own planner configuration (``divisions = N``), so the store keeps
them apart and a rerun resumes. Plot with ``scripts/fig7a.py``.

    python scripts/separate_sweep.py --db separate-sweep.db                  # 8 counts × 10 seeds
    python scripts/separate_sweep.py --db separate-sweep.db --seeds 0-2 --divisions 5,8,12
"""

from __future__ import annotations

import argparse
import sys

from earthbench.results.progress import Progress
from earthbench.running.harness import Case, LocalExecutor, PlannerRef, run_cases
from earthbench.results.store import Store
from earthbench.results.suite import load_suite, parse_seed_range


def divisions_arg(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b or a) + 1))
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--db", default="separate-sweep.db", help="results database (default: separate-sweep.db)")
    p.add_argument("--suite", default="paper-separate-sweep", help="suite (default: paper-separate-sweep)")
    p.add_argument("--divisions", default="5-12", type=divisions_arg, help="division counts, e.g. 5-12 or 5,8,12")
    p.add_argument("--seeds", help="only these seeds, e.g. 0-4")
    p.add_argument("--jobs", type=int, default=None, help="cases at once (default: floor(cores / 2))")
    p.add_argument("--quiet", action="store_true")
    args = p.parse_args(argv)
    suite = load_suite(args.suite)
    seeds = parse_seed_range(args.seeds) if args.seeds else None
    scenarios = suite.select(seeds)
    cases = [Case(suite.name, suite.digest, suite.success_threshold, sc, PlannerRef.resolve("separate", {"divisions": d}))
             for d in args.divisions for sc in scenarios]
    with Store(args.db) as store:
        store.check_writable()
        store.register_suite(suite)
        progress = Progress(len(cases), quiet=args.quiet)
        report = run_cases(cases, store, LocalExecutor(args.jobs, cores_per_case=suite.budget.cores), progress=progress)
    print(f"{report.stored} stored, {report.skipped} already stored, counts {report.counts}", file=sys.stderr)
    return 1 if report.interrupted else 0


if __name__ == "__main__":
    raise SystemExit(main())
