"""Aggregates over the runs of a suite (docs/DESIGN.md §7), one row per (suite, track, planner configuration).

Input: the DataFrame of :func:`earthbench.store.load_runs` (one row per run). Definitions:

* ``runs``: stored runs of the group; ``scenarios``: distinct scenario digests among them;
  ``of``: the suite's scenario count when given (``sizes``), else ``scenarios``.
* ``success_rate``: successes (valid and volume ratio ≥ the suite's threshold) over ``of``:
  runs that failed in any way (invalid, timeout, memory, error, crashed) and scenarios the
  planner has no run for count as failures, as in the performance profiles, so a planner run
  on part of a suite is never ranked on that part alone.
* ``volume_ratio_mean`` / ``_sd``: over *valid* runs (reason ``ok``), since an invalid plan is
  reported, never ranked; the SD is the sample SD (n − 1), NaN for a single run.
* ``time_per_m3_median`` / ``_q1`` / ``_q3`` / ``_iqr`` and ``time_per_m3_ratio_median`` (to the
  scenario's lower bound): over valid runs that loaded something (a valid plan loading nothing
  has an infinite time per m³ and is counted in ``loaded_nothing``).
* ``solve_time_median`` / ``_p90`` and ``solve_cpu_median``: over every run with a measured
  solve time, failures included (a timeout's solve time is the time it was given).
* ``n_<reason>`` for each termination reason; ``cpu_models``: how many CPU models the runs
  came from (solve times from different models are not comparable).

:func:`rank` orders the rows of one (suite, track) table: success rate (higher first), then
median time per m³ (lower first; none last), then median solve time (lower first).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

REASONS = ("ok", "invalid", "timeout", "memory", "error", "crashed")
GROUP = ["suite", "track", "planner", "planner_version", "config_hash"]
RANKING_RULE = ("ranked by success rate (higher first), then median time per m³ over valid runs (lower first), "
                "then median solve time (lower first)")

SUMMARY_COLUMNS = [
    *GROUP, "runs", "of", "scenarios", "successes", "success_rate", "valid_runs", "volume_ratio_mean", "volume_ratio_sd",
    "time_per_m3_median", "time_per_m3_q1", "time_per_m3_q3", "time_per_m3_iqr", "time_per_m3_ratio_median",
    "loaded_nothing", "solve_time_median", "solve_time_p90", "solve_cpu_median",
    *(f"n_{r}" for r in REASONS), "n_other", "cpu_models",
]


def _num(s: pd.Series) -> np.ndarray:
    return pd.to_numeric(s, errors="coerce").to_numpy(dtype=float)


def _summarise(g: pd.DataFrame, of: int | None = None) -> dict[str, float]:
    reason = g["reason"].astype(str).to_numpy()
    ok = reason == "ok"
    success = g["success"].fillna(False).astype(bool).to_numpy()
    vr = _num(g["volume_ratio"])[ok] if "volume_ratio" in g else np.array([])
    vr = vr[np.isfinite(vr)]
    tpm = _num(g["time_per_m3"])[ok] if "time_per_m3" in g else np.array([])
    tpm_ratio = _num(g["time_per_m3_ratio"])[ok] if "time_per_m3_ratio" in g else np.array([])
    finite = np.isfinite(tpm)
    st = _num(g["solve_time_s"])
    st = st[np.isfinite(st)]
    cpu = _num(g["solve_cpu_s"]) if "solve_cpu_s" in g else np.array([])
    cpu = cpu[np.isfinite(cpu)]
    q1, med, q3 = (np.percentile(tpm[finite], [25, 50, 75]) if finite.any() else (np.nan,) * 3)
    counts = {f"n_{r}": int((reason == r).sum()) for r in REASONS}
    models = g["cpu_model"].dropna().nunique() if "cpu_model" in g else 0
    n_sc = int(g["scenario_digest"].nunique())
    of = max(int(of), n_sc) if of else n_sc
    return {
        "runs": len(g),
        "of": of,
        "scenarios": n_sc,
        "successes": int(success.sum()),
        "success_rate": float(success.sum() / of) if of else np.nan,
        "valid_runs": int(ok.sum()),
        "volume_ratio_mean": float(vr.mean()) if len(vr) else np.nan,
        "volume_ratio_sd": float(vr.std(ddof=1)) if len(vr) > 1 else np.nan,
        "time_per_m3_median": float(med),
        "time_per_m3_q1": float(q1),
        "time_per_m3_q3": float(q3),
        "time_per_m3_iqr": float(q3 - q1),
        "time_per_m3_ratio_median": float(np.median(tpm_ratio[finite])) if finite.any() else np.nan,
        "loaded_nothing": int((~finite & ~np.isnan(tpm)).sum()),
        "solve_time_median": float(np.median(st)) if len(st) else np.nan,
        "solve_time_p90": float(np.percentile(st, 90)) if len(st) else np.nan,
        "solve_cpu_median": float(np.median(cpu)) if len(cpu) else np.nan,
        **counts,
        "n_other": int(len(g) - sum(counts.values())),
        "cpu_models": int(models),
    }


def aggregate(runs: pd.DataFrame, sizes: dict[str, int] | None = None) -> pd.DataFrame:
    """One row per (suite, track, planner, planner_version, config_hash), columns :data:`SUMMARY_COLUMNS`,
    ranked within each (suite, track) by :func:`rank` and numbered in ``rank``.

    ``sizes``: suite name → its number of scenarios (the denominator of the success rate).
    """
    rows = []
    sizes = sizes or {}
    if len(runs):
        for key, g in runs.groupby(GROUP, sort=True, dropna=False):
            rows.append({**dict(zip(GROUP, key)), **_summarise(g, sizes.get(key[0]))})
    out = pd.DataFrame.from_records(rows, columns=SUMMARY_COLUMNS)
    return rank(out)


def rank(summary: pd.DataFrame) -> pd.DataFrame:
    """Sort by (suite, track), then the ranking rule (:data:`RANKING_RULE`); add ``rank`` from 1 per table."""
    if summary.empty:
        return summary.assign(rank=pd.Series(dtype=int))
    s = summary.assign(_neg_success=-summary["success_rate"].fillna(0.0))
    s = s.sort_values(["suite", "track", "_neg_success", "time_per_m3_median", "solve_time_median", "planner",
                       "planner_version", "config_hash"], na_position="last", kind="mergesort")
    s = s.drop(columns="_neg_success").reset_index(drop=True)
    s.insert(0, "rank", s.groupby(["suite", "track"]).cumcount() + 1)
    return s
