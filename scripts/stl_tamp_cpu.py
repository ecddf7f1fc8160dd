"""CPU per stl-tamp plan in one process, with the referee's time per target m³ and how the
solves ended (planners/stl_tamp/NOTES.md).

    python scripts/stl_tamp_cpu.py SEEDS TARGET [key=value ...]   # e.g. 0-9 7 max_iter=150
    python scripts/stl_tamp_cpu.py 0-9 7 --ipopt-local '{"perturb_dec_fact": 0.6}' --ipopt-global '{"mu_init": 0.1}'
    python scripts/stl_tamp_cpu.py 0-9 7 --fresh --side-by-side DIR   # uncompiled vs prepared in DIR
    python scripts/stl_tamp_cpu.py 0-2 256 --suite scale --fresh --side-by-side DIR
    python scripts/stl_tamp_cpu.py 0-9 7 --prepared DIR --fresh --start neighbour
    python scripts/stl_tamp_cpu.py 0-9 7 --prepared DIR --fresh --solvers --verify  # FATROP vs IPOPT

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
``--solvers`` plans each scenario twice in turn, ``solver=fatrop`` and ``solver=ipopt``
(alternating which goes first, both with ``--prepared``), and reports both CPU times, both time
per target m³ and FATROP's fallbacks; ``--verify`` solves IPOPT again from every solution FATROP
returns (not timed: its CPU is taken out of the plan's) and counts those IPOPT moves (cost by more
than 1 % or more than 40 iterations): the check that FATROP's answers are the NLP's;
``--global-ipopt`` leaves the global solves of FATROP's side to IPOPT.
"""

from __future__ import annotations

import argparse
import dataclasses
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
from earthbench.results.suite import load_suite, parse_seed_range
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


VERIFY: dict[str, Any] = {"on": False, "cpu": 0.0, "checked": 0, "moved": []}


def verify_fatrop() -> None:
    """After every FATROP success, IPOPT from its solution (untimed: see ``VERIFY["cpu"]``)."""
    from earthbench_planners.stl_tamp import model

    solve_staged = model.PhaseNLP._solve_staged

    def checked(self: Any, params: Any, w0: Any, lb: Any, ub: Any, max_iter: int, options: Any, fatrop_options: Any) -> Any:
        sol = solve_staged(self, params, w0, lb, ub, max_iter, options, fatrop_options)
        if sol.success and VERIFY["on"]:
            c0 = time.process_time()
            counts = dict(self._counts)
            res = self.solver(max_iter, options)(x0=sol.info["w"], p=params, lbx=lb, ubx=ub, lbg=self.lbg, ubg=self.ubg)
            it, f = self.solver(max_iter, options).stats()["iter_count"], float(res["f"])
            self._counts = counts
            VERIFY["checked"] += 1
            if abs(f - sol.cost) > 0.01 * abs(sol.cost) or it > 40:
                VERIFY["moved"].append((round(sol.cost, 3), round(f, 3), it))
            VERIFY["cpu"] += time.process_time() - c0
        return sol

    model.PhaseNLP._solve_staged = checked  # type: ignore[method-assign]


SPLIT: dict[str, dict[str, float]] = {"fatrop": {}, "ipopt": {}}
FATROP_KEYS = ("time_total", "compute_sd_time", "eval_hess_time", "eval_jac_time", "eval_cv_time", "eval_grad_time",
               "eval_obj_time", "iterations_count")
IPOPT_KEYS = ("t_proc_total", "t_proc_nlp_hess_l", "t_proc_nlp_jac_g", "t_proc_nlp_grad_f", "t_proc_nlp_f", "t_proc_nlp_g",
              "iter_count")


def time_split() -> None:
    """Sum, per solver, where its solves' time went (its own statistics)."""
    from earthbench_planners.stl_tamp import model

    VERIFY["on"] = VERIFY["on"] or False
    solve = model.PhaseNLP.solve

    def counted(self: Any, *a: Any, **kw: Any) -> Any:
        sol = solve(self, *a, **kw)
        if sol.info.get("solver") == "fatrop" or "fallback" in sol.info:
            st = self._staged.last_stats.get("fatrop", {})
            for k in FATROP_KEYS:
                SPLIT["fatrop"][k] = SPLIT["fatrop"].get(k, 0.0) + float(st.get(k, 0.0))
        if sol.info.get("solver") == "ipopt":  # the IPOPT side's, or the FATROP side's fallbacks
            st, side = self.last_stats, SPLIT.setdefault("fallback ipopt" if VERIFY["on"] else "ipopt", {})
            for k in IPOPT_KEYS:
                side[k] = side.get(k, 0.0) + float(st.get(k, 0.0))
        return sol

    model.PhaseNLP.solve = counted  # type: ignore[method-assign]


def plan_once(planner: Any, sc: Any, prepared: str | None, fresh: bool) -> tuple[Any, float]:
    if fresh:
        hierarchy._NLP_CACHE.clear()
    p = planner
    p.prepared = prepared
    VERIFY["cpu"] = 0.0
    c0 = time.process_time()
    plan = p.plan(sc)
    return plan, time.process_time() - c0 - VERIFY["cpu"]


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
    ap.add_argument("--solvers", action="store_true")
    ap.add_argument("--verify", action="store_true")
    ap.add_argument("--global-ipopt", action="store_true", help="with --solvers: FATROP's side solves its global NLPs by IPOPT")
    args = ap.parse_args(argv)
    if args.solvers:
        return solvers_side_by_side(args)
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


class GlobalByIpopt(StlTampPlanner):
    """stl-tamp whose global solves are IPOPT's whatever its ``solver`` (an experiment)."""

    def _global(self, *a: Any, **kw: Any) -> Any:
        config = self.config
        self.config = dataclasses.replace(config, solver="ipopt")
        try:
            return super()._global(*a, **kw)
        finally:
            self.config = config


def solvers_side_by_side(args: argparse.Namespace) -> None:
    """FATROP against IPOPT, each scenario planned by both in turn in this process."""
    if args.verify:
        verify_fatrop()
    time_split()
    kw = parse_config(args.settings, StlTampPlanner)
    rows = []
    scenarios = [s for s in load_suite(args.suite).select(parse_seed_range(args.seeds))
                 if abs(s.task.target_volume - args.target) <= 1e-6]
    for n, sc in enumerate(scenarios):
        out: dict[str, Any] = {"id": sc.id}
        for which in (("fatrop", "ipopt") if n % 2 == 0 else ("ipopt", "fatrop")):
            VERIFY["on"] = which == "fatrop"
            cls = GlobalByIpopt if which == "fatrop" and args.global_ipopt else StlTampPlanner
            plan, cpu = plan_once(cls(**{**kw, "solver": which}), sc, args.prepared, args.fresh)
            verdict = judge(sc, plan)
            out[which] = {"cpu_s": round(cpu, 3), "valid": verdict.valid, "succeeded": verdict.valid and verdict.loaded_volume
                          >= sc.task.target_volume * 0.98, "tpt": round(core_metrics(sc, plan, verdict)["time_per_target_m3"], 3),
                          "solvers": plan.info["solvers"], "nlps": plan.info["nlp_cache"],
                          "staged_compiled": sorted(n._staged._derived is None for n in hierarchy._NLP_CACHE.values()
                                                    if n._staged is not None),
                          "global_iterations": plan.info["global"].get("iterations", 0),
                          "local_iterations": sum(r.get("iterations", 0) for r in plan.info["local"])}
        rows.append(out)
        print(json.dumps(out), flush=True)
    for which in ("fatrop", "ipopt"):
        cpu = sorted(r[which]["cpu_s"] for r in rows)
        p90 = cpu[min(len(cpu) - 1, math.ceil(0.9 * len(cpu)) - 1)]
        print(f"{which}: CPU per plan median {statistics.median(cpu):.2f} s, p90 {p90:.2f} s; time per target m³ median "
              f"{statistics.median(r[which]['tpt'] for r in rows):.2f}; valid {sum(r[which]['valid'] for r in rows)}/{len(rows)}, "
              f"at the target {sum(r[which]['succeeded'] for r in rows)}/{len(rows)}")
    fat = [r["fatrop"]["solvers"] for r in rows]
    solves, falls = sum(f["fatrop"] for f in fat), sum(f["fallback"] for f in fat)
    print(f"paired CPU ratio fatrop/ipopt median {statistics.median(r['fatrop']['cpu_s'] / r['ipopt']['cpu_s'] for r in rows):.3f}; "
          f"paired time-per-m³ ratio median {statistics.median(r['fatrop']['tpt'] / r['ipopt']['tpt'] for r in rows):.3f}; "
          f"FATROP solves {solves}, fallbacks to IPOPT {falls} ({falls / max(1, solves):.1%})")
    print("where the solves' time went (s, and iterations), summed over the plans:",
          json.dumps({k: {kk: round(vv, 3) for kk, vv in v.items()} for k, v in SPLIT.items()}))
    if args.verify:
        print(f"verified: {VERIFY['checked']} FATROP solutions solved again by IPOPT, {len(VERIFY['moved'])} moved "
              f"(cost FATROP → IPOPT, iterations): {VERIFY['moved'][:20]}")


if __name__ == "__main__":
    main(sys.argv[1:])
