"""The statistics behind every table and comparison: bootstrap intervals and paired tests.

One place, so the leaderboard, ``run``'s summary and ``compare`` state the same uncertainty:

* :func:`bootstrap_ci` — a 95 % BCa bootstrap interval (``scipy.stats.bootstrap``, 999
  resamples, a fixed seed so a table is reproducible byte for byte) of a median or a rate;
* :func:`wilcoxon_p` — two-sided Wilcoxon signed-rank test on paired differences (zeros dropped);
* :func:`mcnemar_p` — exact McNemar test on paired successes (binomial on the discordant pairs);
* :func:`min_wilcoxon_p` — the smallest p-value the signed-rank test can give with n pairs, so a
  caller can say when n can never reach its alpha;
* :func:`holm` — Holm's step-down adjustment of several p-values (family-wise error ≤ alpha).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence

import numpy as np

CONFIDENCE = 0.95
N_RESAMPLES = 999
SEED = 20261202


def _median(x: np.ndarray, axis: int = -1) -> np.ndarray:
    return np.median(x, axis=axis)


def _mean(x: np.ndarray, axis: int = -1) -> np.ndarray:
    return np.mean(x, axis=axis)


STATISTICS: dict[str, Callable[..., np.ndarray]] = {"median": _median, "mean": _mean}


def bootstrap_ci(values: Sequence[float] | np.ndarray, statistic: str = "median") -> tuple[float, float]:
    """95 % BCa bootstrap interval of ``statistic`` ("median" or "mean", e.g. of 0/1 successes: a rate).

    NaN for fewer than two values; a single point when every value is the same (no spread to
    resample). Non-finite values must be removed by the caller (a median over them is not defined here).
    """
    from scipy.stats import bootstrap

    x = np.asarray(values, dtype=float)
    if len(x) < 2:
        return math.nan, math.nan
    if np.all(x == x[0]):
        return float(x[0]), float(x[0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # BCa on tiny or lumpy samples warns and may give NaN: then percentile
        res = bootstrap((x,), STATISTICS[statistic], vectorized=True, axis=-1, confidence_level=CONFIDENCE,
                        n_resamples=N_RESAMPLES, method="BCa", random_state=np.random.default_rng(SEED))
        lo, hi = float(res.confidence_interval.low), float(res.confidence_interval.high)
        if not (math.isfinite(lo) and math.isfinite(hi)):
            res = bootstrap((x,), STATISTICS[statistic], vectorized=True, axis=-1, confidence_level=CONFIDENCE,
                            n_resamples=N_RESAMPLES, method="percentile", random_state=np.random.default_rng(SEED))
            lo, hi = float(res.confidence_interval.low), float(res.confidence_interval.high)
    return lo, hi


def wilcoxon_p(d: Sequence[float] | np.ndarray) -> tuple[float, float]:
    """(statistic, two-sided p) of the signed-rank test on differences ``d``; p = 1 when all are zero."""
    from scipy.stats import wilcoxon

    x = np.asarray(d, dtype=float)
    nz = x[x != 0]
    if len(nz) == 0:
        return 0.0, 1.0
    res = wilcoxon(nz, zero_method="wilcox", alternative="two-sided")
    return float(res.statistic), float(res.pvalue)


def min_wilcoxon_p(n: int) -> float:
    """Smallest two-sided p of the exact signed-rank test with ``n`` non-zero pairs: 2 / 2ⁿ (1 for n = 0)."""
    return 1.0 if n <= 0 else min(1.0, 2.0 / 2.0 ** n)


def mcnemar_p(a: Sequence[bool] | np.ndarray, b: Sequence[bool] | np.ndarray) -> float:
    """Exact two-sided McNemar p-value of paired successes ``a`` and ``b`` (1 without discordant pairs)."""
    from scipy.stats import binomtest

    sa, sb = np.asarray(a, dtype=bool), np.asarray(b, dtype=bool)
    only_a, only_b = int((sa & ~sb).sum()), int((~sa & sb).sum())
    if only_a + only_b == 0:
        return 1.0
    return float(binomtest(only_b, only_a + only_b, 0.5).pvalue)


def holm(p: Sequence[float]) -> list[float]:
    """Holm-adjusted p-values (NaN stays NaN): reject those ≤ alpha to keep the family-wise error ≤ alpha."""
    idx = [i for i, v in enumerate(p) if not math.isnan(v)]
    order = sorted(idx, key=lambda i: p[i])
    m = len(order)
    out = [math.nan] * len(p)
    running = 0.0
    for k, i in enumerate(order):
        running = max(running, min(1.0, (m - k) * p[i]))
        out[i] = running
    return out
