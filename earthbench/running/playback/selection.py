"""Which runs the page's replay viewer embeds (:func:`pick_runs`)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover
    import pandas as pd


def pick_runs(runs: pd.DataFrame, limit: int) -> pd.DataFrame:
    """Up to ``limit`` runs with a plan worth replaying: per planner in turn, a success, an invalid run, then more,
    spread over the scenario families. A run published under several suites is picked once.
    """
    have = runs[runs["reason"].isin(["ok", "invalid"])].drop_duplicates("id").sort_values("id")
    if have.empty or limit <= 0:
        return have.iloc[:0]
    if "family" in have:  # spread each planner's picks over the families: the first of each, then the second, …
        have = have.assign(_nth=have.groupby(["solver", "family"]).cumcount()).sort_values(["_nth", "family", "id"])
    queues = []
    for _, g in have.groupby("solver", sort=True):
        succ, bad = g[g["success"].astype(bool)], g[g["reason"] == "invalid"]
        rest = g.drop(index=succ.index[:1].union(bad.index[:1]))
        queues.append(list(succ.index[:1]) + list(bad.index[:1]) + list(rest.index))
    picked: list[Any] = []
    while len(picked) < limit and any(queues):
        for q in queues:
            if q and len(picked) < limit:
                picked.append(q.pop(0))
    return have.loc[picked].drop(columns=["_nth"], errors="ignore")
