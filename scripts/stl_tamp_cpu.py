"""CPU per stl-tamp plan in one process, with the referee's time per target m³ and how the
solves ended (README's stl-tamp section, docs/DESIGN.md §11).

    python scripts/stl_tamp_cpu.py SEEDS TARGET [key=value ...]   # e.g. 0-9 7 max_iter=150

Plans ``paper-extensive``'s scenarios of TARGET m³ for SEEDS (``a-b``) one after another in this
process (the first plan also pays the solvers' construction), each timed with
``time.process_time``; one JSON line per plan, then a summary line. ``key=value`` overrides a
field of stl-tamp's ``Config``.
"""

from __future__ import annotations

import dataclasses
import json
import statistics
import sys
import time

from earthbench.referee import judge
from earthbench.suite import load_suite
from earthbench_metrics.run import core_metrics
from earthbench_planners.stl_tamp import StlTampPlanner
from earthbench_planners.stl_tamp.planner import Config


def overrides(args: list[str]) -> dict:
    fields = {f.name for f in dataclasses.fields(Config)}
    out = {}
    for kv in args:
        k, _, v = kv.partition("=")
        if k not in fields:
            raise SystemExit(f"unknown Config field {k!r}")
        t = type(getattr(Config(), k))
        out[k] = (v.lower() in ("1", "true", "yes")) if t is bool else t(v)
    return out


def main(argv: list[str]) -> None:
    a, _, b = argv[0].partition("-")
    target, kw = float(argv[1]), overrides(argv[2:])
    scs = [sc for sc in load_suite("paper-extensive").scenarios if abs(sc.task.target_volume - target) < 1e-6]
    rows = []
    for seed in range(int(a), int(b or a) + 1):
        sc = scs[seed]
        c0 = time.process_time()
        plan = StlTampPlanner(Config(**kw)).plan(sc)
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
