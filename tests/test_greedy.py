"""The greedy baseline: valid plans that meet the target on rbf maps, exact predictions."""

from __future__ import annotations

import pytest

from earthbench import judge
from earthbench.scoring import evaluate
from metrics import lower_bound_time_per_m3
from planners.greedy import GreedyPlanner
from terrains.rbf import rbf


@pytest.mark.parametrize("seed", range(5))
def test_greedy_plans_are_valid_and_reach_the_target(seed):
    sc = rbf(seed, 4.0, n_bases=30)
    plan = GreedyPlanner().plan(sc)
    v = judge(sc, plan)
    m = evaluate(sc, plan, v)
    assert v.valid, v.violations
    assert m["volume_ratio"] >= 0.9
    assert m["success"]
    # the planner uses the referee's cut model, so its claim is exact
    assert m["volume_prediction_error"] == pytest.approx(0.0, abs=1e-9)
    assert m["makespan_prediction_error"] == pytest.approx(0.0, abs=1e-9)


def test_greedy_respects_the_truck_capacity():
    sc = rbf(1, 6.0, n_bases=30)
    sc = sc.replace(machines=sc.machines.__class__(truck=sc.machines.truck.__class__(capacity=1.0), truck_pose=sc.machines.truck_pose, excavator_pose=sc.machines.excavator_pose))
    v = judge(sc, GreedyPlanner().plan(sc))
    assert v.valid and v.loaded_volume == pytest.approx(1.0)


def test_greedy_config_is_hashed_and_bad_settings_are_named():
    from earthbench import PluginError

    assert GreedyPlanner().config_hash == GreedyPlanner().config_hash
    assert GreedyPlanner(min_fill=0.5).config_hash != GreedyPlanner().config_hash
    with pytest.raises(PluginError, match="min_fill"):
        GreedyPlanner(min_fil=0.5)


@pytest.mark.parametrize("seed", range(3))
def test_time_per_m3_never_beats_the_lower_bound(seed):
    sc = rbf(seed, 2.0, n_bases=14)
    plan = GreedyPlanner().plan(sc)
    m = evaluate(sc, plan, judge(sc, plan))
    assert m["time_per_m3"] >= lower_bound_time_per_m3(sc)
    assert m["time_per_m3_ratio"] >= 1.0
