"""Wheel-loader rules of the referee: every rule passing and failing, plus the loader's model.

The site (20 m × 12 m, 0.1 m cells, floor 0): a 1 m high block of material east of x = 14. The
loader starts at (12.8, 5) facing east, so its bucket edge (1.2 m ahead) touches the face.
The truck stands at (9.2, 8.8). A valid cycle: charge 0.4 m (4 columns × 18 rows of cells =
0.72 m³), reverse on a quarter circle of radius 4 m to (9.2, 1) facing north, drive north to
(9.2, 6.0) — 2.8 m from the truck, the bucket edge 0.6 m from its loading circle — and dump.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from earthbench import Budget, Charge, Dig, Dump, Heightmap, Machines, Move, Plan, Pose, Scenario, Site, Task, judge
from earthbench.errors import PlanFormatError
from earthbench.cut import apply_cut, charge_cut
from earthbench.world import LoaderSpec
from earthbench.results.scoring import evaluate
from earthbench_metrics import lower_bound_time_per_m3

START = Pose(12.8, 5.0, 0.0)
TRUCK = Pose(9.2, 8.8, 0.0)


def loader_scenario(truck: Pose = TRUCK, start: Pose = START, floor: float | None = 0.0, open_outside: bool = True, **spec) -> Scenario:
    z = np.zeros((120, 200))
    z[:, 140:] = 1.0
    return Scenario(
        id="test/loader-block",
        terrain=Heightmap((0.0, 0.0), 0.1, z),
        site=Site(((0, 0), (20, 0), (20, 12), (0, 12)), floor=floor, open_outside=open_outside),
        machines=Machines(excavator=None, excavator_pose=None, loader=LoaderSpec(**spec), loader_pose=start, truck_pose=truck),
        task=Task(0.7),
        track="wheel_loader",
        budget=Budget(wall_s=60),
    )


def arc(start: tuple[float, float, float], curvature: float, length: float, t0: float, speed: float = 1.0, n: int = 24) -> Move:
    """A move along an arc of signed ``length`` (negative: in reverse) from ``start``."""
    x0, y0, th0 = start
    s = np.linspace(0.0, length, n + 1)
    if abs(curvature) < 1e-12:
        x, y, th = x0 + s * math.cos(th0), y0 + s * math.sin(th0), np.full_like(s, th0)
    else:
        th = th0 + curvature * s
        x = x0 + (np.sin(th) - math.sin(th0)) / curvature
        y = y0 - (np.cos(th) - math.cos(th0)) / curvature
    t = t0 + np.abs(s) / speed
    return Move("loader", tuple((float(a), float(b), float(c), float(d)) for a, b, c, d in zip(t, x, y, th)))


def cycle(
    penetration: float = 0.4, radius: float = 4.0, dump_y: float = 6.0, dump_time: float = 3.0, charge_time: float | None = None
) -> list:
    """Charge, reverse on a quarter circle, drive north to ``dump_y`` and dump; times from 0."""
    dur = charge_time if charge_time is not None else max(2.0, penetration / 0.5) + 1e-6
    c = Charge("loader", 0.0, dur, (START.x, START.y, START.yaw), penetration)
    x1, y1, _ = c.end
    back = arc((x1, y1, 0.0), -1.0 / radius, -radius * math.pi / 2, dur)
    _, _, bx, by, byaw = (0, *back.path[-1])
    fwd = arc((bx, by, byaw), 0.0, dump_y - by, back.t_end)
    return [c, back, fwd, Dump("loader", fwd.t_end, fwd.t_end + dump_time)]


def rules(v) -> set[str]:
    return {x.rule for x in v.violations}


# -- the valid cycle --------------------------------------------------------------------------

def test_a_charge_dump_cycle_is_valid_and_loads_the_cut_volume():
    sc = loader_scenario()
    v = judge(sc, Plan(tuple(cycle())))
    assert v.valid, v.violations
    assert v.loaded_volume == pytest.approx(0.72, abs=1e-9)
    assert v.removed_volume == pytest.approx(0.72, abs=1e-9)
    assert v.digs[0].fill == pytest.approx(0.9)
    # the cut: exactly the 4 columns east of the face, 18 rows centred on y = 5
    cut = np.array(sc.terrain.z) - v.final_terrain.z
    assert cut.sum() == pytest.approx(72.0)
    assert np.all(cut[41:59, 140:144] == 1.0)


def test_the_loader_lower_bound_and_metrics_hold_for_the_cycle():
    sc = loader_scenario()
    plan = Plan(tuple(cycle()))
    m = evaluate(sc, plan, judge(sc, plan))
    bound = lower_bound_time_per_m3(sc)
    assert bound == pytest.approx((2.0 + 3.0) / 0.8)
    assert m["valid"] and m["time_per_m3"] >= bound
    assert m["digs"] == 1 and m["dumps"] == 1


@pytest.mark.parametrize("pens", [(0.4, 0.1), (0.2, 0.3, 0.05), (0.45,), (0.44, 0.44, 0.44)])
def test_the_loader_bound_holds_for_repeated_minimal_charges_and_dumps(pens):
    """Charges and dumps at their minimum durations, back to back: the tightest valid plan."""
    sc = loader_scenario(dump_reach=50.0, clearance=0.0)  # dumping from anywhere in front
    acts, t, x = [], 0.0, START.x
    for p in pens:
        d = max(2.0, p / 0.5) + 1e-9
        acts.append(Charge("loader", t, t + d, (x, START.y, 0.0), p))
        x, t = x + p, t + d
        acts.append(Dump("loader", t, t + 3.0))
        t += 3.0
    sc = sc.replace(
        machines=Machines(
            excavator=None, excavator_pose=None, loader=sc.machines.loader, loader_pose=START, truck_pose=Pose(19.0, 5.0, 0.0)
        )
    )
    v = judge(sc, Plan(tuple(acts)))
    assert v.valid, v.violations
    assert v.makespan / v.loaded_volume >= lower_bound_time_per_m3(sc) - 1e-9


def test_charge_cut_is_apply_cut_from_the_bucket_edge():
    sc = loader_scenario()
    spec = sc.machines.loader
    z1, z2 = np.array(sc.terrain.z), np.array(sc.terrain.z)
    a = charge_cut(sc.terrain, z1, spec, (12.8, 5.0, 0.0), 2.0, 0.0, 0.8)
    b = apply_cut(sc.terrain, z2, (14.0, 5.0), 0.0, 1.8, 2.0, 0.0, 0.8)
    assert a == b == pytest.approx(0.8)
    assert np.array_equal(z1, z2)


# -- charge rules -----------------------------------------------------------------------------

def test_charge_by_a_machine_that_is_not_a_loader_is_wrong_machine():
    sc = loader_scenario()
    v = judge(sc, Plan((Charge("truck", 0.0, 3.0, (TRUCK.x, TRUCK.y, TRUCK.yaw), 0.5),)))
    assert "wrong_machine" in rules(v)


def test_a_loader_cannot_dig_like_a_backhoe():
    v = judge(loader_scenario(), Plan((Dig("loader", 0.0, 5.0, (14.5, 5.0), math.pi, 0.2, 0.5),)))
    assert rules(v) == {"wrong_machine"}


def test_charge_must_start_at_the_loaders_pose():
    sc = loader_scenario()
    ok = judge(sc, Plan((Charge("loader", 0.0, 2.0, (12.8, 5.0, 0.0), 0.4),)))
    assert ok.valid, ok.violations
    off = judge(sc, Plan((Charge("loader", 0.0, 2.0, (12.8, 5.1, 0.0), 0.4),)))
    assert rules(off) == {"entry_pose"}
    turned = judge(sc, Plan((Charge("loader", 0.0, 2.0, (12.8, 5.0, 0.05), 0.4),)))
    assert rules(turned) == {"entry_pose"}


def test_charge_speed_is_limited_by_the_penetration_speed():
    sc = loader_scenario()
    ok = judge(sc, Plan((Charge("loader", 0.0, 2.0, (12.8, 5.0, 0.0), 1.0),)))  # 0.5 m/s exactly
    assert "penetration_speed" not in rules(ok)
    fast = judge(sc, Plan((Charge("loader", 0.0, 1.9, (12.8, 5.0, 0.0), 1.0),)))
    assert "penetration_speed" in rules(fast)


def test_charge_lasts_at_least_the_minimum_charge_time():
    sc = loader_scenario()
    assert judge(sc, Plan((Charge("loader", 0.0, 2.0, (12.8, 5.0, 0.0), 0.2),))).valid
    short = judge(sc, Plan((Charge("loader", 0.0, 1.9, (12.8, 5.0, 0.0), 0.2),)))
    assert rules(short) == {"duration"}


def test_charge_needs_an_empty_bucket():
    sc = loader_scenario()
    c1 = Charge("loader", 0.0, 2.0, (12.8, 5.0, 0.0), 0.2)
    c2 = Charge("loader", 2.0, 4.0, (13.0, 5.0, 0.0), 0.2)
    v = judge(sc, Plan((c1, c2)))
    assert rules(v) == {"bucket_not_empty"}
    d = Dump("loader", 2.0, 5.0)
    c2b = Charge("loader", 5.0, 7.0, (13.0, 5.0, 0.0), 0.2)
    v = judge(
        sc.replace(
            machines=Machines(
                excavator=None,
                excavator_pose=None,
                loader=LoaderSpec(dump_reach=50.0, clearance=0.0),
                loader_pose=START,
                truck_pose=Pose(19.0, 5.0, 0.0),
            )
        ),
        Plan((c1, d, c2b)),
    )
    assert v.valid, v.violations


def test_charge_fills_up_to_capacity_and_pushing_on_into_material_is_overfill():
    sc = loader_scenario()
    # 0.44 m: the edge sweeps 4 columns (0.72 m³) and the axle stays on cut ground
    ok = judge(sc, Plan((Charge("loader", 0.0, 2.0, (12.8, 5.0, 0.0), 0.44),)))
    assert ok.valid and ok.digs[0].volume == pytest.approx(0.72)
    # 2.0 m: the bucket is full after 0.8 m³; the edge pushes on through material it cannot
    # take, and the wheels then drive onto uncut material
    over = judge(sc, Plan((Charge("loader", 0.0, 4.0, (12.8, 5.0, 0.0), 2.0),)))
    assert over.digs[0].volume == pytest.approx(0.8)
    assert rules(over) == {"overfill", "step"}


def test_charge_path_must_stay_in_the_dig_area():
    sc = loader_scenario()
    sc = sc.replace(site=Site(((0, 0), (14.3, 0), (14.3, 12), (0, 12)), floor=0.0))
    assert judge(sc, Plan((Charge("loader", 0.0, 2.0, (12.8, 5.0, 0.0), 0.3),))).valid
    v = judge(sc, Plan((Charge("loader", 0.0, 2.0, (12.8, 5.0, 0.0), 0.4),)))
    assert rules(v) == {"outside_dig_area"}


# -- move rules -------------------------------------------------------------------------------

def test_loader_moves_keep_the_minimum_turning_radius():
    sc = loader_scenario()
    ok = judge(sc, Plan((arc((12.8, 5.0, 0.0), -1 / 3.5, -3.0, 0.0),)))
    assert ok.valid, ok.violations
    tight = judge(sc, Plan((arc((12.8, 5.0, 0.0), -1 / 3.3, -3.0, 0.0),)))
    assert rules(tight) == {"turning_radius"}


def test_a_loader_cannot_turn_in_place():
    sc = loader_scenario()
    v = judge(sc, Plan((Move("loader", ((0.0, 12.8, 5.0, 0.0), (5.0, 12.8, 5.0, 0.5))),)))
    assert rules(v) == {"turning_radius"}


def test_loader_moves_respect_speed_and_heading_limits():
    sc = loader_scenario()
    fast = judge(sc, Plan((arc((12.8, 5.0, 0.0), 0.0, -4.0, 0.0, speed=2.1),)))
    assert rules(fast) == {"speed"}
    side = judge(sc, Plan((Move("loader", ((0.0, 12.8, 5.0, 0.0), (2.0, 12.8, 4.0, 0.0))),)))
    assert "heading" in rules(side)


def test_loader_moves_never_cross_a_cell_higher_than_the_step():
    sc = loader_scenario()
    ok = judge(sc, Plan((arc((12.8, 5.0, 0.0), 0.0, 1.15, 0.0),)))  # axle stops 0.05 m short of the face
    assert ok.valid, ok.violations
    into = judge(sc, Plan((arc((12.8, 5.0, 0.0), 0.0, 1.3, 0.0),)))
    assert rules(into) == {"step"}


def test_a_low_ramp_within_the_step_is_traversable():
    sc = loader_scenario()
    z = np.array(sc.terrain.z)
    z[:, 140:] = 0.15
    assert judge(sc.replace(terrain=sc.terrain.with_z(z)), Plan((arc((12.8, 5.0, 0.0), 0.0, 3.0, 0.0),))).valid
    z[:, 140:] = 0.16
    assert rules(judge(sc.replace(terrain=sc.terrain.with_z(z)), Plan((arc((12.8, 5.0, 0.0), 0.0, 3.0, 0.0),)))) == {"step"}


def test_without_a_floor_the_step_is_measured_from_the_ground_under_the_start():
    sc = loader_scenario(floor=None)
    z = np.array(sc.terrain.z) + 3.0
    sc = sc.replace(terrain=sc.terrain.with_z(z))
    assert judge(sc, Plan((arc((12.8, 5.0, 0.0), 0.0, 1.15, 0.0),))).valid
    assert rules(judge(sc, Plan((arc((12.8, 5.0, 0.0), 0.0, 1.3, 0.0),)))) == {"step"}


def test_the_loader_keeps_its_clearance_from_the_truck():
    assert judge(loader_scenario(), Plan(tuple(cycle(dump_y=6.0)))).valid
    v = judge(loader_scenario(), Plan(tuple(cycle(dump_y=6.4))))
    assert "collision" in rules(v)


# -- dump rules -------------------------------------------------------------------------------

def test_loader_dump_needs_the_truck_within_reach():
    v = judge(loader_scenario(), Plan(tuple(cycle(dump_y=5.7))))  # edge 0.9 m from the loading circle
    assert v.valid, v.violations
    far = judge(loader_scenario(), Plan(tuple(cycle(dump_y=5.5))))  # 1.1 m
    assert rules(far) == {"dump_reach"}
    assert far.loaded_volume > 0  # reported, but the plan is invalid


def test_loader_dump_needs_the_truck_in_front():
    acts = cycle()
    truck = Pose(11.0, 7.6, 0.0)  # 48° off the heading, bucket edge 0.84 m from the loading circle
    v = judge(loader_scenario(truck=truck, clearance=1.5), Plan(tuple(acts)))
    assert rules(v) == {"dump_reach"}
    truck = Pose(10.6, 7.8, 0.0)  # 33° off
    assert judge(loader_scenario(truck=truck, clearance=1.5), Plan(tuple(acts))).valid


def test_loader_dump_lasts_at_least_the_dump_time():
    v = judge(loader_scenario(), Plan(tuple(cycle(dump_time=2.9))))
    assert rules(v) == {"duration"}


def test_loader_dump_needs_the_truck_still():
    acts = cycle()
    d = acts[-1]
    truck_move = Move("truck", ((d.t_start + 0.5, TRUCK.x, TRUCK.y, 0.0), (d.t_start + 1.5, TRUCK.x + 0.5, TRUCK.y, 0.0)))
    v = judge(loader_scenario(), Plan(tuple(acts) + (truck_move,)))
    assert rules(v) == {"truck_moving"}
    later = Move("truck", ((d.t_end, TRUCK.x, TRUCK.y, 0.0), (d.t_end + 1.0, TRUCK.x + 0.5, TRUCK.y, 0.0)))
    assert judge(loader_scenario(), Plan(tuple(acts) + (later,))).valid


# -- model and format -------------------------------------------------------------------------

def test_loader_scenario_round_trips_through_json():
    sc = loader_scenario()
    back = Scenario.from_json(sc.to_json())
    assert back == sc and back.digest == sc.digest
    assert back.machines.loader == LoaderSpec() and back.machines.ids == ("loader", "truck")
    assert back.machines.pose("loader") == START


def test_scenarios_without_a_loader_keep_their_json_form():
    from helpers import block_scenario

    sc = block_scenario()
    doc = json.loads(sc.to_json())
    assert "loader" not in doc["machines"] and "loader_pose" not in doc["machines"]
    assert Scenario.from_json(sc.to_json()).digest == sc.digest


def test_a_wheel_loader_scenario_needs_a_loader_and_its_pose():
    from earthbench.errors import ScenarioError

    with pytest.raises(ScenarioError):
        Machines(loader=LoaderSpec(), loader_pose=None)
    sc = loader_scenario()
    with pytest.raises(ScenarioError):
        sc.replace(machines=Machines())


def test_charge_round_trips_and_malformed_charges_are_rejected():
    plan = Plan(tuple(cycle()))
    back = Plan.from_json(plan.to_json())
    assert back == plan
    doc = {
        "schema": "earthbench.plan/1",
        "actions": [{"type": "charge", "machine": "loader", "t_start": 0, "t_end": 2, "entry": [1, 2, 0], "penetration": 1.0}],
    }
    assert isinstance(Plan.from_dict(doc).actions[0], Charge)
    for bad in ({"entry": [1, 2]}, {"penetration": -1.0}, {"penetration": float("nan")}, {"entry": [1, 2, "x"]}):
        d = json.loads(json.dumps(doc))
        d["actions"][0].update(bad)
        with pytest.raises(PlanFormatError):
            Plan.from_dict(d)
    d = json.loads(json.dumps(doc))
    del d["actions"][0]["penetration"]
    with pytest.raises(PlanFormatError):
        Plan.from_dict(d)
    assert rules(judge(loader_scenario(), d)) == {"malformed"}


# -- properties -------------------------------------------------------------------------------



@settings(max_examples=40, deadline=None)
@given(
    radius=st.floats(3.5, 40.0),
    sign=st.sampled_from([1.0, -1.0]),
    length=st.floats(0.5, 4.0),
    reverse=st.booleans(),
    n=st.integers(2, 40),
)
def test_any_arc_at_or_above_the_minimum_radius_is_accepted_on_open_ground(radius, sign, length, reverse, n):
    start = (7.0, 3.0, math.pi + 0.3)  # facing away from the pile, 7 m behind (its wheels 5 m)
    sc = loader_scenario(start=Pose(*start), truck=Pose(-30.0, -30.0, 0.0))  # the truck far out of the way
    move = arc(start, sign / radius, -length if reverse else length, 0.0, speed=1.0, n=n)
    v = judge(sc, Plan((move,)))
    assert v.valid, v.violations


@settings(max_examples=40, deadline=None)
@given(radius=st.floats(0.5, 3.45), sign=st.sampled_from([1.0, -1.0]), n=st.integers(1, 30))
def test_any_arc_tighter_than_the_minimum_radius_is_flagged(radius, sign, n):
    start = (7.0, 3.0, math.pi + 0.3)
    sc = loader_scenario(start=Pose(*start))
    move = arc(start, sign / radius, 1.0, 0.0, speed=0.2, n=n)
    assert "turning_radius" in rules(judge(sc, Plan((move,))))
