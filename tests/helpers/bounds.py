"""The bound's property, shared by the backhoe's and the wheel loader's hypothesis tests."""

from __future__ import annotations

import math

import pytest
from hypothesis import assume, event

from earthbench import Plan, Scenario, judge
from earthbench.results.scoring import evaluate, time_to_target
from earthbench_metrics import lower_bound_time_to_target


def assert_no_valid_plan_beats_the_bound(sc: Scenario, plan: Plan, target: float) -> None:
    """A valid ``plan`` reaches ``target`` no sooner than the lower bound, and its metrics say so
    (an invalid one is no example: hypothesis draws another)."""
    v = judge(sc, plan)
    assume(v.valid)
    ttt = time_to_target(v.load_curve, target)
    event("reaches the target" if math.isfinite(ttt) else "short of the target")
    bound = lower_bound_time_to_target(sc)
    assert ttt >= bound - 1e-9
    m = evaluate(sc, plan, v)
    assert m["time_per_target_m3_lower_bound"] == pytest.approx(bound / target)
    assert not m["time_per_target_m3_bound_ratio"] < 1.0
