"""Which stored stl-tamp and separate plans ``standless_tries`` could change, from the stores alone.

An area is passed over only once visits to areas without a truck stand have dug nothing
``standless_tries`` times or more (planners/stl_tamp/NOTES.md, "0.12.1"), so a plan with fewer
fruitless visits of any kind (local records without ``skipped`` that loaded nothing) than that is
the version before's, action for action. This reads the plans a store keeps (``info["local"]``;
closed-loop plans keep none) and lists those with as many: only they need planning again
(``scripts/standless.py``).

    python scripts/standless_bound.py leaderboard/20t/board-20t.db leaderboard/standard.db
"""

from __future__ import annotations

import json
import sys

from earthbench.results.store import Store, load_runs
from earthbench_planners.stl_tamp.planner import Config

TRIES = Config().standless_tries


def fruitless_visits(local: list[dict]) -> int:
    return sum(1 for r in local if "skipped" not in r and r.get("loaded", 0.0) <= 0)


def main() -> None:
    for db in sys.argv[1:]:
        runs = load_runs(db)
        store = Store(db, create=False)
        runs = runs[runs["planner"].isin(["stl-tamp", "separate"])]
        for (planner, version), group in runs.groupby(["planner", "planner_version"]):
            kept, candidates = 0, []
            for rid, sid in zip(group["id"], group["scenario_id"]):
                text = store.plan_json(int(rid))
                local = json.loads(text).get("info", {}).get("local") if text else None
                if local is None:
                    continue
                kept += 1
                if (n := fruitless_visits(local)) >= TRIES:
                    candidates.append(f"{sid} ({n})")
            print(f"{db}: {planner} {version}: {kept} plans with local records, {len(candidates)} with {TRIES} or more "
                  f"fruitless visits{': ' + ', '.join(candidates) if candidates else ''}")


if __name__ == "__main__":
    main()
