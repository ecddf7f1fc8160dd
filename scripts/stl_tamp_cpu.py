"""CPU per stl-tamp plan in one process, with the referee's time per target m³ and how the
solves ended (planners/stl_tamp/NOTES.md).

    python scripts/stl_tamp_cpu.py SEEDS TARGET [key=value ...]   # e.g. 0-9 7 max_iter=150
    python scripts/stl_tamp_cpu.py 0-9 7 --ipopt-local '{"perturb_dec_fact": 0.6}' --ipopt-global '{"mu_init": 0.1}'

Plans ``paper-extensive``'s scenarios of TARGET m³ for SEEDS (``a-b``) one after another in this
process (the first plan also pays the solvers' construction), each timed with
``time.process_time``; one JSON line per plan, then a summary line. ``key=value`` overrides a
field of stl-tamp's ``Config``; ``--ipopt-local`` and ``--ipopt-global`` (JSON objects) add IPOPT
options to the local or the global solves, for experiments that are no setting of the planner.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from typing import Any

from earthbench.cli import parse_config
from earthbench.referee import judge
from earthbench.suite import load_suite, parse_seed_range
from earthbench_metrics.run import core_metrics
from earthbench_planners.stl_tamp import StlTampPlanner


def with_ipopt(local_opts: dict[str, Any], global_opts: dict[str, Any]) -> type[StlTampPlanner]:
    """stl-tamp with extra IPOPT options for its local and its global solves."""

    class Planner(StlTampPlanner):
        def _ipopt_options(self, local: bool = True) -> dict[str, Any]:
            return {**super()._ipopt_options(local), **(local_opts if local else global_opts)}

    return Planner


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("seeds")
    ap.add_argument("target", type=float)
    ap.add_argument("settings", nargs="*", metavar="key=value")
    ap.add_argument("--ipopt-local", type=json.loads, default={}, metavar="JSON")
    ap.add_argument("--ipopt-global", type=json.loads, default={}, metavar="JSON")
    args = ap.parse_args(argv)
    target, kw = args.target, parse_config(args.settings, StlTampPlanner)
    planner = with_ipopt(args.ipopt_local, args.ipopt_global) if args.ipopt_local or args.ipopt_global else StlTampPlanner
    rows = []
    for sc in load_suite("paper-extensive").select(parse_seed_range(args.seeds)):
        if abs(sc.task.target_volume - target) > 1e-6:
            continue
        c0 = time.process_time()
        plan = planner(**kw).plan(sc)
        cpu = time.process_time() - c0
        verdict = judge(sc, plan)
        info, g = plan.info, plan.info["global"]
        row = {"id": sc.id, "valid": verdict.valid, "tpt": round(core_metrics(sc, plan, verdict)["time_per_target_m3"], 3),
               "cpu_s": round(cpu, 2), "build_s": round(info["build_time_s"], 2), "global_status": g.get("status"),
               "global_iterations": g.get("iterations", 0), "local_iterations": sum(r.get("iterations", 0) for r in info["local"]),
               "local_solves": info["local_solves"]}
        rows.append(row)
        print(json.dumps(row), flush=True)
    counts = {k: sum(r["local_solves"][k] for r in rows) for k in ("succeeded", "acceptable", "capped", "fallback", "other")}
    print(f"median time per target m³ {statistics.median(r['tpt'] for r in rows):.2f}, valid {sum(r['valid'] for r in rows)}/{len(rows)}, "
          f"CPU per plan median {statistics.median(r['cpu_s'] for r in rows):.2f} s, iterations global "
          f"{sum(r['global_iterations'] for r in rows)} local {sum(r['local_iterations'] for r in rows)}, local solves {counts} "
          f"({counts['succeeded'] / max(1, sum(counts.values())):.0%} succeeded)")


if __name__ == "__main__":
    main(sys.argv[1:])
