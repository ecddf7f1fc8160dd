"""Check docs/metrics.md's promise, "no prefix of a plan scores or ranks better than the plan
itself", on every plan stored in one or more stores (issue 35): each stored plan is judged again
with every time-ordered prefix (:func:`earthbench.publishing.verify.prefix_violations`), against the
scenario stored beside it and its suite's success threshold.

    python scripts/prefix_check.py leaderboard-store.db other.db --jobs 2

Prints one line per store (plans, valid prefixes judged, violations) and every violation;
exit status 1 if any.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from concurrent.futures import ProcessPoolExecutor

from earthbench.plan import Plan
from earthbench.results.scoring import DEFAULT_SUCCESS_THRESHOLD
from earthbench.results.store import Store, decompress
from earthbench.publishing.verify import prefix_violations
from earthbench.world import Scenario


def _check(job: tuple[str, bytes, str, float]) -> tuple[str, int, list[str]]:
    label, scenario_blob, plan_json, threshold = job
    checked, broken = prefix_violations(Scenario.from_text(decompress(scenario_blob)), Plan.from_json(plan_json), threshold)
    return label, checked, broken


def _jobs(path: str):
    with Store(path, read_only=True) as store:
        thresholds = {r["name"]: r["threshold"] for r in store.suite_versions()}
        for row in store.runs():
            reason, blob = store.run_outcome(row["id"])
            if blob is None:
                continue  # no plan (crashed, timed out): nothing to cut
            label = f"{row['planner']} {row['planner_version']} {row['scenario_id']} (run {row['id']})"
            yield label, store.scenario_blob(row["scenario_digest"]), decompress(blob), \
                thresholds.get(row["suite"], DEFAULT_SUCCESS_THRESHOLD)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("db", nargs="+", help="stores to check")
    p.add_argument("--jobs", type=int, default=1, help="processes (default 1)")
    args = p.parse_args(argv)
    bad = 0
    with ProcessPoolExecutor(args.jobs) as pool:
        for path in args.db:
            plans: Counter[str] = Counter()
            checked = 0
            for label, n, broken in pool.map(_check, _jobs(path), chunksize=4):
                plans[label.split(" ")[0]] += 1
                checked += n
                for line in broken:
                    print(f"  {label}: {line}")
                bad += len(broken)
            print(f"{path}: {sum(plans.values())} plans ({', '.join(f'{k} {v}' for k, v in sorted(plans.items()))}), "
                  f"{checked} valid prefixes judged, {bad} violations so far", flush=True)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
