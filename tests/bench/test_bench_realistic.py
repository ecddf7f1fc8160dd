"""Speed of the realistic track (docs/DESIGN.md §5, §6).

Goals: slumping after a dig ≤ 5 ms on the 240 × 120 grid of paper-extensive; the referee's
replay of the same plan with soil ≤ 2 × without; a scan with occlusion ≤ 50 ms on the
paper-extensive map. Run with ``python -m pytest tests/bench/test_bench_realistic.py
--benchmark-only -s`` (``-s`` shows the ratio lines; they are also in ``extra_info``).

The ratio is measured side by side: each round judges the plan once without soil and once with
it, one right after the other, so both see the same load; the figure is the median of the
rounds' ratios, with their range and the machine's load average.
"""

from __future__ import annotations

import os
import statistics
import time

import numpy as np
import pytest

from earthbench import judge
from earthbench.cut import cut_along, cut_level, path_cells
from earthbench.sensing import observe
from earthbench.soil import draw, slump, slump_box
from earthbench.results.suite import load_suite
from earthbench.world import Sensing
from earthbench_planners.greedy.backhoe import GreedyPlanner
from earthbench_planners.singh_cannon.loader import SinghCannonLoader
from earthbench_terrains.pile import pile
from earthbench_terrains.rbf import rbf

ROUNDS = 21


@pytest.fixture(scope="module")
def backhoe_case():
    sc = rbf(0, 30 * 0.28 * 0.97, n_bases=30)  # the plan of tests/bench/test_bench_referee.py
    return sc, GreedyPlanner().plan(sc)


@pytest.fixture(scope="module")
def loader_case():
    sc = pile(0, 4.0)  # the plan of tests/bench/test_bench_referee.py
    return sc, SinghCannonLoader().plan(sc)


def _side_by_side(benchmark, capsys, sc, plan, material: str, label: str) -> float:
    """Judge ``plan`` without and with a ``material`` soil in each round; report the ratio of
    their times (median over the rounds) beside both medians. Returns the median ratio."""
    real = sc.replace(soil=draw({"material": material}, 0))
    exact_v, real_v = judge(sc, plan), judge(real, plan)  # warm: imports, caches
    assert len(real_v.digs) == len(exact_v.digs) > 0  # the same digs, judged on two grounds
    times: dict[str, list[float]] = {"none": [], material: []}

    def one_round() -> None:
        for key, scenario in (("none", sc), (material, real)):
            t0 = time.perf_counter()
            judge(scenario, plan)
            times[key].append(time.perf_counter() - t0)

    benchmark.pedantic(one_round, rounds=ROUNDS, iterations=1, warmup_rounds=1)
    for key in times:  # the warm-up round is not measured
        del times[key][:-ROUNDS]
    n = ROUNDS
    ratios = [b / a for a, b in zip(times["none"], times[material])]
    median = statistics.median(ratios)
    line = (f"{label}: replay without soil {statistics.median(times['none']) * 1e3:.2f} ms, with {material}"
            f" {statistics.median(times[material]) * 1e3:.2f} ms (medians of {n} rounds); ratio median {median:.2f}"
            f" (range {min(ratios):.2f}–{max(ratios):.2f}); load average {os.getloadavg()[0]:.2f}")
    benchmark.extra_info.update(ratio_median=round(median, 3), ratio_min=round(min(ratios), 3), ratio_max=round(max(ratios), 3),
                                none_ms=round(statistics.median(times["none"]) * 1e3, 3),
                                soil_ms=round(statistics.median(times[material]) * 1e3, 3), load=os.getloadavg()[0])
    with capsys.disabled():
        print("\n" + line)
    return median


def test_replay_30_digs_with_soil_against_without(benchmark, capsys, backhoe_case):
    sc, plan = backhoe_case
    assert sum(a.kind == "dig" for a in plan.actions) >= 29
    _side_by_side(benchmark, capsys, sc, plan, "loam", "30-dig backhoe plan")


def test_replay_loader_pile_with_soil_against_without(benchmark, capsys, loader_case):
    sc, plan = loader_case
    _side_by_side(benchmark, capsys, sc, plan, "sand", "loader plan on pile")


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
