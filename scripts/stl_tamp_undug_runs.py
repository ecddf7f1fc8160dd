"""The longest run of areas stl-tamp left undug in a row for failed local solves, in every stl-tamp
plan stored in the given results databases (planners/stl_tamp/NOTES.md, "0.12.1": ``give_up_after``
changes a plan only where an area digs after that many in a row).

    python scripts/stl_tamp_undug_runs.py leaderboard/standard.db leaderboard/realistic/standard-realistic.db leaderboard/20t/board-20t.db
"""

from __future__ import annotations

import json
import sys

from earthbench.results.store import Store, load_runs
from earthbench_planners.stl_tamp.planner import Config

GIVE_UP_AFTER = Config().give_up_after


def undug_runs(local: list[dict], after: int = GIVE_UP_AFTER) -> tuple[int, bool]:
    """The longest run of areas left undug at the fallback limit, and whether an area dug after a run of ``after`` or more."""
    longest = run = 0
    dug_after = False
    for r in local:
        if str(r.get("skipped", "")).startswith("fallback limit"):
            run += 1
            longest = max(longest, run)
        else:
            dug_after |= run >= after and r.get("loaded", 0.0) > 0
            run = 0
    return longest, dug_after


def main() -> None:
    for db in sys.argv[1:]:
        runs = load_runs(db)
        store = Store(db, create=False)
        rows = []
        for rid, sid in zip(runs["id"][runs["planner"] == "stl-tamp"], runs["scenario_id"][runs["planner"] == "stl-tamp"]):
            text = store.plan_json(int(rid))
            local = json.loads(text).get("info", {}).get("local") if text else None
            if local is not None:  # a closed-loop run's plan keeps no local records
                rows.append((undug_runs(local), sid))
        (longest, _), sid = max(rows, default=((0, False), None), key=lambda r: r[0][0])
        moved = [s for (_, dug_after), s in rows if dug_after]
        print(f"{db}: {len(rows)} plans; longest run of areas left undug: {longest} ({sid}); "
              f"plans where an area dug after {GIVE_UP_AFTER} or more in a row (they would change): {len(moved)} {moved[:5]}")


if __name__ == "__main__":
    main()
