"""Reading plans and scenarios: round trips, and clear errors that name the action and field."""

from __future__ import annotations

import json
import math

import pytest
from helpers import block_scenario

from earthbench import Plan, PlanFormatError, Scenario, ScenarioError, judge
from earthbench_terrains.rbf import rbf


def test_plan_round_trip(valid_plan):
    again = Plan.from_json(valid_plan.to_json())
    assert again == valid_plan


def test_scenario_round_trip_keeps_the_digest(tmp_path):
    sc = rbf(3, 2.0, n_bases=30)
    path = tmp_path / "s.json"
    sc.to_json(path)
    again = Scenario.from_json(path)
    assert again == sc and again.digest == sc.digest
    assert again.terrain.z.dtype == sc.terrain.z.dtype


def test_digest_ignores_labels_but_not_content():
    sc = rbf(1, 2.0)
    assert sc.replace(id="other", meta={"x": 1}).digest == sc.digest
    assert sc.replace(task=sc.task.__class__(2.5)).digest != sc.digest
    assert rbf(2, 2.0).digest != sc.digest


def good_doc(valid_plan) -> dict:
    return json.loads(valid_plan.to_json())


@pytest.mark.parametrize(
    "mutate, words",
    [
        (lambda d: d["actions"][0].update(type="teleport"), ["action 0", "unknown type", "teleport"]),
        (lambda d: d["actions"][0].pop("depth"), ["action 0 (dig)", "missing field 'depth'"]),
        (lambda d: d["actions"][0].update(depth=math.nan), ["action 0 (dig)", "'depth'", "finite"]),
        (lambda d: d["actions"][1].update(t_start=-1.0), ["action 1 (dump)", "'t_start'", "negative"]),
        (lambda d: d["actions"][1].update(t_end=0.5), ["action 1 (dump)", "before t_start"]),
        (lambda d: d["actions"][0].update(contact=[1.0]), ["action 0 (dig)", "'contact'", "2 numbers"]),
        (lambda d: d["actions"][0].update(machine=7), ["action 0 (dig)", "'machine'"]),
        (
            lambda d: d["actions"].append({"type": "move", "machine": "truck", "path": [[0, 9, 9, 0], [0, 9, 9, 0]]}),
            ["action 2 (move) sample 1", "increase"],
        ),
        (lambda d: d.update(schema="earthbench.plan/0"), ["schema"]),
        (lambda d: d.update(actions={}), ["'actions'", "list"]),
    ],
)
def test_malformed_plans_get_clear_errors_and_an_invalid_verdict(valid_plan, mutate, words):
    doc = good_doc(valid_plan)
    mutate(doc)
    with pytest.raises(PlanFormatError) as err:
        Plan.from_dict(doc)
    for w in words:
        assert w in str(err.value)
    v = judge(block_scenario(), doc)
    assert not v.valid and v.violations[0].rule == "malformed"
    assert str(err.value) == v.violations[0].message


def test_not_json_is_an_invalid_verdict_not_a_crash():
    v = judge(block_scenario(), "{not json")
    assert not v.valid and "not valid JSON" in v.violations[0].message


def test_plan_built_in_code_with_nan_is_judged_malformed(valid_plan):
    dig = valid_plan.actions[0]
    bad = Plan((dig.__class__(dig.machine, dig.t_start, dig.t_end, dig.contact, math.nan, dig.depth, dig.drag_length),))
    v = judge(block_scenario(), bad)
    assert [x.rule for x in v.violations] == ["malformed"]


@pytest.mark.parametrize(
    "mutate, words",
    [
        (lambda d: d["terrain"].update(z=[[1.0, math.nan], [1.0, 1.0]]), ["NaN"]),
        (lambda d: d["terrain"].update(z=[1.0, 2.0]), ["2-D"]),
        (lambda d: d["task"].update(target_volume=-1), ["target_volume", "positive"]),
        (lambda d: d.pop("site"), ["malformed scenario", "site"]),
        (lambda d: d.update(track="dozer"), ["track"]),
    ],
)
def test_malformed_scenarios_get_clear_errors(mutate, words):
    d = block_scenario().to_dict()
    mutate(d)
    with pytest.raises(ScenarioError) as err:
        Scenario.from_dict(json.loads(json.dumps(d)))
    for w in words:
        assert w in str(err.value)
