"""Areas without a truck stand, scenario by scenario: stl-tamp 0.12.1 and separate 0.5.1 pass them
over once they prove hopeless on a site (planners/stl_tamp/NOTES.md, "0.12.1").

Plans every backhoe scenario of SUITE whose family contains FAMILY (and whose seed is in SEEDS),
open loop, with the planner's default settings and, with ``--both``, with ``standless_tries=0`` (the
versions before) beside it, each judged by the referee. One JSON line per plan: the visits to areas
without a stand that dug and that dug nothing, the areas passed over (none: the plan is the version before's),
whether such areas were given up on the site (``hopeless``), CPU
(``time.process_time`` around ``plan()``), time per target m³, validity and the excavator's travel.

    python scripts/standless.py standard                            # which stl-tamp plans it touches
    python scripts/standless.py scale rbf48x24 0 --both --planner separate   # its effect, side by side
"""

from __future__ import annotations

import argparse
import json
import time
from functools import cache
from pathlib import Path

from earthbench.errors import EarthbenchError
from earthbench.referee import judge
from earthbench.results.records import PlannerRef
from earthbench.results.scoring import evaluate
from earthbench.results.suite import load_suite
from earthbench.running.harness.prepare import find
from earthbench.sensing import observe
from earthbench_planners.separate.planner import SeparatePlanner
from earthbench_planners.stl_tamp import StlTampPlanner
from earthbench_planners.stl_tamp.hierarchy import Standless

PLANNERS = {"stl-tamp": StlTampPlanner, "separate": SeparatePlanner}


@cache
def prepared() -> Path | None:
    """stl-tamp's preparation at its default settings on this machine (``earthbench prepare stl-tamp``):
    its compiled NLPs serve both sides and separate too, since ``standless_tries`` changes no NLP."""
    found = find(PlannerRef.resolve("stl-tamp"))
    return None if found is None else Path(found.path)


def one(sc, tries: int | None, name: str = "stl-tamp") -> dict:
    """Plan ``sc`` with ``standless_tries=tries`` (None: the default) and judge it."""
    cls = PLANNERS[name]
    planner = cls() if tries is None else cls(cls.Config(standless_tries=tries))
    planner.prepared = prepared()
    t0 = time.process_time()
    plan = planner.plan(observe(sc))
    cpu = time.process_time() - t0
    v = judge(sc, plan)
    m = evaluate(sc, plan, v, 0.9)
    s = plan.info["standless"]
    tries_used = planner.config.standless_tries
    return {"sc": sc.id, "planner": f"{name} {planner.version}", "tries": tries_used, **s,
            "hopeless": Standless(dug=s["dug"], fruitless=s["fruitless"]).hopeless(tries_used),
            "valid": v.valid, "cpu": round(cpu, 1), "tpm3": round(m.get("time_per_target_m3", float("nan")), 2),
            "ratio": round(m.get("volume_ratio", 0.0), 3), "exc_m": round(v.travel.get("excavator", 0.0), 1)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("suite")
    ap.add_argument("family", nargs="?", default="")
    ap.add_argument("seeds", nargs="?", default=None, help="comma-separated seeds (default: all)")
    ap.add_argument("--planner", choices=sorted(PLANNERS), default="stl-tamp")
    ap.add_argument("--both", action="store_true", help="also plan with standless_tries=0 (the versions before)")
    ap.add_argument("--tries", type=int, default=None, help="standless_tries of the new side (default: the planner's)")
    a = ap.parse_args()
    seeds = None if a.seeds is None else {int(s) for s in a.seeds.split(",")}
    n = touched = 0
    for sc in load_suite(a.suite).scenarios:
        if sc.track != "backhoe" or a.family not in sc.meta["family"] or (seeds and int(sc.meta["seed"]) not in seeds):
            continue
        for tries in ((a.tries, 0) if a.both else (a.tries,)):
            try:
                r = one(sc, tries, a.planner)
            except EarthbenchError as e:  # a planner's refusal is a row, not the end of the survey
                r = {"sc": sc.id, "tries": tries, "error": f"{type(e).__name__}: {e}"}
            print(json.dumps(r), flush=True)
            if tries == a.tries:
                n += 1
                touched += r.get("passed_over", 0) > 0
    print(f"{a.suite}, {a.planner}: {n} plans, {touched} passed over areas without a stand (the others are the plans "
          "of the version before)")


if __name__ == "__main__":
    main()
