"""The generalisation gap: how a planner does on sealed draws of a suite against the public suite.

A planner tuned on the public seeds should do about as well on draws nobody saw before
(docs/sealed-evaluation.md); one that recognises public scenarios (or was tuned to them
alone) does worse. For every planner configuration with runs on both the public suite and
at least one sealed draw of it (``SUITE~sealed-C``, :mod:`earthbench.seal`; every draw pooled),
:func:`gap_table` gives, per metric, the public and sealed figures with the board's 95 %
intervals (:mod:`earthbench.stats`: exact Clopper–Pearson for the success rate, the
distribution-free order-statistic interval for the median time per target m³, none where n is
too small; a BCa bootstrap for the mean volume ratio) and the gap sealed − public with its own
interval. For the rate and the median the gap's interval joins the two samples' 97.5 %
intervals (sealed low − public high, sealed high − public low): both cover with probability at
least 0.975² > 0.95, so the gap's interval covers at least 95 % without assuming a
distribution; for the mean it is a two-sample percentile bootstrap. A planner is **flagged**
on a metric when a two-sample test rejects "sealed and public come from one distribution" at
the 1 % level (:data:`FLAG_LEVEL`): Fisher's exact test on the success counts, Mood's median
test on the time per target m³, a permutation test on the difference of mean volume ratios.
(Not disjoint intervals, as before 0.3.0: a sample without spread, such as volume ratios that
are all 1, has an interval of no width, and any sealed failure then lies outside it.
docs/sealed-evaluation.md, "What the first sealed draws showed".) The level is 1 % because a
board tests every planner on every metric: at 5 % an honest board of four planners would
carry a chance flag about every other time.

Metrics (each as the leaderboard computes it): ``success_rate`` (per scenario, a scenario
without a run counts as failed), ``time_per_target_m3`` (median over valid runs, a run short of
the target counting as ∞, as it ranks: :mod:`earthbench.results.scoring`) and ``volume_ratio`` (mean
over valid runs).
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
import pandas as pd

from ..seal import public_name
from ..stats import CONFIDENCE, N_RESAMPLES, SEED, STATISTICS, bootstrap_ci, median_ci, rate_ci

KEY = ["planner", "planner_version", "config_hash"]
#: metric → (statistic, what the sample is)
METRICS = {"success_rate": "mean", "time_per_target_m3": "median", "volume_ratio": "mean"}
COLUMNS = [*KEY, "public_suite", "draws", "metric", "public", "public_lo", "public_hi", "public_n",
           "sealed", "sealed_lo", "sealed_hi", "sealed_n", "gap", "gap_lo", "gap_hi", "p_value", "flagged"]
#: A metric is flagged when its two-sample test's p-value is below this.
FLAG_LEVEL = 0.01


def _sample(runs: pd.DataFrame, metric: str, of: int) -> np.ndarray:
    """The values a metric is a statistic of: per-scenario successes padded to ``of`` scenarios,
    or the values of the valid runs (a median keeps ∞, a run short of the target: dropping it
    would reward loading less; a mean only the finite ones)."""
    if metric == "success_rate":
        per = runs.groupby("scenario_digest")["success"].max().astype(float).to_numpy()
        return np.concatenate([per, np.zeros(max(of - len(per), 0))])
    ok = runs[runs["reason"] == "ok"]
    x = pd.to_numeric(ok[metric], errors="coerce").to_numpy(dtype=float) if metric in ok else np.array([])
    return x[~np.isnan(x)] if METRICS[metric] == "median" else x[np.isfinite(x)]


def interval(x: np.ndarray, metric: str, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """The board's interval of ``metric`` over the sample ``x`` (NaN where n allows none)."""
    if not len(x):
        return math.nan, math.nan
    if metric == "success_rate":
        return rate_ci(int(round(float(x.sum()))), len(x), confidence)
    if METRICS[metric] == "median":
        return median_ci(x, confidence)
    return bootstrap_ci(x, METRICS[metric]) if confidence == CONFIDENCE else (math.nan, math.nan)


def _stat(x: np.ndarray, statistic: str) -> float:
    return float(STATISTICS[statistic](x)) if len(x) else math.nan


def gap_ci(public: np.ndarray, sealed: np.ndarray, metric: str) -> tuple[float, float]:
    """95 % interval of the metric's sealed − public difference (two independent samples): the
    two 97.5 % intervals joined for a rate or a median, a percentile bootstrap for a mean."""
    from scipy.stats import bootstrap

    statistic = METRICS[metric]
    if statistic == "median" or metric == "success_rate":
        one_side = 1 - (1 - CONFIDENCE) / 2
        p_lo, p_hi = interval(public, metric, one_side)
        s_lo, s_hi = interval(sealed, metric, one_side)
        with np.errstate(invalid="ignore"):
            lo, hi = float(np.float64(s_lo) - p_hi), float(np.float64(s_hi) - p_lo)
        return (lo, hi) if not (math.isnan(lo) or math.isnan(hi)) else (math.nan, math.nan)
    if len(public) < 2 or len(sealed) < 2:
        return math.nan, math.nan
    if np.all(public == public[0]) and np.all(sealed == sealed[0]):
        d = float(sealed[0] - public[0])
        return d, d
    f = STATISTICS[statistic]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = bootstrap((public, sealed), lambda a, b, axis=-1: f(b, axis=axis) - f(a, axis=axis), vectorized=True, axis=-1,
                        confidence_level=CONFIDENCE, n_resamples=N_RESAMPLES, method="percentile",
                        random_state=np.random.default_rng(SEED))
    return float(res.confidence_interval.low), float(res.confidence_interval.high)


def p_value(public: np.ndarray, sealed: np.ndarray, metric: str) -> float:
    """Two-sided p-value of "the sealed and public samples of ``metric`` come from one
    distribution" (NaN when a sample is empty): Fisher's exact test on success counts, Mood's
    median test on a median (∞ compares as larger than every time), a permutation test on the
    difference of means."""
    from scipy.stats import fisher_exact, median_test, permutation_test

    if not len(public) or not len(sealed):
        return math.nan
    if metric == "success_rate":
        k_p, k_s = int(round(float(public.sum()))), int(round(float(sealed.sum())))
        return float(fisher_exact([[k_p, len(public) - k_p], [k_s, len(sealed) - k_s]]).pvalue)
    if METRICS[metric] == "median":
        try:
            return float(median_test(public, sealed, ties="below")[1])
        except ValueError:  # every value on one side of the grand median: nothing tells the samples apart
            return 1.0
    if np.all(public == public[0]) and np.all(sealed == public[0]):
        return 1.0
    f = STATISTICS[METRICS[metric]]
    res = permutation_test((public, sealed), lambda a, b, axis=-1: f(b, axis=axis) - f(a, axis=axis), vectorized=True,
                           n_resamples=N_RESAMPLES, alternative="two-sided", random_state=np.random.default_rng(SEED))
    return float(res.pvalue)


def gap_table(runs: pd.DataFrame, members: pd.DataFrame) -> pd.DataFrame:
    """One row per (public suite, planner configuration, metric) with runs on the suite and a sealed draw of it.

    ``runs``: :func:`earthbench.results.store.load_runs` rows of the public suites and their sealed
    draws; ``members``: :func:`earthbench.results.store.suite_members` of the same suites (the
    denominators of the success rate).
    """
    if runs.empty:
        return pd.DataFrame(columns=COLUMNS)
    origin = runs["suite"].map(lambda s: public_name(str(s)) or s)
    sizes = members.groupby("suite")["scenario_digest"].nunique().to_dict() if not members.empty else {}
    rows: list[dict[str, Any]] = []
    for (public, *key), g in runs.assign(_origin=origin).groupby(["_origin", *KEY], sort=True):
        pub = g[g["suite"] == public]
        sea = g[g["suite"] != public]
        if pub.empty or sea.empty:
            continue
        draws = sorted(sea["suite"].unique())
        of_pub = int(sizes.get(public, pub["scenario_digest"].nunique()))
        of_sea = sum(int(sizes.get(d, sea.loc[sea["suite"] == d, "scenario_digest"].nunique())) for d in draws)
        for metric, statistic in METRICS.items():
            a = _sample(pub, metric, of_pub)
            b = np.concatenate([_sample(sea[sea["suite"] == d], metric, int(sizes.get(d, 0))) for d in draws]) \
                if metric == "success_rate" else _sample(sea, metric, of_sea)
            p, s = _stat(a, statistic), _stat(b, statistic)
            p_lo, p_hi = interval(a, metric)
            s_lo, s_hi = interval(b, metric)
            g_lo, g_hi = gap_ci(a, b, metric)
            pv = p_value(a, b, metric)
            rows.append({**dict(zip(KEY, key)), "public_suite": public, "draws": len(draws), "metric": metric,
                         "public": p, "public_lo": p_lo, "public_hi": p_hi, "public_n": len(a),
                         "sealed": s, "sealed_lo": s_lo, "sealed_hi": s_hi, "sealed_n": len(b),
                         "gap": s - p, "gap_lo": g_lo, "gap_hi": g_hi, "p_value": pv,
                         "flagged": bool(pv < FLAG_LEVEL)})
    return pd.DataFrame(rows, columns=COLUMNS)


def _f(v: Any, scale: float = 1.0) -> str:
    """A figure: ∞ for an infinite median (every run short of the target), – for no value."""
    if v is None or math.isnan(float(v)):
        return "–"
    return ("∞" if v > 0 else "-∞") if math.isinf(float(v)) else f"{float(v) * scale:.3g}"


def _ci(lo: Any, hi: Any, scale: float = 1.0) -> str:
    """An interval in brackets, or nothing when neither end has a value."""
    ends = [_f(lo, scale), _f(hi, scale)]
    return "" if ends == ["–", "–"] else f" [{ends[0]}–{ends[1]}]"


def _p(v: Any) -> str:
    """A p-value to two significant figures, or – for none."""
    return "–" if v is None or math.isnan(float(v)) else (f"{float(v):.2g}" if v >= 0.001 else "< 0.001")


def markdown(table: pd.DataFrame) -> str:
    """The gap table as Markdown, one section per public suite ('' when there is nothing to compare)."""
    if table.empty:
        return ""
    out = ["## Generalisation gap: sealed draws against the public suite", "",
           "Each planner's figures on the public suite and on the sealed draws of it (docs/sealed-evaluation.md), "
           "95 % intervals in brackets (exact for rates, order statistics for medians, – where n is too small); "
           "gap = sealed − public; p: a two-sample test of sealed against public (Fisher's exact test on success, "
           "Mood's median test on time, a permutation test on the mean volume ratio). "
           f"**flagged**: p < {FLAG_LEVEL:g}. Success rates in %.", ""]
    for public, t in table.groupby("public_suite", sort=True):
        out += [f"### {public} ({int(t['draws'].max())} sealed draw(s))", "",
                "| planner | metric | public | sealed | gap | p | |", "|---|---|---|---|---|---|---|"]
        for _, r in t.iterrows():
            k = 100.0 if r["metric"] == "success_rate" else 1.0
            out.append(f"| {r['planner']} {r['planner_version']} | {r['metric']} "
                       f"| {_f(r['public'], k)}{_ci(r['public_lo'], r['public_hi'], k)} "
                       f"| {_f(r['sealed'], k)}{_ci(r['sealed_lo'], r['sealed_hi'], k)} "
                       f"| {_f(r['gap'], k)}{_ci(r['gap_lo'], r['gap_hi'], k)} | {_p(r['p_value'])} "
                       f"| {'**flagged**' if r['flagged'] else ''} |")
        out.append("")
    return "\n".join(out)


def with_sealed_draws(store: Any, suites: Any) -> list[str] | None:
    """``suites`` and every sealed draw of them that ``store`` lists (None stays None: every suite)."""
    if not suites:
        return None
    names = store.suite_names()
    return list(dict.fromkeys([*suites, *(n for n in names if public_name(n) in suites)]))


def write(table: pd.DataFrame, out: Any) -> list[Any]:
    """``generalisation.csv`` in ``out`` when there is a gap to show; the files written."""
    if table.empty:
        return []
    path = out / "generalisation.csv"
    table.to_csv(path, index=False)
    return [path]
