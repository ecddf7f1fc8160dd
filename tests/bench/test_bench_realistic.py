"""Speed of the realistic track (docs/DESIGN.md §5, §6).

Goals: slumping after a dig ≤ 5 ms on the 240 × 120 grid of paper-extensive; the referee's
replay of the same plan with soil ≤ 2 × without; a scan with occlusion ≤ 50 ms on the
paper-extensive map. Run with ``pytest tests/bench/test_bench_realistic.py --benchmark-only``.
"""

from __future__ import annotations

import numpy as np
import pytest

from earthbench import judge
from earthbench.cut import cut_along, cut_level, path_cells
from earthbench.sensing import observe
from earthbench.soil import draw, slump, slump_box
from earthbench.suite import load_suite
from earthbench.world import Sensing
from planners.greedy import GreedyPlanner
from terrains.rbf import rbf


@pytest.fixture(scope="module")
def backhoe_case():
    sc = rbf(0, 30 * 0.28 * 0.97, n_bases=30)  # the plan of tests/bench/test_bench_referee.py
    return sc, GreedyPlanner().plan(sc)


@pytest.mark.parametrize("soil", ["none", "loam"])
def test_replay_30_digs(benchmark, backhoe_case, soil):
    sc, plan = backhoe_case
    if soil != "none":
        sc = sc.replace(soil=draw({"material": soil}, 0))
    verdict = benchmark(judge, sc, plan)
    assert len(verdict.digs) == sum(a.kind == "dig" for a in plan.actions)
    benchmark.extra_info["digs"] = len(verdict.digs)


def test_slump_after_one_dig_240x120(benchmark):
    sc = load_suite("paper-extensive").scenarios[0]
    assert sc.terrain.shape == (120, 240)
    soil = draw({"material": "sand"}, 0)
    contact, heading = (6.0, 3.0), 0.3
    z0 = np.array(sc.terrain.z)
    cells = path_cells(sc.terrain, z0.shape, contact, heading, 0.7, 1.0)
    box = slump_box(z0.shape, cells[0], cells[1], sc.terrain.resolution, 0.4, soil.repose_deg)
    before = z0[box[0]:box[1], box[2]:box[3]].copy()
    cut = z0.copy()
    cut_along(sc.terrain, cut, contact, heading, 0.7, 1.0, cut_level(sc.terrain, cut, contact, 0.4), 0.28, cells)

    def once():
        z = cut.copy()
        return slump(z, sc.terrain.resolution, soil.repose_deg, before, box)

    fell = benchmark(once)
    assert fell > 0.0
    benchmark.extra_info["fallen_m3"] = fell
    benchmark.extra_info["box"] = list(box)


def test_scan_with_occlusion_paper_extensive(benchmark):
    sc = load_suite("paper-extensive").scenarios[0]
    truth = sc.replace(sensing=Sensing(noise=0.03, bias=0.02, cell_size=0.1, occlusion=True, sensor_height=3.0))
    view = benchmark(observe, truth)
    assert view.terrain.shape == (60, 120)
