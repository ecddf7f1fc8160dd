"""Which stored singh-cannon-backhoe plans 1.7's further station search could change, from the stores alone.

1.7 adds a station search (``Session.relocate_further``) that runs only where 1.6 gave up:
no station would do even at the last V_min, the plan's ``info["status"]`` "no feasible dig
left" (and from then on, in the same plan, before V_min is relaxed). Every action before that
point is 1.6's, so a plan with any other status is 1.6's, action for action. This reads the
plans a store keeps (``info["status"]`` and ``info["events"]``; closed-loop plans keep neither,
so they are counted apart) and lists those that gave up: only they, and the closed-loop ones,
need planning again (``scripts/replan_stored.py``).

    python scripts/scb_relocate_bound.py leaderboard/standard.db leaderboard/20t/board-20t.db
"""

from __future__ import annotations

import json
import sys

from earthbench.results.store import Store, load_runs

PLANNER = "singh-cannon-backhoe"
GAVE_UP = "no feasible dig left"


def main() -> None:
    for db in sys.argv[1:]:
        runs = load_runs(db)
        store = Store(db, create=False)
        runs = runs[runs["planner"] == PLANNER]
        if runs.empty:
            print(f"{db}: no {PLANNER} runs")
            continue
        for version, group in runs.groupby("planner_version"):
            kept, closed, candidates = 0, [], []
            for rid, sid, cfg in zip(group["id"], group["scenario_id"], group["config"]):
                text = store.plan_json(int(rid))
                info = json.loads(text).get("info", {}) if text else {}
                events = info.get("events")
                if events is None:
                    closed.append(f"{sid}{' (closed loop)' if json.loads(cfg).get('closed_loop') else ''}")
                    continue
                kept += 1
                if info.get("status") == GAVE_UP:
                    candidates.append(sid)
            loops = sum("(closed loop)" in c for c in closed)
            print(f"{db}: {PLANNER} {version}: {kept} plans with events, "
                  f"{len(candidates)} that ended {GAVE_UP!r}{': ' + ', '.join(candidates) if candidates else ''}; "
                  f"{len(closed)} without events{f' (closed loop: {loops})' if closed else ''}")


if __name__ == "__main__":
    main()
