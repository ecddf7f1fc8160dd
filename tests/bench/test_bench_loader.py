"""Speed of the wheel-loader planners on ``pile`` (issue 8 goal: a whole plan under 5 s).

Run with ``pytest tests/bench/test_bench_loader.py --benchmark-only``.
"""

from __future__ import annotations

import pytest

from earthbench import judge
from earthbench_planners.greedy.loader import GreedyLoader
from earthbench_planners.singh_cannon.loader import SinghCannonLoader
from earthbench_terrains.pile import pile


@pytest.mark.parametrize("planner", [SinghCannonLoader, GreedyLoader], ids=lambda p: p.name)
def test_loader_plan_pile_4m3(benchmark, planner):
    sc = pile(0, 4.0)
    plan = benchmark.pedantic(planner().plan, args=(sc,), rounds=3, iterations=1)
    v = judge(sc, plan)
    assert v.valid and v.loaded_volume >= 0.95 * 4.0
    benchmark.extra_info["cycles"] = plan.info["cycles"]
    benchmark.extra_info["candidates_tried"] = plan.info["candidates_tried"]


def test_replay_loader_plan(benchmark):
    sc = pile(0, 4.0)
    plan = SinghCannonLoader().plan(sc)
    assert benchmark(judge, sc, plan).valid


def test_loader_bound_pile_4m3(benchmark):
    """The time-to-target bound runs in the scoring of every run: side by side with the bound
    before issue 49 (``n (t_c + t_d)``, a few µs), the meeting of loader, pile and truck."""
    from earthbench_metrics import lower_bound_time_to_target

    sc = pile(0, 4.0)
    assert benchmark(lower_bound_time_to_target, sc) > 25.0
