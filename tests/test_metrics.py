"""Per-run metrics and the time-per-m³ lower bound."""

from __future__ import annotations

import math

import pytest
from helpers import block_scenario, dig_dump_plan
from hypothesis import given, settings
from hypothesis import strategies as st

from earthbench import Dig, Dump, Plan, Prediction, judge
from earthbench.motion import swing_time
from earthbench.results.scoring import evaluate
from earthbench_metrics import lower_bound_time_per_m3


def test_metrics_of_one_bucket():
    sc = block_scenario(target=0.56)
    plan = Plan(tuple(dig_dump_plan()), Prediction(volume=0.3, makespan=5.0))
    m = evaluate(sc, plan, judge(sc, plan))
    assert m["volume_ratio"] == pytest.approx(0.5)
    assert m["time_per_m3"] == pytest.approx(plan.actions[-1].t_end / 0.28)
    assert m["digs"] == 1 and m["dumps"] == 1 and m["mean_bucket_fill"] == pytest.approx(1.0)
    assert m["volume_prediction_error"] == pytest.approx(0.02)
    assert m["makespan_prediction_error"] == pytest.approx(5.0 - plan.actions[-1].t_end)
    assert not m["success"]  # valid but only half the target
    assert m["solve_time_s"] is None  # the harness fills it


def test_nothing_loaded_means_infinite_time_per_m3():
    sc = block_scenario()
    m = evaluate(sc, Plan(), judge(sc, Plan()))
    assert m["time_per_m3"] == math.inf and m["volume_ratio"] == 0.0 and not m["success"]


def test_invalid_plans_never_succeed():
    sc = block_scenario(target=0.28)
    plan = Plan(tuple(dig_dump_plan(depth=0.45)))
    m = evaluate(sc, plan, judge(sc, plan))
    assert m["volume_ratio"] >= 0.9 and not m["valid"] and not m["success"]


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(1.5, 6.5), st.floats(0.5, 4.5)), min_size=1, max_size=8), st.floats(0.0, 5.0))
def test_the_lower_bound_holds_for_any_valid_sequence_of_buckets(contacts, slack):
    """Dig-dump cycles at minimum durations anywhere in reach: never faster than the bound."""
    sc = block_scenario(target=1.0, floor=None)  # repeated digs in one spot may go deep
    spec, base, truck = sc.machines.excavator, sc.machines.excavator_pose, (9.0, 9.0)
    acts, t, turn = [], 0.0, 0.0
    for c in contacts:
        if not (spec.reach_min + 1.0 <= math.dist(c, (base.x, base.y)) <= spec.reach_max):
            continue
        heading = math.atan2(base.y - c[1], base.x - c[0])
        d = swing_time(base, turn, c, spec) + spec.min_stroke_time + 1e-6 + slack
        acts.append(Dig("excavator", t, t + d, c, heading, 0.4, 1.0))
        t += d
        turn = math.atan2(c[1] - base.y, c[0] - base.x) - base.yaw
        d = swing_time(base, turn, truck, spec) + spec.min_dump_time + 1e-6
        acts.append(Dump("excavator", t, t + d))
        t += d
        turn = math.atan2(truck[1] - base.y, truck[0] - base.x) - base.yaw
    plan = Plan(tuple(acts))
    v = judge(sc, plan)
    assert v.valid, v.violations
    if v.loaded_volume > 0:
        assert v.makespan / v.loaded_volume >= lower_bound_time_per_m3(sc) - 1e-9
