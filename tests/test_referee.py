"""Every referee rule, with a plan that obeys it and one that breaks it by a small margin."""

from __future__ import annotations

import math

import pytest
from helpers import block_scenario, dig_dump_plan, straight_move

from earthbench import Dig, Dump, Move, Plan, Pose, judge
from earthbench.referee import RULES


def rules(verdict) -> set[str]:
    return {v.rule for v in verdict.violations}


def test_valid_dig_and_dump_loads_a_full_bucket(scenario, valid_plan):
    v = judge(scenario, valid_plan)
    assert v.valid, v.violations
    assert v.loaded_volume == pytest.approx(0.28)
    assert v.removed_volume == pytest.approx(0.28)
    assert v.makespan == pytest.approx(valid_plan.actions[-1].t_end)
    lost = (scenario.terrain.z - v.final_terrain.z).sum() * scenario.terrain.cell_area
    assert lost == pytest.approx(0.28)


def test_every_rule_has_a_description():
    assert {"speed", "yaw_rate", "heading", "keep_out", "reach", "below_floor", "collision"} <= set(RULES)


# -- motion ------------------------------------------------------------------------------------

EXC = Pose(4.0, 9.0, -math.pi / 2)
TRUCK = Pose(9.0, 9.0, math.pi)


@pytest.mark.parametrize("factor, ok", [(0.999, True), (1.01, False)])
def test_speed_limit(scenario, factor, ok):
    # the truck reverses east (yaw π, so east is straight backwards) at factor × its limit
    m = straight_move("truck", TRUCK, (11.0, 9.0), 0.0, 0.86 * factor)
    assert ("speed" not in rules(judge(scenario, Plan((m,))))) == ok


@pytest.mark.parametrize("factor, ok", [(1.0, True), (1.01, False)])
def test_yaw_rate_limit(scenario, factor, ok):
    turn = 1.0
    m = Move("truck", ((0.0, 9.0, 9.0, math.pi), (turn / (0.11 * factor), 9.0, 9.0, math.pi + turn)))
    assert ("yaw_rate" not in rules(judge(scenario, Plan((m,))))) == ok


@pytest.mark.parametrize("lateral, ok", [(0.04, True), (0.06, False)])
def test_motion_along_heading(scenario, lateral, ok):
    # drive 2 m backwards (east) while drifting ``lateral`` metres north
    m = Move("truck", ((0.0, 9.0, 9.0, math.pi), (10.0, 11.0, 9.0 + lateral, math.pi)))
    assert ("heading" not in rules(judge(scenario, Plan((m,))))) == ok


@pytest.mark.parametrize("sideways, ok", [(4e-15, True), (5e-7, True), (1e-2, False)])
def test_a_rounding_error_is_no_slide_but_a_short_slide_is(scenario, sideways, ok):
    # a step straight sideways (north, the truck facing west): a rounding error's worth is no move
    # at all, while a centimetre is a slide however short the chord (the slack shrinks with it)
    m = Move("truck", ((0.0, 9.0, 9.0, math.pi), (1.0, 9.0, 9.0 + sideways, math.pi)))
    assert ("heading" not in rules(judge(scenario, Plan((m,))))) == ok


def test_a_turning_arc_follows_its_chord(scenario):
    # a unicycle arc: the chord points along the mean heading, so no lateral slip is flagged
    r, dth = 2.0, 0.3  # forward (west) from yaw π, turning counter-clockwise on a 2 m circle
    x1 = 9.0 - r * math.sin(dth)
    y1 = 9.0 - r * (1 - math.cos(dth))
    m = Move("truck", ((0.0, 9.0, 9.0, math.pi), (dth / 0.1, x1, y1, math.pi + dth)))
    assert judge(scenario, Plan((m,))).valid


@pytest.mark.parametrize("start, ok", [((9.0, 9.0), True), ((9.01, 9.0), False)])
def test_move_starts_where_the_machine_is(scenario, start, ok):
    m = straight_move("truck", Pose(start[0], start[1], math.pi), (11.0, 9.0), 0.0, 0.5)
    assert ("discontinuous" not in rules(judge(scenario, Plan((m,))))) == ok


@pytest.mark.parametrize("y_top, ok", [(5.3, True), (5.5, False)])
def test_keep_out_for_machines(y_top, ok):
    # the truck, facing north, reverses south from (9, 9) to (9, 7), toward a zone ending at
    # y_top: its 3.2 m footprint reaches 1.6 m behind its centre, to y = 5.4
    sc = block_scenario(keep_outs=[((8.5, 5.0), (9.5, 5.0), (9.5, y_top), (8.5, y_top))])
    truck = Pose(9.0, 9.0, math.pi / 2)
    sc = sc.replace(machines=sc.machines.__class__(excavator=sc.machines.excavator, excavator_pose=EXC, truck_pose=truck))
    m = straight_move("truck", truck, (9.0, 7.0), 0.0, 0.5)
    assert ("keep_out" not in rules(judge(sc, Plan((m,))))) == ok


def test_keep_out_for_the_bucket():
    sc = block_scenario(keep_outs=[((3.8, 5.5), (4.2, 5.5), (4.2, 5.6), (3.8, 5.6))])
    assert "keep_out" in rules(judge(sc, Plan(tuple(dig_dump_plan(heading=math.pi / 2)))))
    assert judge(sc, Plan(tuple(dig_dump_plan(contact=(3.0, 5.0), heading=math.pi / 2)))).valid


def test_no_overlap_between_actions_of_one_machine(scenario):
    dig, dump = dig_dump_plan()
    early = Dump("excavator", dig.t_end - 0.01, dump.t_end)
    assert "overlap" in rules(judge(scenario, Plan((dig, early))))
    # and the excavator cannot drive while it digs
    m = straight_move("excavator", EXC, (4.0, 9.5), 1.0, 0.5)
    assert "overlap" in rules(judge(scenario, Plan((dig, m))))


def test_unknown_and_wrong_machine(scenario):
    dig, dump = dig_dump_plan()
    v = judge(scenario, Plan((Dig("crane", dig.t_start, dig.t_end, dig.contact, dig.heading, 0.4, 1.0),)))
    assert rules(v) == {"unknown_machine"}
    v = judge(scenario, Plan((Dig("truck", dig.t_start, dig.t_end, dig.contact, dig.heading, 0.4, 1.0),)))
    assert rules(v) == {"wrong_machine"}


# -- digging -----------------------------------------------------------------------------------

@pytest.mark.parametrize("r, ok", [(6.1, True), (6.12, False), (3.0, True), (2.98, False)])
def test_reach_annulus(scenario, r, ok):
    # contact straight south of the base at distance r, dragging 1 m toward it; the drag end is at
    # r − 1, so the lower bound is tested through the drag end
    plan = Plan(tuple(dig_dump_plan(contact=(4.0, 9.0 - r))))
    assert ("reach" not in rules(judge(scenario, plan))) == ok


@pytest.mark.parametrize("x, ok", [(0.35, True), (0.34, False)])
def test_footprint_inside_dig_area(scenario, x, ok):
    # the bucket is 0.7 m wide: at x = 0.35 its west edge touches the dig area's edge x = 0
    plan = Plan(tuple(dig_dump_plan(contact=(x, 5.0), heading=math.pi / 2)))
    assert ("outside_dig_area" not in rules(judge(scenario, plan))) == ok


@pytest.mark.parametrize("depth, ok", [(0.4, True), (0.41, False)])
def test_cut_depth_limit(scenario, depth, ok):
    assert ("cut_depth" not in rules(judge(scenario, Plan(tuple(dig_dump_plan(depth=depth)))))) == ok


@pytest.mark.parametrize("drag, ok", [(1.0, True), (1.01, False)])
def test_drag_length_limit(scenario, drag, ok):
    assert ("drag_length" not in rules(judge(scenario, Plan(tuple(dig_dump_plan(drag=drag)))))) == ok


@pytest.mark.parametrize("floor, ok", [(0.6, True), (0.61, False)])
def test_cut_never_below_the_floor(floor, ok):
    sc = block_scenario(floor=floor)
    v = judge(sc, Plan(tuple(dig_dump_plan())))
    assert ("below_floor" not in rules(v)) == ok
    assert v.final_terrain.z.min() >= floor - 1e-9


def test_bucket_must_be_empty_before_a_dig(scenario):
    dig, dump = dig_dump_plan()
    dig2 = Dig("excavator", dig.t_end, dig.t_end + 10, (3.0, 5.0), dig.heading, 0.4, 1.0)
    assert "bucket_not_empty" in rules(judge(scenario, Plan((dig, dig2))))
    dig3 = Dig("excavator", dump.t_end, dump.t_end + 10, (3.0, 5.0), math.atan2(4, 1), 0.4, 1.0)
    assert "bucket_not_empty" not in rules(judge(scenario, Plan((dig, dump, dig3))))


def test_dig_duration_covers_swing_and_stroke(scenario):
    dig, dump = dig_dump_plan()
    assert judge(scenario, Plan((dig, dump))).valid
    short = Dig("excavator", dig.t_start, dig.t_end - 0.01, dig.contact, dig.heading, dig.depth, dig.drag_length)
    v = judge(scenario, Plan((short,)))
    assert rules(v) == {"duration"}
    assert v.violations[0].magnitude == pytest.approx(0.01, abs=1e-5)


def test_over_deep_dig_fills_the_bucket_and_leaves_the_rest():
    # a 2 m slab cut 0.4 m over 0.7 × 1.0 m would be 0.28 m³: a smaller bucket takes only its capacity
    sc = block_scenario(bucket_capacity=0.1005)
    v = judge(sc, Plan(tuple(dig_dump_plan())))
    assert v.valid
    assert v.removed_volume == pytest.approx(0.1005)
    lowered = (sc.terrain.z - v.final_terrain.z) > 1e-12
    cut = sc.terrain.z - v.final_terrain.z
    # whole cells go down to the cut level in drag order; exactly one cell is cut partly
    partial = lowered & (cut < 0.4 - 1e-9)
    assert partial.sum() == 1


# -- dumping -----------------------------------------------------------------------------------

def test_dump_duration_covers_swing(scenario):
    dig, dump = dig_dump_plan()
    short = Dump("excavator", dump.t_start, dump.t_end - 0.01)
    assert rules(judge(scenario, Plan((dig, short)))) == {"duration"}


def test_truck_must_be_still_during_a_dump(scenario):
    dig, dump = dig_dump_plan()
    m = straight_move("truck", TRUCK, (9.5, 9.0), dump.t_start + 0.5, 0.5)
    assert "truck_moving" in rules(judge(scenario, Plan((dig, dump, m))))
    m_after = straight_move("truck", TRUCK, (9.5, 9.0), dump.t_end, 0.5)
    assert judge(scenario, Plan((dig, dump, m_after))).valid


@pytest.mark.parametrize("x, ok", [(11.1, True), (11.2, False)])
def test_truck_within_dump_reach(x, ok):
    # base at (4, 9); the truck at distance 7.1 has its loading area's edge exactly at 6.1 m
    sc = block_scenario()
    sc = sc.replace(machines=sc.machines.__class__(excavator=sc.machines.excavator, excavator_pose=EXC, truck_pose=Pose(x, 9.0, math.pi)))
    plan = Plan(tuple(dig_dump_plan(extra=1.0)))
    assert ("dump_reach" not in rules(judge(sc, plan))) == ok


def test_only_dumped_material_counts_and_a_full_truck_takes_no_more(scenario):
    dig, dump = dig_dump_plan()
    assert judge(scenario, Plan((dig,))).loaded_volume == 0.0
    small = scenario.replace(machines=scenario.machines.__class__(
        excavator=scenario.machines.excavator, excavator_pose=EXC, truck_pose=TRUCK,
        truck=scenario.machines.truck.__class__(capacity=0.2)))
    v = judge(small, Plan((dig, dump)))
    assert v.loaded_volume == pytest.approx(0.2)


# -- collisions ----------------------------------------------------------------------------------

@pytest.mark.parametrize("x, ok", [(7.5, True), (7.45, False)])
def test_excavator_truck_clearance(scenario, x, ok):
    # the truck drives forward (west) toward the excavator and stops at x; clearance is 3.5 m
    m = straight_move("truck", TRUCK, (x, 9.0), 0.0, 0.5)
    assert ("collision" not in rules(judge(scenario, Plan((m,))))) == ok


def test_violations_name_the_action(scenario):
    dig, dump = dig_dump_plan()
    bad = Dig("excavator", dig.t_start, dig.t_end, dig.contact, dig.heading, 0.5, 1.0)
    v = judge(scenario, Plan((bad, dump)))
    (viol,) = [x for x in v.violations if x.rule == "cut_depth"]
    assert viol.action == 0 and viol.magnitude == pytest.approx(0.1)
