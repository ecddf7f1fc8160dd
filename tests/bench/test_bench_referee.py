"""Speed of the referee: replay a 30-dig plan on the 12 m × 6 m map at 0.05 m cells.

Goal (issue 2): median under 20 ms. Run with ``pytest tests/bench --benchmark-only``.
"""

from __future__ import annotations

from earthbench import judge
from planners.greedy import GreedyPlanner
from terrains.rbf import rbf


def test_replay_30_digs(benchmark):
    sc = rbf(0, 30 * 0.28 * 0.97, n_bases=30)
    plan = GreedyPlanner().plan(sc)
    digs = sum(a.kind == "dig" for a in plan.actions)
    assert 29 <= digs <= 32
    verdict = benchmark(judge, sc, plan)
    assert verdict.valid
    benchmark.extra_info["digs"] = digs
    benchmark.extra_info["actions"] = len(plan.actions)


def test_greedy_plan_7m3(benchmark):
    sc = rbf(0, 7.0, n_bases=30)
    plan = benchmark(GreedyPlanner().plan, sc)
    assert judge(sc, plan).valid
