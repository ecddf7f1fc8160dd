"""Speed of the Singh–Cannon backhoe planner (issue 7).

Goals: the refined search over 200 candidates (one region: candidate grid, forward model,
Fig. 7 scores, choice and the exact workspace check of the winner) in a median under 20 ms;
a whole plan for a ``bench`` scenario under 5 s. Run with
``pytest tests/bench/test_bench_singh_cannon_backhoe.py --benchmark-only``; reported, not asserted.
"""

from __future__ import annotations

from earthbench import judge
from earthbench_planners.singh_cannon.backhoe import SinghCannonBackhoe
from earthbench_planners.singh_cannon.backhoe_model import candidate_grid, evaluate
from earthbench_terrains.bench import bench


def _session_and_region(seed: int = 0):
    ses = SinghCannonBackhoe().session(bench(seed, 8.0))
    regions = ses.coarse_plan(ses.base, ses.v_min)
    region = max(regions, key=lambda r: r.d_hi - r.d_lo)  # the longest radial search range
    return ses, region


def test_refined_search_200_candidates(benchmark):
    """One dig selection: 20 distances × 10 approach angles, scored, best chosen and checked."""
    ses, region = _session_and_region()
    ses.line(ses.base, region.bearing)  # the strip of a region is built once per coarse plan
    choice = benchmark(ses.refine, region, ses.base, ses.turn, ses.v_min)
    assert choice is not None and choice.volume >= 0.9 * ses.cap
    benchmark.extra_info["candidates"] = ses.model.n_d * ses.model.n_alpha


def test_refined_search_200_candidates_with_new_strip(benchmark):
    """The same, building the region's radial strip and workspace samples each time."""
    ses, region = _session_and_region()

    def search():
        ses._lines.clear()
        return ses.refine(region, ses.base, ses.turn, ses.v_min)

    assert benchmark(search) is not None


def test_forward_model_200_candidates(benchmark):
    """The vectorised forward model alone (swept volume, energy, time, quality of 200 candidates)."""
    ses, region = _session_and_region()
    line = ses.line(ses.base, region.bearing)
    d, a = candidate_grid(ses.model, ses.spec, region.d_lo, region.d_hi)
    cand = benchmark(evaluate, line, ses.z, d, a, ses.model, level_min=region.level_min, capacity=ses.cap, swing_time=0.0)
    assert cand.feasible.any()


def test_whole_plan_bench_8m3(benchmark):
    sc = bench(0, 8.0)
    plan = benchmark.pedantic(SinghCannonBackhoe().plan, args=(sc,), rounds=5, iterations=1)
    assert judge(sc, plan).valid
    benchmark.extra_info["digs"] = sum(a.kind == "dig" for a in plan.actions)
