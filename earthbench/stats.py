"""The statistics behind every table and comparison: intervals that hold at small n, paired tests.

One place, so the leaderboard, ``run``'s summary and ``compare`` state the same uncertainty
in the same words (:data:`INTERVAL_NOTE`, :func:`separation_note`):

* :func:`rate_ci` — the exact (Clopper–Pearson) 95 % interval of a rate k / n, from the beta
  quantiles (``scipy.stats.beta``): its coverage is at least 95 % for every true rate and n;
* :func:`median_ci` — the distribution-free 95 % interval of a median between two order
  statistics: it covers the true median with probability ≥ 95 % for any continuous distribution
  (ties only widen it), and there is none below :data:`MEDIAN_CI_MIN_N` values, where even the
  smallest and largest value cover the median less often than 95 %;
* :func:`bootstrap_ci` — a BCa bootstrap interval; kept for callers, no table uses it any more
  (below about 20 values it covers less than it says);
* :func:`wilcoxon_p` — two-sided Wilcoxon signed-rank test on paired differences (zeros dropped;
  infinite differences — one side never reached the target — rank above every finite one);
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
#: Significance level of every paired test behind shared ranks and verdicts.
ALPHA = 0.05

#: How every table, summary and comparison names its intervals.
INTERVAL_NOTE = ("95 % intervals in brackets: exact (Clopper–Pearson) for rates, distribution-free (order statistics) for "
                 "medians, none for a median of fewer than 6 values")


def rate_ci(successes: int, n: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Exact (Clopper–Pearson) interval of the rate ``successes / n``; NaN for n = 0."""
    from scipy.stats import beta

    if n <= 0:
        return math.nan, math.nan
    a = (1 - confidence) / 2
    k = int(successes)
    lo = 0.0 if k <= 0 else float(beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k >= n else float(beta.ppf(1 - a, k + 1, n - k))
    return lo, hi


def median_ci_ranks(n: int, confidence: float = CONFIDENCE) -> tuple[int, int] | None:
    """1-based ranks (l, n + 1 − l) of the order statistics bounding the median's interval, the
    narrowest symmetric pair covering with probability ≥ ``confidence``; None when no pair does."""
    from scipy.stats import binom

    if n < 1:
        return None
    # P(X_(l) ≤ m ≤ X_(n+1−l)) = 1 − 2 P(B ≤ l − 1), B ~ Binomial(n, ½), for a continuous distribution
    l_max = int(binom.ppf((1 - confidence) / 2, n, 0.5))  # the largest l − 1 with P(B ≤ l − 1) ≤ α / 2, or one more
    for low in range(max(l_max, 0) + 1, 0, -1):
        if 1 - 2 * float(binom.cdf(low - 1, n, 0.5)) >= confidence:
            return low, n + 1 - low
    return None


#: The fewest values for which a 95 % median interval exists (1 − 2 / 2⁶ = 0.969; with 5: 0.938).
MEDIAN_CI_MIN_N = 6


def median_ci(values: Sequence[float] | np.ndarray, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Distribution-free interval of the median between two order statistics; NaN where n is too small.

    Values may be infinite (a run that never reached the target): they sort last, as they rank.
    """
    x = np.sort(np.asarray(values, dtype=float))
    ranks = _ranks95(len(x)) if confidence == CONFIDENCE else median_ci_ranks(len(x), confidence)
    if ranks is None:
        return math.nan, math.nan
    return float(x[ranks[0] - 1]), float(x[ranks[1] - 1])


_RANKS: dict[int, tuple[int, int] | None] = {}


def _ranks95(n: int) -> tuple[int, int] | None:
    if n not in _RANKS:
        _RANKS[n] = median_ci_ranks(n)
    return _RANKS[n]


def min_paired_p(n: int) -> float:
    """Smallest two-sided p an exact paired test (signed-rank or McNemar) can give with ``n`` non-tied pairs."""
    return min_wilcoxon_p(n)


def min_separating_n(alpha: float = ALPHA) -> int:
    """The fewest non-tied pairs with which a paired test can reach ``alpha`` at all (6 at 0.05)."""
    n = 1
    while min_paired_p(n) >= alpha:
        n += 1
    return n


def separation_note(n: int, alpha: float = ALPHA) -> str:
    """The one wording, for boards, ``run``'s summary and ``compare``, of a sample too small to separate."""
    return (f"with {n} scenario(s) no paired test can tell two planners apart at α = {alpha:g} (the smallest possible "
            f"p is {min_paired_p(n):.3g}; it takes {min_separating_n(alpha)}): shared ranks here say nothing")


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


def paired_differences(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray) -> np.ndarray:
    """``b − a`` per pair, where two equal infinities (neither reached the target) are a tie (0), not NaN."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    with np.errstate(invalid="ignore"):
        d = y - x
    return np.where(np.isinf(x) & (x == y), 0.0, d)


def wilcoxon_p(d: Sequence[float] | np.ndarray) -> tuple[float, float]:
    """(statistic, two-sided p) of the signed-rank test on differences ``d``; p = 1 when all are zero."""
    from scipy.stats import wilcoxon

    x = np.asarray(d, dtype=float)
    nz = x[(x != 0) & ~np.isnan(x)]
    if len(nz) == 0:
        return 0.0, 1.0
    inf = np.isinf(nz)
    if inf.any():  # a rank test: an infinite difference ranks above every finite one, whatever number stands for it
        big = 2.0 * float(np.abs(nz[~inf]).max(initial=1.0)) + 1.0
        nz = np.where(inf, np.sign(nz) * big, nz)
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
