"""Solve time across the scale ladder, in-process, seed 0 of each size (issue 18).

Goals: greedy and singh-cannon-backhoe ≤ 0.05 s per m³ at every size, and solve time per m³ at
256 m³ ≤ 1.5× that at 4 m³. ``extra_info`` holds the time per m³ of target and the referee's
volume ratio. Run with ``python -m pytest tests/bench/test_bench_scale.py --benchmark-only``.
"""

from __future__ import annotations

import pytest

from earthbench import PLANNERS, judge
from earthbench.results.suite import load_suite

SIZES = ("rbf12x6", "rbf24x12", "rbf48x24", "rbf96x48")


@pytest.fixture(scope="module")
def ladder():
    return {sc.id.split("/")[1]: sc for sc in load_suite("scale").select([0])}


@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("planner", ["greedy", "singh-cannon-backhoe"])
def test_scale_solve(benchmark, ladder, planner, size):
    sc = ladder[size]
    plan = benchmark.pedantic(lambda: PLANNERS.get(planner)().plan(sc), rounds=3, iterations=1)
    v = judge(sc, plan)
    assert v.valid and v.loaded_volume >= 0.95 * sc.task.target_volume
    benchmark.extra_info.update(target_m3=sc.task.target_volume, volume_ratio=v.loaded_volume / sc.task.target_volume,
                                median_s_per_m3=benchmark.stats.stats.median / sc.task.target_volume)
