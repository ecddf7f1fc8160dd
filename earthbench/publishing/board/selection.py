"""Which runs a board shows (docs/DESIGN.md §9): every stored run of each suite's scenarios, labelled by
configuration; the seeds a board is limited to; each planner's latest version; the run each terrain
figure draws; the planners whose versions get a history figure."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from ...results.store import Store, check_one_rules, load_runs


def published_runs(db: str | Path | Store, suites: Sequence[str] | None = None) -> pd.DataFrame:
    """The runs of each suite (all suites that ran when ``suites`` is empty), with a ``solver`` label.

    Each suite's frame comes from ``load_runs(db, suite)``, so a suite counts every stored run
    of its scenarios, whichever suite ran them. Runs judged under different versions of the
    referee's rules are refused (:func:`earthbench.results.store.check_one_rules`).
    """
    store = db if isinstance(db, Store) else Store(db, create=False)
    try:
        if not suites:
            suites = store.run_suites()
        frames = [load_runs(store, suite=s) for s in suites]
    finally:
        if not isinstance(db, Store):
            store.close()
    frames = [f for f in frames if len(f)]
    if not frames:
        return load_runs_empty()
    runs = pd.concat(frames, ignore_index=True)
    check_one_rules(runs, db)
    runs["solver"] = solver_labels(runs)
    return runs


def load_runs_empty() -> pd.DataFrame:
    return pd.DataFrame(columns=["id", "suite", "suite_digest", "scenario_id", "scenario_digest", "track", "planner",
                                 "planner_version", "config_hash", "reason", "success", "solver"])


def solver_labels(runs: pd.DataFrame) -> pd.Series:
    """``planner version``, `` closed-loop`` for a closed-loop configuration (docs/DESIGN.md §6),
    plus ``[config hash]`` where one label still covers several configs."""
    closed = runs["config"].map(closed_loop) if "config" in runs else pd.Series(False, index=runs.index)
    base = runs["planner"].astype(str) + " " + runs["planner_version"].astype(str) + closed.map({True: " closed-loop", False: ""})
    n_cfg = runs.groupby(base)["config_hash"].transform("nunique")
    return base.where(n_cfg <= 1, base + " [" + runs["config_hash"].astype(str).str[:8] + "]")


def closed_loop(config: Any) -> bool:
    """Whether a stored configuration (JSON text) runs closed-loop; malformed text counts as open-loop."""
    try:
        return bool(json.loads(config).get("closed_loop")) if isinstance(config, str) else False
    except (ValueError, AttributeError):
        return False


def seed_list(seeds: Sequence[int]) -> str:
    """``0–2, 5`` for seeds 0, 1, 2, 5: runs of consecutive seeds as ranges."""
    out: list[str] = []
    for s in sorted(set(seeds)):
        if out and out[-1].rsplit("–", 1)[-1] == str(s - 1):
            out[-1] = f"{out[-1].split('–')[0]}–{s}"
        else:
            out.append(str(s))
    return ", ".join(out)


def limit_to_seeds(runs: pd.DataFrame, members: pd.DataFrame,
                   seeds: Sequence[int] | None) -> tuple[pd.DataFrame, pd.DataFrame, str]:
    """The runs and suite members of ``seeds`` only (all when None), and the note every stamp then carries."""
    if seeds is None:
        return runs, members, ""
    return (runs[runs["seed"].isin(seeds)].reset_index(drop=True), members[members["seed"].isin(seeds)].reset_index(drop=True),
            f"{'seed' if len(set(seeds)) == 1 else 'seeds'} {seed_list(seeds)}")


def shown_runs(runs: pd.DataFrame, latest: set[tuple[str, str, str, str]], all_versions: bool = False) -> pd.DataFrame:
    """The runs a table's figures draw: each planner's latest version (``latest`` from
    :func:`earthbench.results.aggregate.latest_versions`), every version with ``all_versions``."""
    if all_versions:
        return runs
    keep = [(s, t, p, str(v)) in latest for s, t, p, v in zip(runs["suite"], runs["track"], runs["planner"], runs["planner_version"])]
    return runs[keep]


def closed_configs(runs: pd.DataFrame) -> frozenset[str]:
    """The hashes of the closed-loop configurations among ``runs`` (docs/DESIGN.md §6)."""
    if "config" not in runs:
        return frozenset()
    return frozenset(runs.loc[runs["config"].map(closed_loop).astype(bool), "config_hash"].astype(str))


def sample_runs(runs: pd.DataFrame) -> pd.DataFrame:
    """One run with a plan per solver: on the scenario most solvers have a plan for."""
    have = runs[runs["reason"].isin(["ok", "invalid"])]
    if have.empty:
        return have
    counts = have.groupby("scenario_digest")["solver"].nunique()
    first_id = have.groupby("scenario_digest")["scenario_id"].min()
    order = sorted(counts.index, key=lambda d: (-counts[d], first_id[d]))
    best = order[0]
    picks = []
    for _, g in have.groupby("solver"):
        on = g[g["scenario_digest"] == best]
        if len(on):
            picks.append(on.iloc[0])
        else:  # this solver has no plan there: its first scenario in the preferred order
            rank = {d: i for i, d in enumerate(order)}
            picks.append(g.loc[g["scenario_digest"].map(rank).idxmin()])
    return pd.DataFrame(picks)


def histories(summary: pd.DataFrame) -> list[tuple[str, pd.DataFrame]]:
    """(planner, its suite-scope rows) for every planner of a table with more than one version."""
    rows = summary[summary["scope"] == "suite"]
    return [(str(p), g) for p, g in rows.groupby("planner", sort=True) if g["planner_version"].nunique() > 1]


__all__ = ["closed_configs", "closed_loop", "histories", "limit_to_seeds", "load_runs_empty", "published_runs", "sample_runs",
           "seed_list", "shown_runs", "solver_labels"]
