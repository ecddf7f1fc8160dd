"""CPU per stl-tamp plan in one process, with the referee's time per target m³ and how the
solves ended (README's stl-tamp section, docs/DESIGN.md §11).

    python scripts/stl_tamp_cpu.py SEEDS TARGET [key=value ...]   # e.g. 0-9 7 max_iter=150

Plans ``paper-extensive``'s scenarios of TARGET m³ for SEEDS (``a-b``) one after another in this
process (the first plan also pays the solvers' construction), each timed with
``time.process_time``; one JSON line per plan, then a summary line. ``key=value`` overrides a
field of stl-tamp's ``Config``.
"""

from __future__ import annotations

import json
import statistics
import sys
import time

from earthbench.cli import parse_config
from earthbench.referee import judge
from earthbench.suite import load_suite, parse_seed_range
from earthbench_metrics.run import core_metrics
from earthbench_planners.stl_tamp import StlTampPlanner


def main(argv: list[str]) -> None:
    target, kw = float(argv[1]), parse_config(argv[2:], StlTampPlanner)
    rows = []
    for sc in load_suite("paper-extensive").select(parse_seed_range(argv[0])):
        if abs(sc.task.target_volume - target) > 1e-6:
            continue
        c0 = time.process_time()
        plan = StlTampPlanner(**kw).plan(sc)
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
