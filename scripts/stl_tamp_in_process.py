"""stl-tamp's plans made in this process on a suite's scenarios, each judged on the truth
(planners/stl_tamp/NOTES.md, "0.12.0"): one line per plan (valid, broken rules, volume ratio, time
per target m³, time per loaded m³, solve CPU), then the count of invalid plans.

    python scripts/stl_tamp_in_process.py KEYFILE|- FAMILY SEEDS [key=value ...]
    python scripts/stl_tamp_in_process.py leaderboard/realistic/keys/standard-realistic~sealed-6e32a61e5c7f.key bench- 5
    SUITE=standard python scripts/stl_tamp_in_process.py - paper-extensive 0,1,2 side_by_swing=true

``KEYFILE`` draws the sealed suite of that key (``-``: the public one); ``FAMILY`` is a substring
of the family's name; ``SEEDS`` a comma-separated list; ``SUITE`` (environment) the suite
(default ``standard-realistic``). Each plan sees :func:`earthbench.sensing.observe` of its scenario
as under the harness. The NLPs come from stl-tamp's preparation on this machine when there is one
for this version and configuration, else from an earlier version's with the same configuration
hash whose NLPs are the same (``PREPARED_VERSION``, default 0.11.0: 0.12.0 did not change them),
else uncompiled (the same plans, more CPU). To compare with older code, put a copy of its
``planners`` folder, named ``earthbench_planners``, first on ``PYTHONPATH``.
"""

from __future__ import annotations

import glob
import json
import os
import sys
import time
from pathlib import Path

from earthbench.referee import judge
from earthbench.registry import PLANNERS
from earthbench.results.records import PlannerRef
from earthbench.results.scoring import evaluate
from earthbench.results.suite import load_suite, open_sealed
from earthbench.running.harness.prepare import find
from earthbench.seal import SealKey
from earthbench.sensing import observe


def settings(items: list[str]) -> dict[str, object]:
    """``key=value`` settings of stl-tamp's ``Config``, each value read as JSON (``true``, ``0.5``) or kept as text."""
    out: dict[str, object] = {}
    for item in items:
        key, _, raw = item.partition("=")
        try:
            out[key] = json.loads(raw)
        except json.JSONDecodeError:
            out[key] = raw
    return out


def prepared_folder(ref: PlannerRef) -> Path | None:
    """This version's preparation, or ``PREPARED_VERSION``'s of the same configuration hash."""
    found = find(ref)
    if found is not None:
        return Path(found.path)
    for manifest in glob.glob(os.path.expanduser("~/.cache/earthbench/prepared/stl-tamp-*/prepare.json")):
        doc = json.loads(Path(manifest).read_text())
        if doc.get("version") == os.environ.get("PREPARED_VERSION", "0.11.0") and doc.get("config_hash") == ref.config_hash:
            return Path(manifest).parent
    return None


def main() -> None:
    key, family, seeds = sys.argv[1:4]
    suite = load_suite(os.environ.get("SUITE", "standard-realistic"))
    if key != "-":
        suite = open_sealed(suite, SealKey.read(key))
    wanted = {int(s) for s in seeds.split(",")}
    cls = PLANNERS.get("stl-tamp")
    overrides = settings(sys.argv[4:])
    folder = prepared_folder(PlannerRef.resolve("stl-tamp", overrides))
    invalid = total = 0
    for sc in suite.scenarios:
        if family not in sc.meta["family"] or int(sc.meta["seed"]) not in wanted:
            continue
        planner = cls(**overrides)
        planner.prepared = folder
        t0 = time.process_time()
        plan = planner.plan(observe(sc))
        cpu = time.process_time() - t0
        verdict = judge(sc, plan)
        m = evaluate(sc, plan, verdict, 0.9)
        rules = ",".join(sorted({v.rule for v in verdict.violations}))
        total, invalid = total + 1, invalid + (not verdict.valid)
        print(f"{sc.meta['family']:45s} s{sc.meta['seed']} v{sc.meta['target']:g} valid={verdict.valid} {rules} "
              f"ratio={m.get('volume_ratio', 0.0):.3f} t/m3={m.get('time_per_target_m3', float('nan')):.2f} "
              f"t/m3load={m.get('time_per_m3', float('nan')):.2f} cpu={cpu:.1f} prepared={folder is not None}", flush=True)
    print("invalid", invalid, "of", total)


if __name__ == "__main__":
    main()
