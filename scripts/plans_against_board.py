"""Did a rerun change a planner's plans? Compare a store's runs with a published board's `runs.csv`.

A board republished from new runs should say which planners' plans moved. The referee's figures
of a plan (makespan, loaded volume, digs, dumps, validity) identify it well enough for that: two
plans with all of them equal on a scenario are, for the board, the same plan. Runs are paired by
suite, scenario digest, planner and configuration (each side's latest version of the planner, as its board ranks it), so a board
remade after a version bump shows whether the new version's plans are the old ones.

    python scripts/plans_against_board.py --db standard.db --csv leaderboard/runs.csv --suite standard

Prints, per planner, the versions compared, the paired scenarios and how many agree; with
`--show N` the first N that differ. Exit status 0 (this reports; it does not judge).
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
import pandas as pd

from earthbench.results.aggregate import latest_versions
from earthbench.publishing.board.selection import shown_runs
from earthbench.results.labels import config_labels
from earthbench.results.store import load_runs

#: The referee's figures compared, and how close floats must be (both sides are the referee's output).
FIGURES = ["valid", "reason", "digs", "dumps", "loaded_volume", "makespan_s"]
RTOL = 1e-9


def latest(runs: pd.DataFrame) -> pd.DataFrame:
    """Each planner's runs of its latest version, chosen as a board chooses it."""
    runs = runs.assign(planner_version=runs["planner_version"].astype(str))
    return shown_runs(runs, latest_versions(runs))


def same(a: pd.Series, b: pd.Series) -> pd.Series:
    """Element-wise agreement, numeric figures to RTOL."""
    x, y = pd.to_numeric(a, errors="coerce"), pd.to_numeric(b, errors="coerce")
    numeric = x.notna() & y.notna()  # per element: a timed-out run's missing figures must not turn 17 into "17.0"
    close = pd.Series(np.isclose(x.fillna(0).to_numpy(float), y.fillna(0).to_numpy(float), rtol=RTOL, atol=1e-12), index=a.index)
    return close.where(numeric, a.astype(str).str.lower() == b.astype(str).str.lower())


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--db", required=True, help="the store of the new runs")
    p.add_argument("--csv", required=True, help="the published board's runs.csv")
    p.add_argument("--suite", required=True, help="the suite compared (public or sealed name)")
    p.add_argument("--show", type=int, default=0, help="print the first N scenarios that differ per planner")
    args = p.parse_args(argv)
    new = latest(load_runs(args.db))
    old = latest(pd.read_csv(args.csv))
    new, old = new[new["suite"] == args.suite], old[old["suite"] == args.suite]
    new, old = (r.assign(config_hash=r["config_hash"].astype(str)) for r in (new, old))
    # one pair per configuration: a board can hold two of one planner (open and closed loop)
    pairs = new.merge(old, on=["suite", "scenario_digest", "planner", "config_hash"], suffixes=("_new", "_old"))
    names = config_labels(new)
    for (planner, config), g in pairs.groupby(["planner", "config_hash"], sort=True):
        agree = pd.concat([same(g[f"{f}_new"], g[f"{f}_old"]) for f in FIGURES], axis=1).all(axis=1)
        v_new, v_old = g["planner_version_new"].iloc[0], g["planner_version_old"].iloc[0]
        name = names.get((planner, config), planner)
        print(f"{name} {v_new} against {v_old}: {int(agree.sum())}/{len(g)} scenarios with the same plan figures")
        for _, r in g[~agree].head(args.show).iterrows():
            print("   ", r["scenario_id_new"], "  ".join(f"{f} {r[f + '_old']}→{r[f + '_new']}" for f in FIGURES
                                                        if not same(pd.Series([r[f + '_new']]), pd.Series([r[f + '_old']])).all()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
