"""Candidate best known plans that no board run made (issue 49): plans made knowing the whole truth.

A board's runs plan from what the planner is shown — on the realistic track a scan and the
material's nominal values, so open loop every planner stops short of the target and no run of
some scenarios reaches it. A best known plan is any valid plan anyone has produced
(docs/publishing.md, "Best known plans"), so this script makes two kinds of witness:

``truth``    a registered planner plans each scenario of a suite from the scenario itself (its true
             terrain and soil, no scan), open loop.
``closed``   the same in closed loop (``run_closed_loop``): each step sees the ground exactly as the
             referee's replay has left it and the load the truck really holds — what a planner
             needs on the realistic track, where the soil's fill factor, hard layer and slump
             make any open-loop plan stop short.
``rollout``  greedy with its opening and relocations chosen by rollouts
             (``planners/greedy/rollout.py``: never later to the target than greedy), given the
             truth too.

Each plan is written as a candidate file (``DIR/<scenario digest>.json``); the project's own
command judges it again on the suite's scenario before keeping anything:

    python scripts/best_witness.py standard-realistic --out cands [--kind rollout] [--planner greedy] [--seeds 0-2]
    earthbench best update --plans cands --suite standard-realistic
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

from earthbench.referee import judge
from earthbench.registry import PLANNERS
from earthbench.results.scoring import evaluate
from earthbench.results.suite import load_suite, parse_seed_range
from earthbench.running.harness.steps import run_closed_loop
from earthbench.sensing import ANONYMOUS_ID
from earthbench.world import Scenario
from earthbench_planners.greedy import rollout


def truth(sc: Scenario) -> Scenario:
    """``sc`` as a planner sees it when it knows everything: no scan, the true soil, anonymous."""
    return dataclasses.replace(sc, id=ANONYMOUS_ID, meta={}, sensing=None)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("suite")
    ap.add_argument("--out", required=True, help="folder for the candidate files")
    ap.add_argument("--kind", choices=("truth", "closed", "rollout"), default="truth")
    ap.add_argument("--planner", default="greedy", help="the planner of --kind truth or closed")
    ap.add_argument("--config", action="append", default=[], help="KEY=VALUE for the planner of --kind truth (JSON values)")
    ap.add_argument("--seeds", default="", help="only these seeds (e.g. 0-2)")
    ap.add_argument("--family", default="", help="only scenarios of families whose name contains this")
    a = ap.parse_args()
    suite = load_suite(a.suite)
    scenarios = suite.select(parse_seed_range(a.seeds) if a.seeds else None)
    config = {k: json.loads(v) for k, v in (c.split("=", 1) for c in a.config)}
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    if a.kind == "rollout":
        producer = {"kind": "witness", "name": "scripts/best_witness.py --kind rollout (greedy)",
                    "config": {"opening_stations": rollout.OPENING_STATIONS, "opening_stands": rollout.OPENING_STANDS,
                               "relocations": rollout.RELOCATIONS}}
    else:
        producer = {"kind": "witness", "name": f"scripts/best_witness.py --kind {a.kind} --planner {a.planner}", "config": config}
    for sc in scenarios:
        if a.family not in sc.id:
            continue
        t0 = time.process_time()
        if a.kind == "rollout":
            plan, rollouts = rollout.rollout_plan(truth(sc))
        elif a.kind == "closed":
            plan, rollouts = run_closed_loop(PLANNERS.get(a.planner)(**config), truth(sc)), 0
        else:
            plan, rollouts = PLANNERS.get(a.planner)(**config).plan(truth(sc)), 0
        cpu = time.process_time() - t0
        v = judge(sc, plan)
        m = evaluate(sc, plan, v)
        (out / f"{sc.digest}.json").write_text(json.dumps({"scenario_digest": sc.digest, "producer": producer,
                                                           "plan": json.loads(plan.to_json())}))
        print(f"{sc.id}: {'valid' if v.valid else 'INVALID ' + ','.join(sorted({x.rule for x in v.violations}))}, "
              f"loaded {m['loaded_volume']:.2f} of {sc.task.target_volume:g} m³, "
              f"{m['time_per_target_m3_bound_ratio']:.3f} × the target bound; {rollouts} rollouts, {cpu:.1f} s CPU", flush=True)


if __name__ == "__main__":
    main()
