"""Dolan–Moré performance profiles (Dolan & Moré, Math. Programming 91, 2002).

For problems ``p`` (scenarios) and solvers ``s`` (planner configurations) with cost
``t[p, s] > 0`` (time per target m³, or solve time), the performance ratio is

    r[p, s] = t[p, s] / min_s' t[p, s']

and the profile of solver ``s`` is the fraction of problems it solves within a factor ``τ``
of the best solver on that problem:

    ρ_s(τ) = |{p : r[p, s] ≤ τ}| / n_problems.

A failure — a run that is not a success, or no run at all — counts as never solved: its cost
is ``inf``, so its ratio is ``inf`` and it is counted for no ``τ``. A problem that no solver
solved still counts in ``n_problems`` (every profile stays below 1 there), so profiles of
different suites are comparable only as fractions of that suite. ``ρ_s(1)`` is the share of
problems on which ``s`` was (one of) the best; ``lim ρ_s(τ)`` as ``τ → ∞`` is its success rate.

Costs of zero are raised to :data:`MIN_COST` so ratios stay finite.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import pandas as pd

#: Smallest cost used in a ratio (a solve time rounded to 0 s would otherwise divide by zero).
MIN_COST = 1e-9


def cost_matrix(runs: pd.DataFrame, cost: str, solver: str = "solver", problem: str = "scenario_digest",
                solved: str = "success") -> pd.DataFrame:
    """Problems × solvers table of ``cost``, ``inf`` where the run failed or is missing.

    ``runs`` has one row per run with columns ``problem``, ``solver``, ``cost`` and ``solved``
    (bool). A non-finite or missing cost of a solved run also counts as a failure.
    """
    df = runs[[problem, solver, cost, solved]].copy()
    c = pd.to_numeric(df[cost], errors="coerce").astype(float)
    ok = df[solved].fillna(False).astype(bool) & np.isfinite(c)
    df["_cost"] = np.where(ok, np.maximum(c.fillna(0.0), MIN_COST), np.inf)
    # a duplicate (problem, solver) keeps its best run
    table = df.pivot_table(index=problem, columns=solver, values="_cost", aggfunc="min", dropna=False)
    return table.astype(float).fillna(np.inf)


def performance_ratios(costs: pd.DataFrame) -> pd.DataFrame:
    """``r[p, s] = t[p, s] / min_s t[p, s]``; ``inf`` for failures and for unsolved problems."""
    t = costs.to_numpy(dtype=float)
    best = t.min(axis=1, keepdims=True) if t.size else np.zeros((t.shape[0], 1))
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(np.isfinite(t) & np.isfinite(best), t / best, np.inf)
    return pd.DataFrame(r, index=costs.index, columns=costs.columns)


def profile(costs: pd.DataFrame, taus: Iterable[float] | None = None) -> pd.DataFrame:
    """``ρ_s(τ)`` for every solver (columns) at every ``τ`` (index).

    Without ``taus``: every distinct finite ratio (and 1), so the step function is exact
    between them.
    """
    r = performance_ratios(costs)
    vals = r.to_numpy()
    n = vals.shape[0]
    if taus is None:
        finite = vals[np.isfinite(vals)]
        taus = np.unique(np.concatenate([[1.0], finite]))
    tau = np.asarray(list(taus), dtype=float)
    if n == 0:
        rho = np.zeros((len(tau), vals.shape[1]))
    else:
        # for each solver: sorted ratios, then count ≤ τ by binary search
        rho = np.empty((len(tau), vals.shape[1]))
        for j in range(vals.shape[1]):
            col = np.sort(vals[:, j])
            rho[:, j] = np.searchsorted(col, tau, side="right") / n
    return pd.DataFrame(rho, index=pd.Index(tau, name="tau"), columns=costs.columns)
