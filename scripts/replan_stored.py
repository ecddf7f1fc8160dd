"""Plan stored runs again with the planner as it now is, and say whether each plan is the stored one.

A planner change that should leave published plans alone (a mend that acts only in states the
committed plans never reach) is checked on the runs a bound names (``scripts/node0_bound.py``,
``scripts/standless_bound.py``): each is planned again in this process from the scenario the
store keeps (sealed draws included), with the run's stored settings, open or closed loop
(:func:`~earthbench.running.harness.steps.run_closed_loop`), and its actions compared with the
stored plan's, number for number. One JSON line per run: the scenario, whether the actions are
the same, and the referee's time per target m³ and validity of both.

    python scripts/replan_stored.py leaderboard/20t/board-20t.db --planner stl-tamp \\
        standard-20t/rbf14-local/s5/v3 standard-20t/jacksboro/s4/v6
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np

from earthbench.plan import Plan
from earthbench.referee import judge
from earthbench.registry import PLANNERS
from earthbench.results.aggregate import version_key
from earthbench.results.records import PlannerRef
from earthbench.results.scoring import evaluate
from earthbench.results.store import Store, load_runs
from earthbench.running.harness.prepare import find
from earthbench.running.harness.steps import run_closed_loop
from earthbench.sensing import observe


def same_actions(a: list[dict], b: list[dict]) -> bool:
    """The two action lists, field for field, floats to 1e-9."""
    if len(a) != len(b):
        return False
    for x, y in zip(a, b):
        if x.keys() != y.keys():
            return False
        for k in x:
            u, v = x[k], y[k]
            if isinstance(u, (list, float, int)) and not isinstance(u, bool):
                if np.shape(u) != np.shape(v) or not np.allclose(u, v, rtol=1e-9, atol=1e-9):
                    return False
            elif u != v:
                return False
    return True


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("db")
    ap.add_argument("scenarios", nargs="*", help="scenario ids (default: every run of the planner's version)")
    ap.add_argument("--planner", required=True)
    ap.add_argument("--version", help="the stored version to compare with (default: the store's latest)")
    ap.add_argument("--closed-loop", choices=("yes", "no", "both"), default="both")
    a = ap.parse_intermixed_args()
    store = Store(a.db, create=False)
    runs = load_runs(a.db)
    runs = runs[runs["planner"] == a.planner]
    version = a.version or max(runs["planner_version"].astype(str), key=version_key)
    runs = runs[runs["planner_version"].astype(str) == version]
    if a.scenarios:
        runs = runs[runs["scenario_id"].isin(a.scenarios)]
    klass = PLANNERS.get(a.planner)
    default = json.loads(json.dumps(dataclasses.asdict(klass.Config())))
    n = same = 0
    for rid, digest, sid, cfg, threshold in zip(runs["id"], runs["scenario_digest"], runs["scenario_id"], runs["config"],
                                                runs["threshold"]):
        config = json.loads(cfg)
        closed = bool(config.get("closed_loop"))
        if a.closed_loop != "both" and closed != (a.closed_loop == "yes"):
            continue
        known = {k: tuple(v) if isinstance(v, list) else v for k, v in config.items()
                 if k in default and v != default[k]}  # the run's overrides, as the harness passes them
        planner = klass(**known)
        prep = find(PlannerRef.resolve(a.planner, known)) if klass.prepares() else None
        planner.prepared = None if prep is None else prep.path
        sc = store.scenario(digest)
        t0 = time.process_time()
        plan = run_closed_loop(planner, sc) if closed else planner.plan(observe(sc))
        cpu = time.process_time() - t0
        old = Plan.from_json(store.plan_json(int(rid)))
        figures = {}
        for side, p in (("stored", old), ("now", plan)):
            v = judge(sc, p)
            m = evaluate(sc, p, v, float(threshold))
            figures[side] = {"tpm3": round(m.get("time_per_target_m3", float("nan")), 3),
                             "ratio": round(m.get("volume_ratio", 0.0), 4), "valid": v.valid}
        agree = same_actions(json.loads(plan.to_json())["actions"], json.loads(old.to_json())["actions"])
        n += 1
        same += agree
        print(json.dumps({"sc": sid, "closed_loop": closed, "same": agree, "cpu": round(cpu, 1), **figures}), flush=True)
    print(f"{a.db}: {a.planner} {version} stored, {klass.version} now: {same} of {n} plans the same")


if __name__ == "__main__":
    main()
