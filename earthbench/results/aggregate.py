"""Aggregates over the runs of a suite: every number of every table, defined once.

Input: the DataFrame of :func:`earthbench.results.store.load_runs` (one row per run). One row per
(suite, track, scope, group, planner, version, config): ``scope`` is ``suite`` (the whole suite,
``group`` empty), ``family`` (``group`` = the family) or ``target`` (``group`` = the target
volume, e.g. ``4 m³``). Definitions, used by ``earthbench run``'s summary, the leaderboard and
its CSVs alike:

* ``runs``: stored runs of the group; ``scenarios``: distinct scenario digests among them;
  ``of``: the group's scenario count in the suite (``members``, else ``sizes`` for a whole
  suite), never fewer than ``scenarios``.
* ``success_rate`` (with its exact 95 % interval ``_lo``/``_hi``, :func:`earthbench.stats.rate_ci`):
  successes (:func:`earthbench.results.scoring.is_success`) over ``of``: runs that failed in any way and
  scenarios the planner has no run for count as failures, so a planner run on part of a
  suite is never ranked on that part alone.
* over *valid* runs (reason ``ok``; an invalid plan is reported, never ranked):
  ``volume_ratio_mean`` / ``_sd`` (sample SD, NaN for one run), ``overshoot_m3_mean``, the
  medians with distribution-free intervals (:func:`earthbench.stats.median_ci`; none below 6
  runs) of ``time_per_target_m3`` (the primary time metric, :func:`earthbench.results.scoring.time_per_target`:
  infinite for a run short of the target, counted in ``short_of_target``; with ``_q1`` / ``_q3``)
  and ``time_per_target_m3_ratio`` (to the scenario's lower bound per m³) and
  ``time_per_target_m3_bound_ratio`` (to its lower bound per target m³, which counts whole
  buckets, the fill factor and the travel to the first dump; NaN in stores not rescored since it
  was added) and ``time_per_target_m3_best_ratio`` (to the scenario's best known plan,
  :mod:`earthbench.publishing.best`: over the valid runs of scenarios that have one; NaN without a best-known
  folder), and over runs that loaded
  something (the others are counted in ``loaded_nothing``) ``time_per_m3``.
* ``target_share_mean``: the mean over valid runs of the share of the target loaded, capped at 1
  (:func:`earthbench.results.scoring.target_share`): the tie-break among runs short of the target.
* ``solve_cpu_median`` (the ranked solve-time figure: CPU seconds of the case's process tree, with
  interval) and ``solve_time_median`` (wall, with interval) / ``_p90``: over every run with a
  measured time, failures included (a timeout's solve time is the time it was given).
* ``load_min`` / ``load_max``: the machine's 1-minute load average around the runs' cases
  (before and after each), ``steal_max``: the largest share of CPU time stolen by a hypervisor
  during one (NaN for runs stored before these were recorded).
* ``config_label``: the configuration's readable name (:mod:`earthbench.results.labels`); ``separable``:
  whether the table has enough scenarios (:func:`earthbench.stats.min_separating_n`) for any paired
  test to tell two planners apart at :data:`RANK_ALPHA`.
* ``prepare_max``: the longest preparation (wall s) the runs used, NaN for a planner without one
  (docs/DESIGN.md §6 "Preparation": paid once per machine, never in the solve times).
* ``n_<reason>`` for each termination reason; ``cpu_models``: how many CPU models the runs
  came from (solve times from different models are not comparable).

Ranking (:data:`RANKING_RULE`, :func:`rank`) within each table: ``latest`` marks the newest
version of each planner (by version number, else by its newest run); only those are
``ranked`` unless ``all_versions``, and never a configuration without a valid run.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from .scoring import target_share
from ..stats import ALPHA, mcnemar_p, median_ci, min_separating_n, paired_differences, rate_ci, wilcoxon_p

REASONS = ("ok", "invalid", "timeout", "memory", "error", "crashed")
GROUP = ["suite", "track", "planner", "planner_version", "config_hash"]
#: One ranked table: a suite and track, whole (scope ``suite``) or one family or target of it.
TABLE = ["suite", "track", "scope", "group"]
SCOPES = ("suite", "family", "target")
#: The primary time metric of tables, rankings, profiles and figures.
PRIMARY = "time_per_target_m3"
#: Significance level of the paired tests that decide shared ranks.
RANK_ALPHA = ALPHA
RANKING_RULE = (
    "ranked by success rate (higher first), then median time per target m³ over valid runs (lower first; a run "
    "short of the target counts as infinite), then the mean share of the target loaded (capped at 1; higher first), then "
    "median solve CPU time (lower first); a planner shares the rank "
    "of the first planner of the group above it (shown as 1=) unless a paired test on their shared scenarios "
    f"separates the two at α = {RANK_ALPHA:g} (exact McNemar on "
    "success, or Wilcoxon signed-rank on time per target m³ where both are valid); ranks cover the latest version of each planner "
    "(older versions: history) and never a configuration without a valid run")

SUMMARY_COLUMNS = [
    "rank", "rank_label", "ranked", "latest", *TABLE, *GROUP[2:], "config_label", "runs", "of", "scenarios", "successes", "success_rate",
    "success_rate_lo", "success_rate_hi", "valid_runs", "volume_ratio_mean", "volume_ratio_sd", "overshoot_m3_mean",
    "target_share_mean", "time_per_target_m3_median", "time_per_target_m3_lo", "time_per_target_m3_hi", "time_per_target_m3_q1",
    "time_per_target_m3_q3", "production_m3h_median", "production_m3h_lo", "production_m3h_hi",
    "time_per_target_m3_ratio_median", "time_per_target_m3_ratio_lo",
    "time_per_target_m3_ratio_hi", "time_per_target_m3_bound_ratio_median", "time_per_target_m3_bound_ratio_lo",
    "time_per_target_m3_bound_ratio_hi", "time_per_target_m3_best_ratio_median", "time_per_target_m3_best_ratio_lo",
    "time_per_target_m3_best_ratio_hi", "time_per_m3_median", "time_per_m3_lo", "time_per_m3_hi", "time_per_m3_q1",
    "time_per_m3_q3", "time_per_m3_iqr", "time_per_m3_ratio_median", "loaded_nothing", "short_of_target",
    "solve_cpu_median", "solve_cpu_lo", "solve_cpu_hi", "solve_time_median", "solve_time_lo", "solve_time_hi", "solve_time_p90",
    "prepare_max",
    *(f"n_{r}" for r in REASONS), "n_other", "cpu_models", "load_min", "load_max", "steal_max", "separable",
]


def _num(g: pd.DataFrame, col: str) -> np.ndarray:
    if col not in g:
        return np.full(len(g), np.nan)
    return pd.to_numeric(g[col], errors="coerce").to_numpy(dtype=float)


def _median_ci(x: np.ndarray) -> tuple[float, float, float]:
    if not len(x):
        return math.nan, math.nan, math.nan
    lo, hi = median_ci(x)
    return float(np.median(x)), lo, hi


def _quartiles(x: np.ndarray) -> tuple[float, float]:
    """First and third quartile; infinite where the quartile falls among infinite values (no NaN from inf − inf)."""
    if not len(x):
        return math.nan, math.nan
    with np.errstate(invalid="ignore"):
        q = np.percentile(x, [25, 75])
    return tuple(math.inf if math.isnan(v) else float(v) for v in q)  # type: ignore[return-value]


def _load_range(g: pd.DataFrame) -> tuple[float, float, float]:
    cols = [c for c in ("load_before", "load_after") if c in g]
    load = np.concatenate([_num(g, c) for c in cols]) if cols else np.array([])
    load = load[np.isfinite(load)]
    steal = _num(g, "steal_share")
    steal = steal[np.isfinite(steal)]
    return (float(load.min()) if len(load) else math.nan, float(load.max()) if len(load) else math.nan,
            float(steal.max()) if len(steal) else math.nan)

def target_label(v: Any) -> str:
    """A target volume as a breakdown's group name: ``4 m³``."""
    try:
        return f"{float(v):g} m³"
    except (TypeError, ValueError):
        return "?"


def production(time_per_m3: float) -> float:
    """Bank m³ an hour at ``time_per_m3`` seconds per bank m³ (0 where no plan reaches the target;
    NaN where there is no figure): the production a site manager compares with a handbook."""
    if math.isnan(time_per_m3):
        return math.nan
    return 3600.0 / time_per_m3 if time_per_m3 > 0 else math.inf


def _summarise(g: pd.DataFrame, of: int | None) -> dict[str, Any]:
    reason = g["reason"].astype(str).to_numpy()
    ok = reason == "ok"
    success = g["success"].fillna(False).astype(bool).to_numpy()
    vr = _num(g, "volume_ratio")[ok]
    vr = vr[np.isfinite(vr)]
    over = _num(g, "overshoot_m3")[ok]
    over = over[np.isfinite(over)]
    tpt, tpt_ratio = _num(g, PRIMARY)[ok], _num(g, "time_per_target_m3_ratio")[ok]
    tpt_bound_ratio = _num(g, "time_per_target_m3_bound_ratio")[ok]
    tpt_best_ratio = _num(g, "time_per_target_m3_best_ratio")[ok]
    tpm, tpm_ratio = _num(g, "time_per_m3")[ok], _num(g, "time_per_m3_ratio")[ok]
    tpt_f, tpm_f = tpt[~np.isnan(tpt)], tpm[np.isfinite(tpm)]  # the primary metric keeps its infinities: they rank
    st = _num(g, "solve_time_s")
    st = st[np.isfinite(st)]
    cpu = _num(g, "solve_cpu_s")
    cpu = cpu[np.isfinite(cpu)]
    prep = _num(g, "prepare_s")
    prep = prep[np.isfinite(prep)]
    counts = {f"n_{r}": int((reason == r).sum()) for r in REASONS}
    n_sc = int(g["scenario_digest"].nunique())
    of = max(int(of), n_sc) if of else n_sc
    # success per scenario (a duplicate run of one scenario counts once, as its best), padded with failures
    per_sc = pd.Series(success).groupby(g["scenario_digest"].to_numpy()).max()
    s_lo, s_hi = rate_ci(int(per_sc.sum()), of)
    tpt_med, tpt_lo, tpt_hi = _median_ci(tpt_f)
    r_med, r_lo, r_hi = _median_ci(tpt_ratio[~np.isnan(tpt_ratio)])
    b_med, b_lo, b_hi = _median_ci(tpt_bound_ratio[~np.isnan(tpt_bound_ratio)])
    k_med, k_lo, k_hi = _median_ci(tpt_best_ratio[~np.isnan(tpt_best_ratio)])
    tpm_med, tpm_lo, tpm_hi = _median_ci(tpm_f)
    st_med, st_lo, st_hi = _median_ci(st)
    cpu_med, cpu_lo, cpu_hi = _median_ci(cpu)
    tq1, tq3 = _quartiles(tpt_f)
    q1, q3 = _quartiles(tpm_f)
    load_min, load_max, steal_max = _load_range(g)
    tr = tpm_ratio[np.isfinite(tpm_ratio)]
    return {
        "runs": len(g), "of": of, "scenarios": n_sc, "successes": int(per_sc.sum()),
        "success_rate": float(per_sc.sum() / of) if of else math.nan, "success_rate_lo": s_lo, "success_rate_hi": s_hi,
        "valid_runs": int(ok.sum()),
        "volume_ratio_mean": float(vr.mean()) if len(vr) else math.nan,
        "volume_ratio_sd": float(vr.std(ddof=1)) if len(vr) > 1 else math.nan,
        "overshoot_m3_mean": float(over.mean()) if len(over) else math.nan,
        "target_share_mean": float(np.mean([target_share(v) for v in vr])) if len(vr) else math.nan,
        "time_per_target_m3_median": tpt_med, "time_per_target_m3_lo": tpt_lo, "time_per_target_m3_hi": tpt_hi,
        "time_per_target_m3_q1": float(tq1), "time_per_target_m3_q3": float(tq3),
        # production, the site's unit: bank m³ an hour at the median time per target m³ (its interval from that one's)
        "production_m3h_median": production(tpt_med), "production_m3h_lo": production(tpt_hi),
        "production_m3h_hi": production(tpt_lo),
        "time_per_target_m3_ratio_median": r_med, "time_per_target_m3_ratio_lo": r_lo, "time_per_target_m3_ratio_hi": r_hi,
        "time_per_target_m3_bound_ratio_median": b_med, "time_per_target_m3_bound_ratio_lo": b_lo,
        "time_per_target_m3_bound_ratio_hi": b_hi,
        "time_per_target_m3_best_ratio_median": k_med, "time_per_target_m3_best_ratio_lo": k_lo,
        "time_per_target_m3_best_ratio_hi": k_hi,
        "time_per_m3_median": tpm_med, "time_per_m3_lo": tpm_lo, "time_per_m3_hi": tpm_hi,
        "time_per_m3_q1": float(q1), "time_per_m3_q3": float(q3), "time_per_m3_iqr": float(q3 - q1),
        "time_per_m3_ratio_median": float(np.median(tr)) if len(tr) else math.nan,
        "loaded_nothing": int(np.isinf(tpm).sum()), "short_of_target": int(np.isinf(tpt_f).sum()),
        "solve_cpu_median": cpu_med, "solve_cpu_lo": cpu_lo, "solve_cpu_hi": cpu_hi,
        "solve_time_median": st_med, "solve_time_lo": st_lo, "solve_time_hi": st_hi,
        "solve_time_p90": float(np.percentile(st, 90)) if len(st) else math.nan,
        "prepare_max": float(prep.max()) if len(prep) else math.nan,
        **counts, "n_other": int(len(g) - sum(counts.values())),
        "cpu_models": int(g["cpu_model"].dropna().nunique()) if "cpu_model" in g else 0,
        "load_min": load_min, "load_max": load_max, "steal_max": steal_max, "separable": of >= min_separating_n(RANK_ALPHA),
    }


def version_key(version: str) -> tuple[int, Any]:
    from packaging.version import InvalidVersion, Version

    try:
        return (1, Version(str(version)))
    except InvalidVersion:
        return (0, str(version))


def latest_versions(runs: pd.DataFrame) -> set[tuple[str, str, str, str]]:
    """(suite, track, planner, version) of each planner's newest version: the highest version number
    (PEP 440), else — for versions that are not numbers — the one whose newest run finished last."""
    out: set[tuple[str, str, str, str]] = set()
    if runs.empty:
        return out
    finished = runs["finished_at"].astype(str) if "finished_at" in runs else pd.Series("", index=runs.index)
    last = finished.groupby([runs[c] for c in GROUP[:4]]).max()
    for (suite, track, planner), sub in last.groupby(level=[0, 1, 2]):
        versions = [(v, t) for (_, _, _, v), t in sub.items()]
        best = max(versions, key=lambda vt: (version_key(vt[0]), vt[1]))[0]
        out.add((suite, track, planner, str(best)))
    return out


def _scoped(runs: pd.DataFrame, scope: str) -> pd.DataFrame:
    if scope == "suite":
        return runs.assign(scope="suite", group="")
    col = runs["family"] if scope == "family" else runs["target_volume"].map(target_label)
    return runs.assign(scope=scope, group=col.fillna("?").astype(str))


def aggregate(runs: pd.DataFrame, sizes: dict[str, int] | None = None, *, members: pd.DataFrame | None = None,
              scopes: Sequence[str] = ("suite",), all_versions: bool = False) -> pd.DataFrame:
    """One row per (table, planner configuration), columns :data:`SUMMARY_COLUMNS`, ranked by :func:`rank`.

    ``sizes``: suite name → its number of scenarios; ``members``: the suites' scenarios
    (columns ``suite``, ``scenario_digest``, ``family``, ``target_volume``), which give every
    breakdown's scenario count. ``scopes``: the tables to make (``suite``, ``family``, ``target``); a
    suite with a single family (or target) gets no table for that scope.
    """
    sizes = sizes or {}
    of: dict[tuple[str, str, str], int] = {}
    if members is not None and len(members):
        for scope in scopes:
            m = _scoped(members, scope)
            for key, n in m.groupby(["suite", "scope", "group"]).size().items():
                of[key] = int(n)
    latest = latest_versions(runs) if len(runs) else set()
    from .labels import config_labels

    labels = config_labels(runs)
    rows, vectors = [], []
    for scope in scopes:
        if not len(runs):
            break
        sr = _scoped(runs, scope)
        if scope != "suite":  # a suite of one family (or one target) has no breakdown: it would repeat the suite
            parts = _scoped(members, scope) if members is not None and len(members) else sr
            split = parts.groupby("suite")["group"].nunique()
            sr = sr[sr["suite"].map(split).fillna(0) > 1]
        for key, g in sr.groupby(["suite", "track", "scope", "group", *GROUP[2:]], sort=True, dropna=False):
            suite, track, _, group, planner, version, _cfg = key
            n_of = of.get((suite, scope, group), sizes.get(suite) if scope == "suite" else None)
            is_latest = (suite, track, planner, str(version)) in latest
            rows.append({**dict(zip(["suite", "track", "scope", "group", *GROUP[2:]], key)), "latest": is_latest,
                         "config_label": labels.get((str(planner), str(_cfg)), str(planner)), **_summarise(g, n_of)})
            vectors.append(_paired_vectors(g))
    out = pd.DataFrame.from_records(rows, columns=[c for c in SUMMARY_COLUMNS if c not in ("rank", "rank_label", "ranked")])
    return rank(out, vectors, all_versions=all_versions)


def _paired_vectors(g: pd.DataFrame) -> tuple[pd.Series, pd.Series]:
    """Per scenario digest: success (best run) and the primary time of valid runs (infinite: short of the target)."""
    d = g["scenario_digest"].to_numpy()
    succ = pd.Series(g["success"].fillna(False).astype(bool).to_numpy()).groupby(d).max()
    t = _num(g, PRIMARY)
    ok = (g["reason"].astype(str).to_numpy() == "ok") & ~np.isnan(t)
    times = pd.Series(t[ok]).groupby(d[ok]).min()
    return succ, times


def separated(a: tuple[pd.Series, pd.Series], b: tuple[pd.Series, pd.Series], alpha: float = RANK_ALPHA) -> bool:
    """Whether a paired test on shared scenarios tells two configurations apart (the shared-rank rule:
    each row is tested against the first row of the group it would join, so ties never chain).

    Success over the union of their scenarios (a missing run is a failure), exact McNemar; else the
    primary time over the scenarios where both are valid, two-sided Wilcoxon signed-rank.
    """
    digests = a[0].index.union(b[0].index)
    sa = a[0].reindex(digests, fill_value=False).to_numpy(dtype=bool)
    sb = b[0].reindex(digests, fill_value=False).to_numpy(dtype=bool)
    if mcnemar_p(sa, sb) < alpha:
        return True
    both = a[1].index.intersection(b[1].index)
    if len(both) == 0:
        return False
    return wilcoxon_p(paired_differences(a[1].loc[both].to_numpy(), b[1].loc[both].to_numpy()))[1] < alpha


def rank(summary: pd.DataFrame, vectors: Sequence[tuple[pd.Series, pd.Series]] | None = None, *,
         all_versions: bool = False) -> pd.DataFrame:
    """Order each table by :data:`RANKING_RULE`; number the ranked rows (``rank``, ``rank_label``: ``1=`` when shared).

    ``vectors`` (per row, from :func:`_paired_vectors`) feed the paired tests; without them
    (a summary read back from CSV) every rank is distinct.
    """
    if summary.empty:
        return summary.assign(rank=pd.Series(dtype=float), rank_label=pd.Series(dtype=str),
                              ranked=pd.Series(dtype=bool))[SUMMARY_COLUMNS]
    s = summary.copy()
    s["_v"] = range(len(s))
    s["ranked"] = (s["latest"].astype(bool) | all_versions) & (s["valid_runs"] > 0)
    s["_unranked"] = ~s["ranked"]
    s["_neg_success"] = -s["success_rate"].fillna(0.0)
    s["_neg_share"] = -s["target_share_mean"].fillna(0.0)
    s["_scope"] = s["scope"].map({sc: i for i, sc in enumerate(SCOPES)})
    s = s.sort_values(["suite", "track", "_scope", "group", "_unranked", "_neg_success", "time_per_target_m3_median",
                       "_neg_share", "solve_cpu_median", "solve_time_median", "planner", "planner_version", "config_hash"],
                      na_position="last", kind="mergesort").reset_index(drop=True)
    ranks: list[float] = [math.nan] * len(s)
    labels: list[str] = ["–"] * len(s)
    for _, idx in s.groupby(TABLE, sort=False).groups.items():
        ranked = [i for i in idx if s.at[i, "ranked"]]
        leader = None  # the first row of the current group of shared rank
        for pos, i in enumerate(ranked):
            if leader is not None and vectors is not None and not separated(vectors[s.at[leader, "_v"]], vectors[s.at[i, "_v"]]):
                ranks[i] = ranks[leader]
            else:
                leader, ranks[i] = i, float(pos + 1)
        for i in ranked:
            shared = sum(1 for j in ranked if ranks[j] == ranks[i]) > 1
            labels[i] = f"{int(ranks[i])}=" if shared else str(int(ranks[i]))
    s["rank"] = ranks
    s["rank_label"] = labels
    return s[SUMMARY_COLUMNS]


def ci_text(value: Any, lo: Any, hi: Any, spec: str = ".1f", scale: float = 1.0, unit: str = "") -> str:
    """``value [lo–hi]`` (the 95 % interval), ``value`` alone without one, ``–`` for no value."""
    def f(v: Any) -> str:
        if v is None or (isinstance(v, float) and math.isnan(v)):
            return "–"
        if isinstance(v, float) and math.isinf(v):
            return "∞"
        return format(float(v) * scale, spec) + unit

    text = f(value)
    if text == "–" or lo is None or hi is None or (isinstance(lo, float) and math.isnan(lo)):
        return text
    return f"{text} [{f(lo)}–{f(hi)}]"
