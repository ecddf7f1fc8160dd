"""CPU per stl-tamp plan in one process, with the referee's time per target m³ and how the
solves ended (planners/stl_tamp/NOTES.md).

    python scripts/stl_tamp_cpu.py SEEDS TARGET [key=value ...]   # e.g. 0-9 7 max_iter=150
    python scripts/stl_tamp_cpu.py 0-9 7 --ipopt-local '{"perturb_dec_fact": 0.6}' --ipopt-global '{"mu_init": 0.1}'
    python scripts/stl_tamp_cpu.py 0-9 7 --fresh --side-by-side DIR   # uncompiled vs prepared in DIR
    python scripts/stl_tamp_cpu.py 0-2 256 --suite scale --fresh --side-by-side DIR
    python scripts/stl_tamp_cpu.py 0-9 7 --prepared DIR --fresh --start neighbour

Plans the scenarios of TARGET m³ of ``paper-extensive`` (or ``--suite``) for SEEDS (``a-b``) one
after another in this process (the first plan also pays the solvers' construction), each timed
with ``time.process_time``; one JSON line per plan, then a summary line. ``key=value`` overrides a
field of stl-tamp's ``Config``; ``--ipopt-local`` and ``--ipopt-global`` (JSON objects) add IPOPT
options to the local or the global solves, for experiments that are no setting of the planner.
``--prepared DIR`` plans with the NLPs compiled in DIR (``earthbench prepare stl-tamp`` prints
the folder); ``--fresh`` forgets the process's NLPs before each plan, so every plan pays what a
case's fresh process pays (the NLPs' load); ``--side-by-side DIR`` plans each scenario twice in
turn, without and with DIR (alternating which goes first), and reports both CPU times and
whether the two plans' actions are the same (their digests). The uncompiled side is the current
code without its preparation, not 0.9.0's own: ``scripts/versions_side_by_side.py`` compares
two installs. ``--start neighbour`` starts each local solve after the first from the previous
area's solution moved rigidly onto the new area (an experiment, planners/stl_tamp/NOTES.md).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import statistics
import sys
import time
from typing import Any

import numpy as np

from earthbench.cli import parse_config
from earthbench.referee import judge
from earthbench.suite import load_suite, parse_seed_range
from earthbench_metrics.run import core_metrics
from earthbench_planners.stl_tamp import StlTampPlanner, hierarchy


def with_ipopt(local_opts: dict[str, Any], global_opts: dict[str, Any]) -> type[StlTampPlanner]:
    """stl-tamp with extra IPOPT options for its local and its global solves."""

    class Planner(StlTampPlanner):
        def _ipopt_options(self, local: bool = True) -> dict[str, Any]:
            return {**super()._ipopt_options(local), **(local_opts if local else global_opts)}

    return Planner


def moved_start(nlp: Any, params: np.ndarray, s0: np.ndarray, guess: np.ndarray, prev_area: Any, prev: Any,
                area: Any) -> np.ndarray:
    """A local start whose dig phases are ``prev``'s, turned by the change of drag heading and
    moved from ``prev_area``'s stand to ``area``'s; phase 0 (the relocation) and the parked
    truck are the IK guess's, each phase's model volume its ``V``."""
    X, U, ph, slack = nlp.unpack(guess, s0)
    d = area.psi - prev_area.psi
    c, s = math.cos(d), math.sin(d)

    def move(x: float, y: float) -> tuple[float, float]:
        x, y = x - prev_area.base[0], y - prev_area.base[1]
        return c * x - s * y + area.base[0], s * x + c * y + area.base[1]

    n = nlp.n
    for k in range(n + 1, nlp.N + 1):
        X[k, 3:6] = prev.X[k, 3:6]
        X[k, 0], X[k, 1] = move(prev.X[k, 0], prev.X[k, 1])
        X[k, 2] = prev.X[k, 2] + d
        X[k, 6:9] = X[n, 6:9]
    U[n:] = prev.U[n:]
    U[n:, 5:7] = 0.0  # the truck stays parked after phase 0
    for i in range(1, nlp.m1):
        ph["px"][i], ph["py"][i] = move(prev.px[i], prev.py[i])
        ph["psi"][i] = prev.psi[i] + d
        ph["eta"][i], ph["dtm"][i], ph["dtw"][i] = prev.eta[i], prev.dtm[i], prev.dtw[i]
    ph["V"][1:] = np.clip(nlp.evaluate(nlp.pack_w(X, U, ph, slack), params)["volumes"], 0.0, nlp.shape.vmax)
    return nlp.pack_w(X, U, ph, slack)


def with_neighbour_start(base: type[StlTampPlanner]) -> type[StlTampPlanner]:
    """``base`` whose local solves after the first start from the previous area's solution."""

    class Planner(base):  # type: ignore[misc,valid-type]
        last: tuple[Any, Any] | None = None

        def _solve_local(self, lp: Any, exc: Any, area: Any, truck: Any, box: Any, w0: np.ndarray) -> Any:
            if self.last is not None and self.last[1].X.shape[0] == lp.nlp.N + 1:
                w0 = moved_start(lp.nlp, lp.params, lp.s0, w0, *self.last, area)
            out = super()._solve_local(lp, exc, area, truck, box, w0)
            if out[0].success:
                self.last = (area, out[0])
            return out

    return Planner


def digest(plan: Any) -> str:
    """The plan's actions' digest (tests/test_plan_digests.py's)."""
    return hashlib.sha256(json.dumps(plan.to_dict()["actions"], sort_keys=True).encode()).hexdigest()[:16]


def plan_once(planner: Any, sc: Any, prepared: str | None, fresh: bool) -> tuple[Any, float]:
    if fresh:
        hierarchy._NLP_CACHE.clear()
    p = planner
    p.prepared = prepared
    c0 = time.process_time()
    plan = p.plan(sc)
    return plan, time.process_time() - c0


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("seeds")
    ap.add_argument("target", type=float)
    ap.add_argument("settings", nargs="*", metavar="key=value")
    ap.add_argument("--ipopt-local", type=json.loads, default={}, metavar="JSON")
    ap.add_argument("--ipopt-global", type=json.loads, default={}, metavar="JSON")
    ap.add_argument("--prepared", metavar="DIR")
    ap.add_argument("--suite", default="paper-extensive")
    ap.add_argument("--fresh", action="store_true")
    ap.add_argument("--side-by-side", metavar="DIR")
    ap.add_argument("--start", choices=("guess", "neighbour"), default="guess")
    args = ap.parse_args(argv)
    target, kw = args.target, parse_config(args.settings, StlTampPlanner)
    planner = with_ipopt(args.ipopt_local, args.ipopt_global) if args.ipopt_local or args.ipopt_global else StlTampPlanner
    if args.start == "neighbour":
        planner = with_neighbour_start(planner)
    rows = []
    for n, sc in enumerate(s for s in load_suite(args.suite).select(parse_seed_range(args.seeds))
                           if abs(s.task.target_volume - target) <= 1e-6):
        if args.side_by_side:
            runs = {}
            for which in (("old", "new") if n % 2 == 0 else ("new", "old")):
                runs[which] = plan_once(planner(**kw), sc, args.side_by_side if which == "new" else None, args.fresh)
            (plan, cpu), (old_plan, old_cpu) = runs["new"], runs["old"]
        else:
            plan, cpu = plan_once(planner(**kw), sc, args.prepared, args.fresh)
        verdict = judge(sc, plan)
        info, g = plan.info, plan.info["global"]
        row = {"id": sc.id, "valid": verdict.valid, "tpt": round(core_metrics(sc, plan, verdict)["time_per_target_m3"], 3),
               "cpu_s": round(cpu, 2), "build_s": round(info["build_time_s"], 2), "global_status": g.get("status"),
               "global_iterations": g.get("iterations", 0), "local_iterations": sum(r.get("iterations", 0) for r in info["local"]),
               "local_solves": info["local_solves"], "nlps": info["nlp_cache"], "solvers": info.get("solvers")}
        if args.side_by_side:
            row.update(old_cpu_s=round(old_cpu, 2), same_plan=digest(plan) == digest(old_plan), digest=digest(plan))
        rows.append(row)
        print(json.dumps(row), flush=True)
    counts = {k: sum(r["local_solves"][k] for r in rows) for k in ("succeeded", "acceptable", "capped", "fallback", "other")}
    print(f"median time per target m³ {statistics.median(r['tpt'] for r in rows):.2f}, valid {sum(r['valid'] for r in rows)}/{len(rows)}, "
          f"CPU per plan median {statistics.median(r['cpu_s'] for r in rows):.2f} s, iterations global "
          f"{sum(r['global_iterations'] for r in rows)} local {sum(r['local_iterations'] for r in rows)}, local solves {counts} "
          f"({counts['succeeded'] / max(1, sum(counts.values())):.0%} succeeded)")
    if args.side_by_side:
        old = statistics.median(r["old_cpu_s"] for r in rows)
        paired = statistics.median(r["cpu_s"] / r["old_cpu_s"] for r in rows)
        print(f"side by side: CPU per plan median {old:.2f} s uncompiled, {statistics.median(r['cpu_s'] for r in rows):.2f} s "
              f"prepared (paired ratio, median {paired:.3f}); same plan {sum(r['same_plan'] for r in rows)}/{len(rows)}")


if __name__ == "__main__":
    main(sys.argv[1:])
