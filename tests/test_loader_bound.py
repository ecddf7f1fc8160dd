"""The wheel loader's time-to-target bound: no valid plan beats it, and what it cannot price.

Plans are built through the public API (the ``pile`` generator, :func:`earthbench.cut.charge_along`)
and judged by the referee: a valid plan whose truck holds the target before the bound is a bug in
the bound or in the referee. The strip plans show why the bound prices no per-cycle reverse or
turn: the loader scrapes along the pile's face with the truck beside it on the floor and dumps
where each charge ends (docs/metrics.md, "What the geometry forces").
"""

from __future__ import annotations

import dataclasses
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from earthbench import Charge, Dump, Move, Plan, Pose, Scenario, judge
from earthbench.cut import charge_along
from earthbench.results.scoring import time_to_target
from earthbench_metrics import lower_bound_time_to_target
from earthbench_planners.greedy.loader import GreedyLoader
from earthbench_planners.singh_cannon.loader import SinghCannonLoader
from earthbench_planners.strip_loader.planner import StripLoader
from earthbench_terrains.pile import pile

from helpers.bounds import assert_no_valid_plan_beats_the_bound

LINE = 11.95  # the loader's line: its bucket (1.8 m wide) half over the straight face at y = 11
TRUCK_Y = 10.15  # the truck's line: its body (1.6 m wide) on the floor south of the face
AHEAD = 0.74  # the truck's centre this far ahead of the cutting edge: in dump reach, within 45°, clear


def strip_plan(target: float, *, height: float = 1.2, slope: float = 0.65, wall: float = 4.6, truck_south: float = 0.0,
               back: float = 0.2, slack: float = 0.0) -> tuple[Scenario, Plan]:
    """A straight pile face from x = ``wall``; the loader starts at x = 3.3 heading east along
    ``LINE``, drives to the face, then charges along it up to a full bucket at a time and dumps where
    the charge ends, backing off ``back`` before the next (the row the last bucket filled in is
    left partly cut). The truck keeps ``AHEAD`` of each dump's edge on ``TRUCK_Y`` (starting
    up to ``truck_south`` metres further east along its line, ahead of the loader, whence it
    reverses to its first stand),
    moving on during each charge; every action lasts its least time plus ``slack``."""
    x = 3.3
    sc = pile(0, target, features=[], wall=(wall, 17.0), height=height, slope=slope, loader=(x, LINE, 0.0),
              truck=(10.0, TRUCK_Y, 0.0), min_gap=0.5)
    spec, z = sc.machines.loader, sc.terrain.z.copy()
    v, vt = spec.travel_speed * 0.99, sc.machines.truck.travel_speed * 0.99
    arrive = truck_south / vt
    acts: list = []
    t, loaded = 0.0, 0.0
    dumps: list[tuple[float, float, float]] = []  # start, end, the truck's stand
    entry = wall - 0.1 - spec.bucket_offset
    if entry > x:
        acts.append(Move("loader", ((t, x, LINE, 0.0), (t + (entry - x) / v, entry, LINE, 0.0))))
        t, x = t + (entry - x) / v, entry
    while loaded < target - 1e-9:
        if dumps:
            acts.append(Move("loader", ((t, x, LINE, 0.0), (t + back / v + slack, x - back, LINE, 0.0))))
            t, x = t + back / v + slack, x - back
        full = charge_along(sc.terrain, z, spec, (x, LINE, 0.0), 5.0, 0.0, spec.bucket_capacity, apply=False).full_at
        if full is None:
            break
        pen = full + sc.terrain.resolution / 2
        loaded += charge_along(sc.terrain, z, spec, (x, LINE, 0.0), pen, 0.0, spec.bucket_capacity).volume
        d = max(spec.min_charge_time, pen / spec.penetration_speed) + 1e-6 + slack
        acts.append(Charge("loader", t, t + d, (x, LINE, 0.0), pen))
        t, x = max(t + d, arrive if not dumps else 0.0), x + pen
        d = spec.min_dump_time + 1e-6 + slack
        acts.append(Dump("loader", t, t + d))
        dumps.append((t, t + d, x + spec.bucket_offset + AHEAD))
        t += d
    first = dumps[0][2]
    east = sc.terrain.origin[0] + sc.terrain.z.shape[1] * sc.terrain.resolution - 1.7  # its body on the closed map
    x0 = min(first + truck_south, max(first, east))
    arrive = (x0 - first) / vt
    assert arrive <= dumps[0][0] + 1e-9  # the first dump waited for it
    truck = [Move("truck", ((0.0, x0, TRUCK_Y, 0.0), (arrive, first, TRUCK_Y, 0.0)))] if x0 > first else []
    for (_, end, a), (start, _, b) in zip(dumps, dumps[1:]):  # on as a dump ends, there before the next
        assert end + (b - a) / vt < start
        truck.append(Move("truck", ((end, a, TRUCK_Y, 0.0), (end + (b - a) / vt, b, TRUCK_Y, 0.0))))
    machines = dataclasses.replace(sc.machines, truck_pose=Pose(x0, TRUCK_Y, 0.0))
    return dataclasses.replace(sc, machines=machines), Plan(tuple(acts + truck))


def ratio(sc: Scenario, plan: Plan) -> float:
    v = judge(sc, plan)
    assert v.valid, v.violations[:3]
    return time_to_target(v.load_curve, sc.task.target_volume) / lower_bound_time_to_target(sc)


def test_a_loader_can_cycle_without_reversing_out_or_turning():
    """Along the face, with the truck beside the strip: every cycle after the first takes the
    fastest charge and dump plus a back-off of two cells; the loader never turns, so no bound that
    holds for every valid plan can charge a cycle the reverse out of the pile and the turn."""
    sc, plan = strip_plan(4.0)
    spec = sc.machines.loader
    assert all(a.path[k][3] == 0.0 for a in plan.actions if isinstance(a, Move) and a.machine == "loader" for k in range(2))
    dumps = [a for a in plan.actions if isinstance(a, Dump)]
    cycle = (dumps[-1].t_end - dumps[0].t_end) / (len(dumps) - 1)
    assert cycle <= spec.min_charge_time + spec.min_dump_time + 0.2 / (0.99 * spec.travel_speed) + 1e-5
    assert 1.0 <= ratio(sc, plan) < 1.06  # 26.4 s against 25.0 s: the first charge drives 1.5 m


def test_no_machine_slides_sideways_on_short_steps():
    """Under rules 1 the ``heading`` rule bounded each step's sideways slip by the chord tolerance
    whatever the step, so steps of 4.99 cm slid the truck north at its full speed without a yaw,
    and the loader sideways without a turn. Rules 2 scale the slack with the chord: the slide is
    refused, while a long straight step may still leave its arc by the tolerance."""
    sc = pile(0, 2.0)
    for machine, speed in (("truck", 0.85), ("loader", 1.99)):
        p = sc.machines.pose(machine)
        side = (-math.sin(p.yaw), math.cos(p.yaw))
        path = tuple((k * 0.0499 / speed, p.x + side[0] * 0.0499 * k, p.y + side[1] * 0.0499 * k, p.yaw) for k in range(41))
        v = judge(sc, Plan((Move(machine, path),)))
        assert [x.rule for x in v.violations] == ["heading"], v.violations[:3]
        ahead, tol = (math.cos(p.yaw), math.sin(p.yaw)), 0.999 * getattr(sc.machines, machine).chord_tolerance
        end = (p.x + 1.2 * ahead[0] + tol * side[0], p.y + 1.2 * ahead[1] + tol * side[1])
        v = judge(sc, Plan((Move(machine, ((0.0, p.x, p.y, p.yaw), (1.3 / speed, *end, p.yaw))),)))
        assert "heading" not in {x.rule for x in v.violations}, v.violations[:3]


def test_the_loader_bound_prices_the_way_to_the_pile_and_the_truck():
    sc, _ = strip_plan(4.0, wall=7.0)  # the loader's pose 3.75 m from the nearest material
    spec = sc.machines.loader
    first = spec.min_charge_time + (3.75 - math.hypot(1.2, 0.9) - 1e-6 - spec.penetration_speed * 1.001 * 2.0) / (2.0 * 1.001)
    assert lower_bound_time_to_target(sc) == pytest.approx(first + 3.0 + 4 * 5.0 - 20e-6, abs=1e-6)
    far = dataclasses.replace(sc, machines=dataclasses.replace(sc.machines, truck_pose=Pose(17.5, 1.0, 0.0)))
    gap = math.hypot(17.5 - 16.95, 1.0 - 11.05) - 1.5 - 3.2  # what the truck must close, or the loader for it
    # by hand: s₁ = t_c + (2.25 + g(s₁) − 1.0)/2.0 with g(s) = gap − 0.861 s: 3.709 s; the loader then
    # drives g(s₁) = 2.17 m back to the pile and the truck closes the rest: s₂ = s₁ + t_d + t_c +
    # (2.17 − 1.0)/2.0 = 9.294 s; three cycles of 5 s and a dump follow
    assert gap == pytest.approx(5.365, abs=1e-3)
    assert lower_bound_time_to_target(far) == pytest.approx(9.294 + 3 * 5.0 + 3.0, abs=2e-3)
    assert lower_bound_time_to_target(pile(0, 2.0)) > 3 * 5.0  # the pile's default layout: the loader drives first


@settings(max_examples=60, deadline=None)
@given(
    height=st.floats(0.9, 1.4),
    slope=st.floats(0.5, 0.8),
    wall=st.floats(4.6, 8.0),
    truck_south=st.floats(0.0, 6.0),
    back=st.floats(0.15, 0.4),
    slack=st.floats(0.0, 0.5),
    target=st.floats(0.4, 4.0),
)
def test_no_valid_loader_plan_beats_the_bound(height, slope, wall, truck_south, back, slack, target):
    """Strip plans on random faces, starts and targets, every action at its least time or slower."""
    sc, plan = strip_plan(target, height=height, slope=slope, wall=wall, truck_south=truck_south, back=back, slack=slack)
    assert_no_valid_plan_beats_the_bound(sc, plan, target)


@pytest.mark.parametrize("planner", [GreedyLoader, SinghCannonLoader, StripLoader])
@pytest.mark.parametrize("seed,target", [(0, 4.0), (3, 2.0), (7, 2.0), (8, 4.0)])
def test_the_loader_planners_never_beat_the_bound(planner, seed, target):
    sc = pile(seed, target)
    plan = planner().plan(sc)
    v = judge(sc, plan)
    assert v.valid, v.violations[:3]
    assert time_to_target(v.load_curve, target) >= lower_bound_time_to_target(sc)
