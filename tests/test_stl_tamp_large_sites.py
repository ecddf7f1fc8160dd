"""stl-tamp 0.12.1 on a site larger than the truck's reach (planners/stl_tamp/NOTES.md, "0.12.1"):
areas without a truck stand are passed over once they have proved hopeless, on a real solve."""

from __future__ import annotations

import dataclasses

import pytest

from earthbench.referee import judge
from earthbench.results.suite import load_suite
from earthbench_planners.stl_tamp import StlTampPlanner


@pytest.fixture(scope="module")
def large_site():
    """``scale``'s 24 × 12 m rbf map, seed 1 (four global windows), at 8 m³ instead of 16: the truck
    drives straight along one long side, so the areas beyond dump reach of it have no stand."""
    sc = next(s for s in load_suite("scale").scenarios if s.id == "scale/rbf24x12/s1/v16")
    return dataclasses.replace(sc, task=dataclasses.replace(sc.task, target_volume=8.0))


@pytest.mark.slow
def test_areas_without_a_truck_stand_are_passed_over_once_they_have_failed(large_site):
    """With ``standless_tries=3`` (the default, 8, leaves room for the 20-t class's sites, where
    such areas load after up to seven fruitless visits, and does not bind on a case this small), three such areas dig nothing,
    then the rest are passed over unsolved and undriven to: the plan keeps every rule, reaches the
    target and drives the excavator less. 0.12.0's behaviour (``standless_tries=0``) keeps solving
    them and driving there for nothing."""
    plan = StlTampPlanner(StlTampPlanner.Config(standless_tries=3)).plan(large_site)
    v = judge(large_site, plan)
    assert v.valid, v.violations[:3]
    assert v.loaded_volume == pytest.approx(8.0, rel=0.01)
    assert plan.info["standless"]["dug"] == 0 and plan.info["standless"]["fruitless"] == 3
    assert plan.info["standless"]["passed_over"] > 0

    old = StlTampPlanner(StlTampPlanner.Config(standless_tries=0)).plan(large_site)
    w = judge(large_site, old)
    assert w.valid and w.loaded_volume == pytest.approx(8.0, rel=0.01)
    assert old.info["standless"]["passed_over"] == 0
    assert old.info["standless"]["fruitless"] > 3
    assert v.travel["excavator"] < w.travel["excavator"]
    assert max(a.t_end for a in plan.actions) < max(a.t_end for a in old.actions)


def test_a_site_where_areas_without_a_stand_dig_is_never_given_up():
    """Hopeless at ``tries`` × (1 + the visits that dug) fruitless visits: a site where the NLP's
    truck serves such areas keeps solving them (the 20-t class's sites load from them)."""
    from earthbench_planners.stl_tamp.hierarchy import Standless

    s = Standless(fruitless=5, dug=1)
    assert not s.hopeless(3)
    s.visited(dug=False)
    assert s.hopeless(3)
    assert not s.hopeless(0)
