"""Fig. 7a of the STL-TAMP paper from stored runs: loaded volume against total time, per method.

Reads every run of ``stl-tamp`` and ``separate`` on the ``paper-extensive`` maps (targets 4–7 m³;
that suite's runs or those of its family in ``standard``) and on
``paper-separate-sweep`` (the paper's division sweep, ``scripts/separate_sweep.py``) from one or
more results databases, draws them with the leaderboard's own figure code
(:func:`earthbench.publishing.board.figures.volume_time_figure`) and prints the numbers behind it: per method the
runs, valid plans, mean loaded volume and makespan, median time per m³, the least-squares slope
of makespan over volume, and — on the paper-extensive scenarios both planners solved — the
median ratio of ``separate``'s time per m³ to ``stl-tamp``'s. With ``--placed``, the same ratio
for ``separate`` run with ``stl-tamp``'s truck placement (``leaderboard/fig7a/separate-placed.toml``),
kept out of the figure: it isolates what the task planning earns from where the truck stands.

    python scripts/fig7a.py --db earthbench.db --db separate-sweep.db --out fig7a.png [--placed placed.db]
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import pandas as pd

from earthbench.publishing.board.figures import volume_time_figure
from earthbench.results.aggregate import version_key
from earthbench.results.store import load_runs

SUITES = ("paper-extensive", "paper-separate-sweep")


def label(row: pd.Series) -> str:
    if row["planner"] == "separate":
        div = json.loads(row["config"] or "{}").get("divisions", 0)
        return "separate, divisions 5–12 (paper's sweep)" if div else "separate, stop at target"
    return f"{row['planner']} {row['planner_version']}, targets 4–7 m³"


def on_paper_extensive(runs: pd.DataFrame) -> pd.Series:
    """Runs on the paper-extensive maps: of that suite, or of its family inside ``standard``."""
    return (runs["suite"] == "paper-extensive") | runs["family"].fillna("").str.startswith("paper-extensive.")


def collect(dbs: list[str]) -> pd.DataFrame:
    frames = []
    for db in dbs:
        runs = load_runs(db)
        keep = runs["suite"].isin(SUITES) | on_paper_extensive(runs)
        frames.append(runs[keep & runs["planner"].isin(["stl-tamp", "separate"])])
    runs = pd.concat(frames, ignore_index=True).drop_duplicates(["scenario_digest", "planner", "planner_version", "config_hash"])
    runs = latest_version_runs(runs)
    runs["solver"] = runs.apply(label, axis=1)
    return runs


def latest_version_runs(runs: pd.DataFrame) -> pd.DataFrame:
    """Each planner's runs of its latest version over every suite given (the figure joins
    several stores and suites; :func:`earthbench.results.aggregate.latest_versions` picks per suite)."""
    latest = runs.groupby("planner")["planner_version"].agg(lambda v: max(v.unique(), key=version_key))
    return runs[runs["planner_version"] == runs["planner"].map(latest)].copy()


def table(runs: pd.DataFrame) -> pd.DataFrame:
    rows = []
    for solver, g in runs.groupby("solver"):
        ok = g[g["reason"] == "ok"]
        slope = float(np.polyfit(ok["loaded_volume"], ok["makespan_s"], 1)[0]) if len(ok) >= 2 else float("nan")
        rows.append({"method": solver, "runs": len(g), "valid": int((g["reason"] == "ok").sum()),
                     "volume mean m³": ok["loaded_volume"].mean(), "makespan mean s": ok["makespan_s"].mean(),
                     "time/m³ median s": ok["time_per_m3"].median(), "slope s per m³": slope,
                     "solve s median": g["solve_time_s"].median()})
    return pd.DataFrame(rows)


def time_per_m3(runs: pd.DataFrame, planner: str) -> pd.Series:
    """A planner's valid runs on the paper-extensive maps: time per m³ by scenario digest."""
    pe = runs[on_paper_extensive(runs) & (runs["reason"] == "ok")]
    return pe[pe["planner"] == planner].set_index("scenario_digest")["time_per_m3"]


def paired_ratio(a: pd.Series, b: pd.Series) -> tuple[int, float, int]:
    """On the scenarios both solved: their number, the median of a / b, and how often a > b."""
    both = a.index.intersection(b.index)
    ratio = a[both] / b[both]
    return len(both), float(np.median(ratio)) if len(both) else float("nan"), int((ratio > 1).sum())


def placed_runs(db: str) -> pd.DataFrame:
    """``separate``'s latest runs in ``db`` (the ``separate-placed`` suite: stl-tamp's truck placement)."""
    runs = load_runs(db)
    return latest_version_runs(runs[runs["planner"] == "separate"])


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--db", action="append", required=True, help="results database (repeatable)")
    p.add_argument("--out", default="fig7a.png", help="figure file (default: fig7a.png)")
    p.add_argument("--placed", help="database of separate run with stl-tamp's truck placement (separate-placed.toml)")
    args = p.parse_args(argv)
    runs = collect(args.db)
    fig = volume_time_figure(runs, "STL-TAMP vs Separate (paper Fig. 7a), paper-extensive maps")
    fig.savefig(args.out, dpi=130)
    with pd.option_context("display.width", 200, "display.max_columns", 20, "display.float_format", "{:.2f}".format):
        print(table(runs).to_string(index=False))
    stl = time_per_m3(runs, "stl-tamp")
    n, r, _ = paired_ratio(time_per_m3(runs, "separate"), stl)
    print(f"paired paper-extensive scenarios: {n}; median time-per-m³ ratio separate / stl-tamp: {r:.3f}")
    if args.placed:
        placed = placed_runs(args.placed)
        n, r, slower = paired_ratio(time_per_m3(placed, "separate"), stl)
        version = placed["planner_version"].iloc[0] if len(placed) else "-"
        print(f"with stl-tamp's truck placement (separate {version}, {args.placed}): paired scenarios {n}; "
              f"median ratio separate / stl-tamp {r:.3f}; separate slower on {slower}")
    print(f"figure: {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
