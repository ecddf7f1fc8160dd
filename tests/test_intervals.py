"""Intervals that hold at small n: coverage by simulation for n = 1…12, and no median interval where n cannot give one."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from earthbench.results.aggregate import aggregate
from earthbench.stats import MEDIAN_CI_MIN_N, median_ci, min_separating_n, rate_ci, separation_note

REPS = 4000


@pytest.mark.parametrize("n", range(1, 13))
def test_rate_intervals_cover_at_least_95_percent(n):
    """Clopper–Pearson covers every true rate at ≥ 95 % (checked at rates from 0.02 to 0.98, and at the edges)."""
    rng = np.random.default_rng(n)
    bounds = {k: rate_ci(k, n) for k in range(n + 1)}
    for p in (0.02, 0.1, 0.3, 0.5, 0.7, 0.9, 0.98, 1.0):
        k = rng.binomial(n, p, REPS)
        covered = np.mean([bounds[x][0] <= p <= bounds[x][1] for x in k])
        assert covered >= 0.95 - 3 * math.sqrt(0.95 * 0.05 / REPS), (n, p, covered)
    assert bounds[n][1] == 1.0 and bounds[0][0] == 0.0
    if n == 4:  # the example: 4 of 4 is about 40–100 %, not 100–100 %
        assert bounds[4][0] == pytest.approx(0.398, abs=1e-3)


@pytest.mark.parametrize("n", range(1, 13))
def test_median_intervals_cover_at_least_95_percent_or_are_not_shown(n):
    rng = np.random.default_rng(100 + n)
    if n < MEDIAN_CI_MIN_N:
        assert all(math.isnan(v) for v in median_ci(rng.normal(size=n)))
        return
    for draw, median in ((lambda size: rng.lognormal(0, 1, size), 1.0), (lambda size: rng.exponential(2.0, size), 2 * math.log(2))):
        hits = 0
        for _ in range(REPS):
            lo, hi = median_ci(draw(n))
            hits += lo <= median <= hi
        assert hits / REPS >= 0.95 - 3 * math.sqrt(0.95 * 0.05 / REPS), (n, hits / REPS)


def test_a_median_with_infinite_values_has_an_interval_in_rank_order():
    lo, hi = median_ci([1, 2, 3, 4, 5, 6, 7, math.inf, math.inf])
    assert lo == 2 and hi == math.inf  # order statistics 2 and 8 of 9


def test_a_table_too_small_to_separate_says_so():
    assert min_separating_n(0.05) == 6
    assert "with 4 scenario(s) no paired test can tell two planners apart at α = 0.05" in separation_note(4)
    rows = [{"suite": "s", "track": "backhoe", "planner": p, "planner_version": "1", "config_hash": p, "scenario_digest": f"d{i}",
             "family": "f", "target_volume": 1.0, "reason": "ok", "success": True, "volume_ratio": 1.0,
             "time_per_target_m3": t * (i + 1), "time_per_m3": t, "solve_time_s": 1.0, "finished_at": "x"}
            for p, t in (("fast", 30.0), ("slow", 60.0)) for i in range(4)]
    s = aggregate(pd.DataFrame(rows)).set_index("planner")
    assert not s["separable"].any() and set(s["rank_label"]) == {"1="}  # twice the time, yet 4 scenarios cannot tell
    assert s["success_rate_lo"].iloc[0] == pytest.approx(0.398, abs=1e-3)
    assert s["time_per_target_m3_lo"].isna().all()  # no median interval from 4 values
