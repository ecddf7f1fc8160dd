"""CPU per stl-tamp plan of two installs side by side: each plan in a fresh process (what a case
pays), the two installs' plans of a scenario in turn (the first alternating) or at once
(``--together``, one core each), and whether their actions are the same (planners/stl_tamp/NOTES.md).

    python scripts/versions_side_by_side.py OLD_PYTHON NEW_PYTHON --suite paper-extensive --target 7 \\
        --seeds 0-9 --new-prepared DIR
    python scripts/versions_side_by_side.py OLD_PYTHON NEW_PYTHON --suite scale --target 256 --seeds 0-3 \\
        --new-prepared DIR --together

OLD_PYTHON and NEW_PYTHON are the interpreters of two installs (e.g. a worktree of stl-tamp
0.9.0's commit with its own venv, and this checkout's); ``--old-prepared``/``--new-prepared``
point either at its preparation's folder (``earthbench prepare stl-tamp`` prints it). An install
without a preparation solves on the NLP disk cache, as its cases did when it was published. One
JSON line per plan, then the medians and the paired ratio new/old per scenario. Times are
``time.process_time`` around ``plan()`` inside each process, never a planner's own figure.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys

from earthbench.results.suite import load_suite, parse_seed_range

#: What each process runs: only names every stl-tamp install since 0.9.0 has.
ONE_PLAN = """
import hashlib, json, sys, time
from earthbench.referee import judge
from earthbench.results.suite import load_suite
from earthbench_planners.stl_tamp import StlTampPlanner
suite, scenario_id, prepared = sys.argv[1], sys.argv[2], sys.argv[3] or None
sc = next(s for s in load_suite(suite).scenarios if s.id == scenario_id)
planner = StlTampPlanner()
if prepared:
    planner.prepared = prepared
c0, w0 = time.process_time(), time.perf_counter()
plan = planner.plan(sc)
cpu, wall = time.process_time() - c0, time.perf_counter() - w0
actions = json.dumps(plan.to_dict()["actions"], sort_keys=True).encode()
print(json.dumps({"version": planner.version, "cpu_s": round(cpu, 3), "wall_s": round(wall, 3), "valid": judge(sc, plan).valid,
                  "digest": hashlib.sha256(actions).hexdigest()[:16],
                  "load": float(open("/proc/loadavg").read().split()[0])}))
"""


def start(python: str, suite: str, scenario_id: str, prepared: str | None) -> subprocess.Popen[str]:
    return subprocess.Popen([python, "-c", ONE_PLAN, suite, scenario_id, prepared or ""],
                            stdout=subprocess.PIPE, text=True)


def result(proc: subprocess.Popen[str]) -> dict:
    out, _ = proc.communicate()
    if proc.returncode != 0:
        raise SystemExit(f"a plan's process ended with {proc.returncode}")
    return json.loads(out.strip().splitlines()[-1])


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("old_python")
    ap.add_argument("new_python")
    ap.add_argument("--suite", default="paper-extensive")
    ap.add_argument("--target", type=float, required=True)
    ap.add_argument("--seeds", default="0-9")
    ap.add_argument("--old-prepared")
    ap.add_argument("--new-prepared")
    ap.add_argument("--together", action="store_true", help="run a scenario's two plans at once")
    args = ap.parse_args(argv)
    scenarios = [s for s in load_suite(args.suite).select(parse_seed_range(args.seeds))
                 if abs(s.task.target_volume - args.target) <= 1e-6]
    if not scenarios:
        raise SystemExit(f"no scenario of {args.target} m³ among seeds {args.seeds} of {args.suite!r}")
    sides = {"old": (args.old_python, args.old_prepared), "new": (args.new_python, args.new_prepared)}
    rows = []
    for n, sc in enumerate(scenarios):
        order = ("old", "new") if n % 2 == 0 else ("new", "old")
        if args.together:
            procs = {k: start(sides[k][0], args.suite, sc.id, sides[k][1]) for k in order}
            got = {k: result(p) for k, p in procs.items()}
        else:
            got = {k: result(start(sides[k][0], args.suite, sc.id, sides[k][1])) for k in order}
        row = {"id": sc.id, "first": order[0], **{f"{k}_{f}": got[k][f] for k in ("old", "new")
                                                    for f in ("version", "cpu_s", "wall_s", "valid", "load")},
               "same_plan": got["old"]["digest"] == got["new"]["digest"]}
        rows.append(row)
        print(json.dumps(row), flush=True)
    med = {k: statistics.median(r[f"{k}_cpu_s"] for r in rows) for k in ("old", "new")}
    paired = [r["new_cpu_s"] / r["old_cpu_s"] for r in rows]
    print(f"{len(rows)} scenarios: CPU per plan median {med['old']:.2f} s {rows[0]['old_version']}, {med['new']:.2f} s "
          f"{rows[0]['new_version']}; paired ratio new/old median {statistics.median(paired):.3f} "
          f"(range {min(paired):.3f}-{max(paired):.3f}); ratio of the medians {med['new'] / med['old']:.3f}; "
          f"same plan {sum(r['same_plan'] for r in rows)}/{len(rows)}; valid {sum(r['new_valid'] for r in rows)}/{len(rows)}")


if __name__ == "__main__":
    main(sys.argv[1:])
