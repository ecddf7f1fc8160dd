"""stl-tamp's NLP solves one by one, FATROP against IPOPT, from the same starts
(planners/stl_tamp/NOTES.md, "Issue 50").

    python scripts/stl_tamp_solves.py SEEDS TARGET [--prepared DIR] [--fatrop JSON]
    python scripts/stl_tamp_solves.py 0-3 7 --prepared DIR
    python scripts/stl_tamp_solves.py 0 7 --fatrop '{"delta_w0": 1e-3}'

Plans the scenarios of TARGET m³ of ``paper-extensive`` for SEEDS with ``solver=ipopt`` and
records every NLP solve (the starts IPOPT's plans pose), then solves each again twice in this
process, by FATROP on the staged NLP (``--fatrop``: its options on top of the planner's) and by
IPOPT on the classic one, each timed with ``time.process_time``. Prints, per kind (global,
local): how many each solver solved, FATROP's cost against IPOPT's, the iterations, the CPU per
iteration and where FATROP's time went (its own statistics: the search direction, the Hessian,
the Jacobian, the constraints) and IPOPT's (CasADi's statistics of the same evaluations).
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
import time
from typing import Any

import numpy as np

from earthbench.results.suite import load_suite, parse_seed_range
from earthbench_planners.stl_tamp import StlTampPlanner, model
from earthbench_planners.stl_tamp.problem import quantize

FATROP_KEYS = ("compute_sd_time", "eval_hess_time", "eval_jac_time", "eval_cv_time")


def capture(seeds: str, target: float) -> list[dict[str, Any]]:
    """Every solve of IPOPT's plans: the NLP's shape, machines and site, its inputs."""
    calls: list[dict[str, Any]] = []
    solve = model.PhaseNLP.solve

    def recorded(self: Any, params: Any, w0: Any, box: Any, **kw: Any) -> Any:
        calls.append({"nlp": (self.shape, self.exc, self.truck, self.site_box), "params": params.copy(), "w0": w0.copy(),
                      "box": box, "kw": {k: v for k, v in kw.items() if k != "solver"}})
        return solve(self, params, w0, box, **kw)

    model.PhaseNLP.solve = recorded  # type: ignore[method-assign]
    try:
        for sc in load_suite("paper-extensive").select(parse_seed_range(seeds)):
            if abs(sc.task.target_volume - target) <= 1e-6:
                StlTampPlanner(solver="ipopt").plan(sc)
    finally:
        model.PhaseNLP.solve = solve  # type: ignore[method-assign]
    return calls


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("seeds")
    ap.add_argument("target", type=float)
    ap.add_argument("--prepared", metavar="DIR")
    ap.add_argument("--fatrop", type=json.loads, default={}, metavar="JSON")
    args = ap.parse_args(argv)
    calls = capture(args.seeds, args.target)
    model.use_prepared(args.prepared)  # after the plans, which set their own (none)
    nlps: dict[Any, Any] = {}
    agg: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    for c in calls:
        if c["nlp"] not in nlps:
            nlps[c["nlp"]] = model.PhaseNLP(*c["nlp"])
            nlps[c["nlp"]].staged()
            print(f"{c['nlp'][0].phases} phases: {nlps[c['nlp']].cache}, staged "
                  f"{'compiled' if nlps[c['nlp']]._staged._derived is None else 'not compiled'}", flush=True)
        nlp, kw = nlps[c["nlp"]], c["kw"]
        lb, ub = nlp.bounds(c["box"], kw.get("fixed_tasks"), kw.get("max_dig_phases"), kw.get("stand"))
        params, w0 = quantize(c["params"]), np.clip(quantize(c["w0"]), lb, ub)
        t0 = time.process_time()
        fat = nlp._solve_staged(params, w0, lb, ub, kw["max_iter"], kw.get("options", {}), args.fatrop)
        t_fat = time.process_time() - t0
        fst = nlp._staged.last_stats["fatrop"]
        t0 = time.process_time()
        ipo = nlp.solve(c["params"], c["w0"], c["box"], **kw)
        t_ipo = time.process_time() - t0
        ist = nlp.last_stats
        a = agg["global" if nlp.shape.steps != StlTampPlanner().config.n_steps else "local"]
        a.update({"solves": 1, "fatrop_ok": fat.success, "ipopt_ok": ipo.success, "fatrop_it": fat.iterations,
                  "ipopt_it": ipo.iterations, "fatrop_s": t_fat, "ipopt_s": t_ipo,
                  "fatrop_as_good": fat.success and fat.cost <= 1.01 * ipo.cost + 1e-6,
                  "ipopt_hess_s": ist.get("t_proc_nlp_hess_l", 0.0), "ipopt_jac_s": ist.get("t_proc_nlp_jac_g", 0.0),
                  **{k: float(fst.get(k, 0.0)) for k in FATROP_KEYS}})
    for kind, a in agg.items():
        ms = {k: round(1e3 * a[k] / max(1, a["fatrop_it"]), 2) for k in FATROP_KEYS}
        print(f"{kind}: {a['solves']} solves; succeeded FATROP {a['fatrop_ok']}, IPOPT {a['ipopt_ok']}; FATROP's cost within "
              f"1 % of IPOPT's or below {a['fatrop_as_good']}; iterations FATROP {a['fatrop_it']}, IPOPT {a['ipopt_it']}; "
              f"CPU FATROP {a['fatrop_s']:.2f} s ({1e3 * a['fatrop_s'] / max(1, a['fatrop_it']):.2f} ms an iteration: {ms}), "
              f"IPOPT {a['ipopt_s']:.2f} s ({1e3 * a['ipopt_s'] / max(1, a['ipopt_it']):.2f} ms: Hessian "
              f"{1e3 * a['ipopt_hess_s'] / max(1, a['ipopt_it']):.2f}, Jacobian {1e3 * a['ipopt_jac_s'] / max(1, a['ipopt_it']):.2f})")


if __name__ == "__main__":
    main(sys.argv[1:])
