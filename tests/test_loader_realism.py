"""The wheel-loader planners on the realistic track (issue 39): they read a scan's noise and
bias from the scan itself, and their plans made on a noisy, occluded cab scan with a soil class
are valid on the truth, open and closed loop."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from earthbench import judge
from earthbench.running.harness.steps import run_closed_loop
from earthbench.results.scoring import evaluate
from earthbench.sensing import observe
from earthbench.soil import MATERIALS, draw, fill_range
from earthbench.world import Scenario, Sensing
from earthbench_planners.greedy.loader import GreedyLoader
from earthbench_planners.loader_cycle import read_scan
from earthbench_planners.singh_cannon.loader import SinghCannonLoader
from earthbench_planners.strip_loader.planner import StripLoader
from earthbench_terrains.pile import pile

CAB = Sensing(noise=0.03, bias=0.02, cell_size=0.1, occlusion=True, sensor_height=3.0, seed=11)


def cab_site(seed: int, target: float, soil: dict) -> Scenario:
    """A pile scenario (not one of the suite's seeds) scanned from the cab, with a soil class."""
    return pile(seed, target).replace(soil=draw(soil, seed), sensing=CAB)


def test_read_scan_measures_a_cab_scans_noise_and_bias_and_keeps_the_floor_flat():
    truth = cab_site(11, 2.0, {"material": "loam"})
    view = observe(truth)
    g = read_scan(view.terrain, 0.0, 0.02)
    assert g.noise == pytest.approx(0.03, rel=0.15)
    assert g.offset == pytest.approx(0.02, abs=0.008)
    assert g.level >= 0.02
    # the open ground around the loader and the truck reads as the floor, not as material
    xs, ys = view.terrain.cell_centres()
    near = np.hypot(xs[None, :] - 8.0, ys[:, None] - 5.0) < 2.0
    assert np.all(g.z[near] == 0.0)
    assert np.all(view.terrain.z[near] != 0.0)  # while the raw scan is noisy there


def test_read_scan_leaves_exact_ground_as_it_is():
    sc = pile(11, 2.0)
    g = read_scan(sc.terrain, 0.0, 0.02)
    assert g.offset == 0.0 and g.margin == 0.0 and g.level == 0.02
    assert np.array_equal(g.z, sc.terrain.z)


@pytest.mark.parametrize("planner", [GreedyLoader, SinghCannonLoader])
def test_open_loop_plan_on_a_noisy_cab_scan_is_valid_on_the_truth(planner):
    truth = cab_site(12, 2.0, {"material": "clay"})
    plan = planner().plan(observe(truth))
    v = judge(truth, plan)
    assert v.valid, v.violations[:3]
    assert evaluate(truth, plan, v)["success"]


@pytest.mark.parametrize("planner", [GreedyLoader, SinghCannonLoader])
def test_closed_loop_digs_on_when_charges_come_back_short(planner):
    # the site's bank fill is far below the class's nominal one: every charge delivers about
    # two thirds of what the planner expects, and the truck still gets its target
    truth = cab_site(13, 2.0, {"material": "loam", "fill_factor": 0.55})
    p = planner(planner.Config(closed_loop=True))
    plan = run_closed_loop(p, truth)
    v = judge(truth, plan)
    assert v.valid, v.violations[:3]
    assert v.loaded_volume >= 0.9 * truth.task.target_volume
    assert len(v.digs) >= 4  # 2 m³ at 0.55 × 0.8 m³ a charge at most: at least four charges


def _pile_20t_clay() -> Scenario:
    from earthbench.results.suite import load_suite

    return next(sc for sc in load_suite("pile-20t-realistic").scenarios if sc.id == "pile-20t-realistic/pile-clay-survey/s4/v8")


@pytest.mark.parametrize(("planner", "fullest"), [(GreedyLoader, False), (SinghCannonLoader, False), (StripLoader, False),
                                                  (GreedyLoader, True)])
def test_open_loop_never_charges_after_a_dump_that_may_have_filled_the_truck(planner, fullest):
    # the 20t class's truck holds 8.1-8.8 bank m³ of clay and the target is 8: charges that
    # deliver more than the planner expects fill it before the plan thinks it is done, and a
    # charge after that dump starts with soil in the bucket (bucket_not_empty). The planner
    # bounds what its charges may deliver by the class's fullest bucket and largest swell.
    truth = _pile_20t_clay()
    if fullest:  # the worst site the class allows: the fullest buckets, the smallest truck
        lo, hi = fill_range("clay", "20t")
        truth = truth.replace(soil=dataclasses.replace(truth.soil, fill_factor=round(hi, 6), swell=MATERIALS["clay"].swell[1]))
    plan = planner().plan(observe(truth))
    v = judge(truth, plan)
    assert v.valid, v.violations[:3]
    assert evaluate(truth, plan, v)["success"]
