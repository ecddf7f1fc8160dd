"""Greedy with rollouts (the best known plans' witness): valid, and never later to the target than greedy."""

from __future__ import annotations

import pytest

from earthbench import judge
from earthbench.results.scoring import evaluate
from earthbench_planners.greedy.backhoe import GreedyConfig, GreedyPlanner
from earthbench_planners.greedy.rollout import RolloutSession, rollout_plan
from earthbench_terrains.rbf import rbf


@pytest.mark.parametrize("seed", [0, 3])
def test_the_rollout_plan_is_valid_and_no_later_than_greedys(seed):
    sc = rbf(seed, 4.0, n_bases=30)
    plan, rollouts = rollout_plan(sc)
    v = judge(sc, plan)
    m = evaluate(sc, plan, v)
    g = GreedyPlanner().plan(sc)
    mg = evaluate(sc, g, judge(sc, g))
    assert v.valid, v.violations
    assert m["success"] and rollouts > 2
    assert m["time_to_target_s"] <= mg["time_to_target_s"] + 1e-9
    # the session's own model is the referee's on the exact track: what it chose by is what is scored
    assert m["volume_prediction_error"] == pytest.approx(0.0, abs=1e-9)


def test_a_copy_played_out_decides_as_greedy_does():
    """A session marked ``inner`` is greedy itself: the same plan, action for action."""
    sc = rbf(1, 4.0, n_bases=30)
    inner = RolloutSession(sc, GreedyConfig())
    inner.inner = True
    assert inner.run().actions == GreedyPlanner().plan(sc).actions
    assert inner.outcome()[0] == max(t for t, _ in inner.curve)
