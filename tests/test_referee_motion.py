"""The motion model between samples, footprints and the map's edge: each hole of the referee
that a sparse sample, a point machine or an unbounded map let through, as a regression test,
and hypothesis properties that no sampling of the same motion changes the verdict."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from test_referee_loader import arc, loader_scenario

from earthbench import Charge, Dig, Dump, Move, Plan, Pose, judge
from earthbench.motion import arcs, dense_poses, min_dig_time, min_dump_time, poses_at
from earthbench.results.suite import load_suite
from earthbench_planners.singh_cannon.loader import SinghCannonLoader


def rules(v) -> set[str]:
    return {x.rule for x in v.violations}


@pytest.fixture(scope="module")
def pile0():
    return next(s for s in load_suite("pile").scenarios if s.id == "pile/pile/s0/v2")


def with_pose(sc, machine: str, pose: Pose):
    return sc.replace(machines=dataclasses.replace(sc.machines, **{f"{machine}_pose": pose}))


def u_turn(n: int, radius: float = 3.5, t: float = 6.0) -> Move:
    """From (12, 8.8) heading north, a left half circle to (12 − 2r, 8.8) heading south."""
    th = np.linspace(0.0, math.pi, n + 1)
    x, y = 12.0 - radius + radius * np.cos(th), 8.8 + radius * np.sin(th)
    return Move("loader", tuple((float(t * f), float(a), float(b), float(math.pi / 2 + c)) for f, a, b, c in zip(th / math.pi, x, y, th)))


# -- the motion model itself --------------------------------------------------------------------

def test_the_arc_between_two_samples_is_the_one_the_dense_samples_lie_on():
    m = u_turn(60)
    p = np.array(m.path)
    sparse = np.array([p[0], p[-1]])
    a = arcs(sparse)
    assert a["length"][0] == pytest.approx(math.pi * 3.5)
    assert a["radius"][0] == pytest.approx(3.5)
    on = poses_at(sparse, p[:, 0])
    assert np.allclose(on[:, :2], p[:, 1:3], atol=1e-9)
    d = dense_poses(sparse, 0.05)
    assert np.allclose(np.hypot(d[:, 1] - (12.0 - 3.5), d[:, 2] - 8.8), 3.5)
    assert np.max(np.hypot(*np.diff(d[:, 1:3], axis=0).T)) <= 0.05 + 1e-12


# -- issue: chords, not motion --------------------------------------------------------------------

@pytest.mark.parametrize("n", [1, 2, 60])
def test_a_u_turn_over_the_pile_breaks_the_step_however_it_is_sampled(pile0, n):
    sc = with_pose(pile0, "loader", Pose(12.0, 8.8, math.pi / 2))
    v = judge(sc, Plan((u_turn(n),)))
    assert "step" in rules(v), v.violations


@pytest.mark.parametrize("n", [1, 2, 40])
def test_a_half_circle_is_as_fast_as_its_arc_not_its_chord(n):
    start = Pose(8.0, 2.0, math.pi / 2)
    sc = loader_scenario(start=start, truck=Pose(-30.0, -30.0, 0.0))
    move = arc((start.x, start.y, start.yaw), 1 / 5.2, math.pi * 5.2, 0.0, speed=math.pi * 5.2 / 5.24, n=n)
    v = judge(sc, Plan((move,)))
    assert "speed" in rules(v)
    assert max(x.magnitude for x in v.violations if x.rule == "speed") == pytest.approx(3.12 - 2.0, abs=0.01)


# -- issue: a full bucket pushes on --------------------------------------------------------------

def test_a_charge_that_drives_on_past_a_full_bucket_is_overfill(pile0):
    plan = SinghCannonLoader().plan(pile0)
    assert judge(pile0, plan).valid
    k, c = next((k, a) for k, a in enumerate(plan.actions) if isinstance(a, Charge))
    longer = Charge(c.machine, c.t_start, c.t_start + 2.9 / 0.5, c.entry, c.penetration + 1.15)
    acts = list(plan.actions[: k]) + [longer]
    v = judge(pile0, Plan(tuple(acts)))
    assert "overfill" in rules(v)


# -- issue: off the map is level ground ---------------------------------------------------------

def test_leaving_a_closed_map_is_off_map(pile0):
    start = pile0.machines.loader_pose  # (12, 6) facing north; its body reaches 2.9 m behind
    back = Move("loader", ((0.0, start.x, start.y, start.yaw), (2.0, start.x, start.y - 4.0, start.yaw)))
    assert "off_map" in rules(judge(pile0, Plan((back,))))
    assert "off_map" not in rules(judge(pile0.replace(site=dataclasses.replace(pile0.site, open_outside=True)), Plan((back,))))


def test_the_backhoe_maps_are_open_outside_and_keep_their_digests():
    sc = load_suite("smoke").scenarios[0]
    assert sc.outside_open and "open_outside" not in sc.to_json()
    assert "track_length" not in sc.to_json()


# -- issue: machines are points -------------------------------------------------------------------

def _bench_digs(depths: list[float]) -> Plan:
    sc = next(s for s in load_suite("bench").scenarios if s.id == "bench/bench/s0/v4")
    e, base = sc.machines.excavator, sc.machines.excavator_pose
    truck = (sc.machines.truck_pose.x, sc.machines.truck_pose.y)
    acts, t, turn = [], 0.0, 0.0
    contact = (base.x - 2.5, base.y)  # dragging east 0.5 m, to 0.7 m from the west end of the tracks
    for d in depths:
        dt = min_dig_time(base, turn, contact, e) + 1e-6
        acts.append(Dig("excavator", t, t + dt, contact, 0.0, d, 0.5))
        t, turn = t + dt, math.pi - base.yaw
        dt = min_dump_time(base, turn, truck, e) + 1e-6
        acts.append(Dump("excavator", t, t + dt))
        t, turn = t + dt, math.atan2(truck[1] - base.y, truck[0] - base.x) - base.yaw
    return sc, Plan(tuple(acts))


def test_digging_the_bench_down_beside_the_tracks_is_undermining():
    sc, shallow = _bench_digs([0.4])
    assert judge(sc, shallow).valid, judge(sc, shallow).violations
    sc, deep = _bench_digs([0.4] * 6)  # each level from the (partly cut) contact: about 1 m down, 0.7 m from the tracks
    v = judge(sc, deep)
    assert rules(v) == {"undermining"}
    assert all(x.action >= 2 for x in v.violations)


def test_working_on_a_steep_flank_is_tilt():
    sc, plan = _bench_digs([0.4])
    e = sc.machines.excavator
    steep = sc.replace(machines=dataclasses.replace(sc.machines, excavator=dataclasses.replace(e, max_tilt=0.0)))
    flat = sc.replace(terrain=sc.terrain.with_z(np.full(sc.terrain.shape, 1.5)))
    assert "tilt" in rules(judge(steep, plan))
    assert "tilt" not in rules(judge(flat, plan))


# -- swept-path clearance (integrity issue) -----------------------------------------------------

@settings(max_examples=40, deadline=None)
@given(
    angle=st.floats(0.0, 2 * math.pi),
    offset=st.floats(-3.3, 3.3),
    before=st.floats(5.0, 9.0),
    after=st.floats(5.0, 9.0),
    exc_moves=st.booleans(),
)
def test_a_truck_passing_through_the_excavator_between_samples_is_a_collision(angle, offset, before, after, exc_moves):
    """Both samples of the truck lie ≥ 5 m from the excavator, the chord between them within
    the 3.5 m clearance: caught, also while the excavator drives too."""
    sc = load_suite("smoke").scenarios[0]
    e = Pose(20.0, 20.0, 0.0)
    ux, uy = math.cos(angle), math.sin(angle)
    nx, ny = -uy, ux
    a = (e.x - before * ux + offset * nx, e.y - before * uy + offset * ny)
    b = (e.x + after * ux + offset * nx, e.y + after * uy + offset * ny)
    dur = (before + after) / 0.85
    sc = sc.replace(machines=dataclasses.replace(sc.machines, excavator_pose=e, truck_pose=Pose(a[0], a[1], angle)))
    acts = [Move("truck", ((0.0, a[0], a[1], angle), (dur, b[0], b[1], angle)))]
    if exc_moves:  # the excavator reverses along the same line, slowly, against the truck
        sc = sc.replace(machines=dataclasses.replace(sc.machines, excavator_pose=Pose(e.x, e.y, angle)))
        acts.append(Move("excavator", ((0.0, e.x, e.y, angle), (dur, e.x - 0.05 * dur * ux, e.y - 0.05 * dur * uy, angle))))
    assert "collision" in rules(judge(sc, Plan(tuple(acts))))


# -- any sampling of one motion gives one verdict -------------------------------------------------

@settings(max_examples=60, deadline=None)
@given(
    x=st.floats(5.0, 15.0),
    y=st.floats(3.0, 9.0),
    yaw=st.floats(-math.pi, math.pi),
    curvature=st.floats(-1 / 3.5, 1 / 3.5),
    length=st.floats(0.5, 9.0),
    reverse=st.booleans(),
    speed=st.floats(0.5, 2.5),
    sparse=st.integers(1, 4),
)
def test_a_limit_the_dense_motion_breaks_is_caught_however_sparsely_it_is_sampled(x, y, yaw, curvature, length, reverse, speed, sparse):
    """Step (the 1 m block east of x = 14), keep-out, the closed map's edge, speed, turning
    radius: whatever 80 samples along the arc break, 1–4 samples of the same arc break too."""
    if abs(curvature) * length / sparse > math.pi - 0.05:
        return  # a sample pair more than half a turn apart is another curve
    sc = loader_scenario(start=Pose(x, y, yaw), truck=Pose(-30.0, -30.0, 0.0), open_outside=False)
    sc = sc.replace(site=dataclasses.replace(sc.site, keep_outs=(((4.0, 9.0), (6.0, 9.0), (6.0, 10.5), (4.0, 10.5)),)))
    signed = -length if reverse else length
    dense = judge(sc, Plan((arc((x, y, yaw), curvature, signed, 0.0, speed=speed, n=80),)))
    coarse = judge(sc, Plan((arc((x, y, yaw), curvature, signed, 0.0, speed=speed, n=sparse),)))
    checked = {"step", "keep_out", "off_map", "speed", "turning_radius", "collision"}
    assert rules(dense) & checked <= rules(coarse), (dense.violations, coarse.violations)


@settings(max_examples=30, deadline=None)
@given(curvature=st.floats(-0.5, 0.5), length=st.floats(-6.0, 6.0), n=st.integers(1, 5), t=st.floats(-1.0, 12.0))
def test_a_timeline_pose_is_the_motion_models_pose(curvature, length, n, t):
    from earthbench.motion import Timeline

    if abs(curvature * length) / n > math.pi - 0.05:
        return
    m = arc((1.0, 2.0, 0.3), curvature, length, 0.5, speed=1.0, n=n)
    line = Timeline(Pose(1.0, 2.0, 0.3), [m])
    p = line.pose(t)
    q = poses_at(line.path, np.array([t]))[0]
    assert (p.x, p.y, p.yaw) == pytest.approx(tuple(q), abs=1e-9)


@settings(max_examples=40, deadline=None)
@given(start=st.tuples(st.floats(0.0, 50.0), st.floats(0.0, 50.0), st.floats(-math.pi, math.pi)),
       goal=st.tuples(st.floats(0.0, 50.0), st.floats(0.0, 50.0)), later=st.floats(0.0, 100.0))
def test_a_machine_at_rest_stands_exactly_where_its_last_move_ended(start, goal, later):
    """The arc's end is 1e-15 m off the sample for about half of all drives; the station a
    planner checked (tilt, track level) must be the one the referee judges, bit for bit."""
    from earthbench.motion import turn_drive_turn
    from earthbench.motion import Timeline

    path = turn_drive_turn(Pose(*start), goal, 0.0, 0.5, 0.5)
    line = Timeline(Pose(*start), [Move("excavator", tuple(path))] if len(path) > 1 else [])
    t_end, x, y, yaw = path[-1]
    p = line.pose(t_end + later)
    assert (p.x, p.y) == (x, y)
    assert math.cos(p.yaw) == math.cos(yaw) and math.sin(p.yaw) == math.sin(yaw)
    assert tuple(poses_at(line.path, np.array([t_end + later]))[0, :2]) == (x, y)

