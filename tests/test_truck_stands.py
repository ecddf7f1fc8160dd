"""The truck's stands the fast backhoe planners share (planners/truck_stands.py, issues 48 and 49):
off the dig area, out of the arm's shadow, on ground within the truck's limits, and near the
dig's bearing, so that a plan keeps the site rules (rules version 2) and swings little."""

from __future__ import annotations

import math

import numpy as np
import pytest

from earthbench import PLANNERS, judge
from earthbench.plan import Dig, Move
from earthbench.rules import arm_shadow, overlap_area
from earthbench.results.scoring import evaluate
from earthbench_planners.truck_stands import TruckStands
from earthbench_terrains.bench import bench


def test_the_stand_chosen_for_a_dig_is_out_of_its_shadow_and_nearest_its_bearing():
    sc = bench(0, 4.0)
    spec, truck, base = sc.machines.excavator, sc.machines.truck_pose, sc.machines.excavator_pose
    stands = TruckStands(sc, spec, np.array(sc.terrain.z))
    line = stands.line(truck, base)
    assert len(line[0]) > 10 and stands.ground_ok(line[0]).all()
    for bearing in np.radians([150.0, 180.0, 210.0]):  # contacts on the bench face, toward the truck's floor
        contact = (base.x + 4.5 * math.cos(bearing), base.y + 4.5 * math.sin(bearing))
        heading = bearing + math.pi
        # a long dig: the truck reaches any stand in time, so the least swing decides
        got = stands.best_for_dig(base, truck, line, contact, heading, spec.max_drag_length, 0.0, 60.0)
        assert got is not None
        stand, _, swing = got
        shadow = arm_shadow(base, contact, heading, spec.bucket_width, spec.max_drag_length)
        assert overlap_area(shadow, sc.machines.truck, np.array([[stand.x, stand.y, stand.yaw]]))[0] == 0.0
        # no stand on the line is out of the shadow at a smaller swing
        bearings = np.arctan2(line[0][:, 1] - base.y, line[0][:, 0] - base.x)
        clear = overlap_area(shadow, sc.machines.truck, line[0]) == 0.0
        swings = np.abs((bearings - bearing + math.pi) % (2 * math.pi) - math.pi)
        assert swing <= swings[clear].min() + 1e-9


@pytest.mark.parametrize("planner", ["greedy", "singh-cannon-backhoe"])
@pytest.mark.parametrize("seed", [0, 1])
def test_bench_plans_keep_the_site_rules_with_the_truck_following_the_face(planner, seed):
    """greedy 1.2 parked the truck on the bench (its ground dug under it) and swung 73° a dump;
    now the truck slides along the floor during digs and both planners load within 1.2 × the
    target bound (greedy 1.2: 1.55, singh-cannon-backhoe 1.3: 1.31 on these)."""
    sc = bench(seed, 4.0)
    plan = PLANNERS.get(planner)().plan(sc)
    verdict = judge(sc, plan)
    assert verdict.valid, verdict.violations[:3]
    m = evaluate(sc, plan, verdict)
    assert m["volume_ratio"] >= 0.99
    assert m["time_per_target_m3_bound_ratio"] <= 1.2
    digs = [a for a in plan.actions if isinstance(a, Dig)]
    slides = [a for a in plan.actions if isinstance(a, Move) and a.machine == "truck"]
    assert any(d.t_start < s.path[-1][0] and s.path[0][0] < d.t_end for d in digs for s in slides)


def test_the_truck_drives_an_arc_when_that_beats_turning_in_place():
    """A stand ahead and to the side: the arc at the truck's full speed and yaw rate gets there
    sooner than turning in place first (0.11 rad/s), and the referee accepts it; a goal behind
    the truck is reached turning in place."""
    from earthbench.motion import turn_drive_turn
    from earthbench.plan import Plan
    from earthbench.world import Pose
    from earthbench_planners.truck_stands import drive

    sc = bench(0, 4.0)
    t, start = sc.machines.truck, sc.machines.truck_pose  # on the floor west of the bench, heading north
    goal = (start.x - 3.0, start.y + 9.0)
    path = drive(start, goal, 0.0, t.travel_speed, t.yaw_rate)
    straight = turn_drive_turn(start, goal, 0.0, t.travel_speed, t.yaw_rate)
    assert path[-1][0] < straight[-1][0] - 2.0 and path[-1][1:3] == pytest.approx(goal)
    verdict = judge(sc, Plan((Move("truck", tuple(path)),)))
    assert not verdict.violations, verdict.violations[:3]
    behind = (start.x - 1.0, start.y - 2.0)
    assert drive(start, behind, 0.0, t.travel_speed, t.yaw_rate) == turn_drive_turn(start, behind, 0.0, t.travel_speed, t.yaw_rate)
    assert Pose(*path[-1][1:]).yaw != start.yaw
