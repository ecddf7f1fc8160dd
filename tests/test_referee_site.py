"""The site's rules around a dig and the truck's ground (rules version 2, docs/referee.md):
``arm_over_machine``, ``dig_under_machine``, ``truck_tilt``, ``truck_step``, ``truck_undercut``.
Each with plans that break it and plans that just keep it, built through the public API."""

from __future__ import annotations

import math

import numpy as np
import shapely
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from earthbench import Budget, Dig, Heightmap, Machines, Move, Plan, Pose, Scenario, Site, Task, judge
from earthbench.motion import swing_time
from earthbench.referee import RULES, RULES_VERSION
from earthbench.rules import arm_shadow, overlap_area, truck_ground
from earthbench.world import ExcavatorSpec, LoaderSpec, TruckSpec

BASE = Pose(10.0, 10.0, -math.pi / 2)
EAST = Pose(16.0, 10.0, math.pi)
SPEC = ExcavatorSpec()
NEW = {"arm_over_machine", "dig_under_machine", "truck_tilt", "truck_step", "truck_undercut"}


def site(z: np.ndarray | None = None, truck: Pose = EAST, loader: Pose | None = None, **spec) -> Scenario:
    """A flat 20 m × 14 m map at 0.1 m cells (height 0, floor −1), the excavator at (10, 10)
    facing south, the dig area south of it; ``z`` replaces the heights."""
    heights = np.zeros((140, 200)) if z is None else z
    return Scenario(
        id="test/site",
        terrain=Heightmap((0.0, 0.0), 0.1, heights),
        site=Site(((4, 1), (16, 1), (16, 8), (4, 8)), floor=-1.0),
        machines=Machines(excavator=ExcavatorSpec(**spec), excavator_pose=BASE, truck_pose=truck,
                          loader=LoaderSpec() if loader else None, loader_pose=loader),
        task=Task(0.28),
        budget=Budget(wall_s=60),
    )


def dig(contact: tuple[float, float], heading: float | None = None, t0: float = 0.0, depth: float = 0.3, spec=SPEC) -> Dig:
    if heading is None:  # drag toward the base
        heading = math.atan2(BASE.y - contact[1], BASE.x - contact[0])
    d = swing_time(BASE, 0.0, contact, spec) + spec.min_stroke_time + 1e-6
    return Dig("excavator", t0, t0 + d, contact, heading, depth, 1.0)


def rules(sc: Scenario, *actions) -> set[str]:
    return {v.rule for v in judge(sc, Plan(tuple(actions))).violations}


def drive(start: Pose, goal: tuple[float, float], t0: float = 0.0, speed: float = 0.8) -> Move:
    d = math.hypot(goal[0] - start.x, goal[1] - start.y)
    return Move("truck", ((t0, start.x, start.y, start.yaw), (t0 + d / speed, goal[0], goal[1], start.yaw)))


def test_the_new_rules_are_described_and_versioned():
    assert NEW <= set(RULES)
    assert RULES_VERSION == 2


# -- arm_over_machine ------------------------------------------------------------------------

def test_a_truck_between_the_base_and_the_bucket_is_under_the_arm():
    sc = site(truck=Pose(10.0, 6.45, 0.0))  # 3.55 m from the base: clearance kept, bucket 0.15 m off its body
    assert rules(sc, dig((10.0, 4.5), math.pi / 2)) == {"arm_over_machine"}


def test_a_truck_beside_the_arm_keeps_the_rule():
    sc = site(truck=Pose(12.5, 6.5, math.pi / 2))
    assert rules(sc, dig((10.0, 4.5), math.pi / 2)) == set()


def test_a_truck_that_drives_under_the_arm_during_the_stroke_is_caught():
    start = Pose(14.0, 6.45, math.pi)
    sc = site(truck=start)
    d = dig((10.0, 4.5), math.pi / 2)
    assert rules(sc, d) == set()  # where it stands
    assert "arm_over_machine" in rules(sc, d, drive(start, (10.0, 6.45), t0=0.5, speed=0.86))


def test_the_swing_before_the_stroke_is_not_the_stroke():
    """The bucket swings raised to the contact's bearing first; a truck leaving the shadow's
    ground during that swing keeps the rule, one still there when the stroke starts does not."""
    sc0 = site(truck=Pose(10.0, 6.45, 0.0))
    spec = ExcavatorSpec()
    contact = (10.0, 4.5)
    # a previous dig to the north leaves the arm pointing 180° away: 2.86 s of swing to this contact
    first = Dig("excavator", 0.0, 10.0, (10.0, 14.5), -math.pi / 2, 0.3, 1.0)
    turn = math.pi
    swing = swing_time(BASE, turn, contact, spec)
    t0 = 30.0  # (no dump between: it would swing the arm to the truck, on this contact's bearing)
    second = Dig("excavator", t0, t0 + swing + spec.min_stroke_time + 1e-6, contact, math.pi / 2, 0.3, 1.0)
    start = sc0.machines.truck_pose
    leave_early = Move("truck", ((t0, start.x, start.y, 0.0), (t0 + swing * 0.9, start.x + 2.0, start.y, 0.0)))
    leave_late = Move("truck", ((t0 + swing + 0.5, start.x, start.y, 0.0), (t0 + swing + 3.0, start.x + 2.0, start.y, 0.0)))
    sc = site(truck=start)
    assert "arm_over_machine" not in rules(sc, first, second, leave_early)
    assert "arm_over_machine" in rules(sc, first, second, leave_late)


def test_a_loader_under_the_arm_on_a_mixed_site():
    loader = Pose(11.5, 6.6, 0.0)  # the body reaches 2.9 m behind, 0.5 m ahead of the front axle
    sc = site(loader=loader)
    assert "arm_over_machine" in rules(sc, dig((10.0, 4.5), math.pi / 2))
    assert "arm_over_machine" not in rules(site(loader=Pose(16.0, 4.0, 0.0)), dig((10.0, 4.5), math.pi / 2))


# -- dig_under_machine -----------------------------------------------------------------------

def test_digging_under_the_truck():
    sc = site(truck=Pose(14.5, 6.0, math.pi / 2))  # body x 13.7–15.3, y 4.4–7.6
    assert rules(sc, dig((13.2, 6.0))) == set()  # the bucket's corner stops 0.23 m short of its body
    got = rules(sc, dig((14.0, 6.0)))
    assert "dig_under_machine" in got and "arm_over_machine" not in got  # under the bucket: named once, as the worse


def test_digging_under_its_own_tracks():
    spec = {"reach_min": 1.0}  # a reach that lets the bucket come in under the tracks (1.3 m ahead of the base)
    sc = site(**spec)
    assert "dig_under_machine" in rules(sc, dig((10.0, 8.5), 0.0, spec=ExcavatorSpec(**spec)))
    assert "dig_under_machine" not in rules(sc, dig((10.0, 8.1), 0.0, spec=ExcavatorSpec(**spec)))


# -- truck_undercut ------------------------------------------------------------------------

def test_a_dig_that_lowers_the_ground_under_the_parked_truck():
    sc = site(truck=Pose(14.5, 6.0, math.pi / 2))
    assert "truck_undercut" in rules(sc, dig((14.0, 6.0)))
    assert "truck_undercut" not in rules(sc, dig((13.2, 6.0)))


# -- the truck's ground: truck_step, truck_tilt -----------------------------------------------

def _trench(depth: float, x0: float = 12.0, width: float = 0.5) -> np.ndarray:
    z = np.zeros((140, 200))
    z[:, int(round(x0 * 10)):int(round((x0 + width) * 10))] = -depth
    return z


def test_the_truck_drives_into_a_trench():
    start = Pose(16.0, 3.0, math.pi)
    assert rules(site(_trench(0.4), truck=start), drive(start, (8.0, 3.0))) == {"truck_step"}
    assert rules(site(_trench(0.08), truck=start), drive(start, (8.0, 3.0))) == set()


def test_the_truck_drives_into_the_excavation_it_saw_dug():
    start = Pose(16.0, 4.0, math.pi)
    sc = site(truck=start)
    d = dig((12.0, 4.0), math.pi / 2, depth=0.4)  # a 0.4 m deep pit across its way
    move = drive(start, (9.0, 4.0), t0=d.t_end + 1.0)
    assert "truck_step" in rules(sc, d, move)
    assert "truck_step" not in rules(sc, move)


def _ramp(grade_x: float, grade_y: float) -> np.ndarray:
    x = (np.arange(200) + 0.5) * 0.1
    y = (np.arange(140) + 0.5) * 0.1
    return grade_x * x[None, :] + grade_y * y[:, None]


def test_grade_and_cross_slope_limits():
    start = Pose(17.0, 12.0, math.pi)  # drives west, along x
    move = drive(start, (13.0, 12.0))
    assert rules(site(_ramp(0.22, 0.0), truck=start), move) == set()  # 22 % along: within 25 %
    assert rules(site(_ramp(0.30, 0.0), truck=start), move) == {"truck_tilt"}
    assert rules(site(_ramp(0.0, 0.12), truck=start), move) == set()  # 12 % across: within 16 %
    assert rules(site(_ramp(0.0, 0.20), truck=start), move) == {"truck_tilt"}


def test_truck_ground_predicate_reads_a_plane_exactly():
    sc = site(_ramp(0.1, 0.05))
    grade, cross, step = truck_ground(sc, sc.terrain.z, TruckSpec(), np.array([[10.0, 7.0, 0.0], [10.0, 7.0, math.pi / 2]]))
    assert np.allclose(grade, [0.1, 0.05]) and np.allclose(cross, [0.05, 0.1]) and np.all(step < 1e-9)


def test_the_truck_ground_limits_stay_out_of_the_digest():
    sc = site()
    assert "max_grade" not in sc.to_json() and "max_step" not in sc.to_json()
    other = Machines(truck=TruckSpec(max_step=0.3), excavator_pose=BASE, truck_pose=sc.machines.truck_pose)
    assert sc.replace(machines=other).digest != sc.digest


# -- properties: a plan that breaks the limit is always caught --------------------------------

SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@SETTINGS
@given(st.floats(6.0, 14.0), st.floats(2.0, 7.5), st.floats(-math.pi, math.pi), st.floats(1.05 * math.pi, 1.95 * math.pi))
def test_any_truck_the_arm_or_bucket_reaches_over_is_caught(x, y, yaw, angle):
    """A truck whose body shares area with the hull of the base and the bucket's footprint
    (computed here with shapely, apart from the referee) is always flagged; one clear of it never."""
    contact = (10.0 + 4.5 * math.cos(angle), 10.0 + 4.5 * math.sin(angle))
    heading = math.atan2(BASE.y - contact[1], BASE.x - contact[0])
    sc = site(truck=Pose(x, y, yaw))
    bucket = shapely.Polygon([(contact[0] + dx * math.cos(heading) - dy * math.sin(heading),
                               contact[1] + dx * math.sin(heading) + dy * math.cos(heading))
                              for dx, dy in ((0, -0.35), (1, -0.35), (1, 0.35), (0, 0.35))])
    hull = shapely.MultiPoint([(BASE.x, BASE.y), *bucket.exterior.coords]).convex_hull
    body = shapely.Polygon(TruckSpec().body(x, y, yaw)[0])
    got = rules(sc, dig(contact, heading)) & {"arm_over_machine", "dig_under_machine"}
    if body.intersection(hull).area > 1e-4:
        assert got
    elif body.distance(hull) > 1e-4:
        assert not got


@SETTINGS
@given(st.floats(0.0, 0.7), st.floats(9.0, 15.0), st.floats(0.3, 1.5))
def test_any_trench_deeper_than_the_step_is_caught(depth, x0, width):
    start = Pose(18.0, 3.0, math.pi)
    got = rules(site(_trench(depth, x0, width), truck=start), drive(start, (6.0, 3.0)))
    if depth >= 0.3:
        assert "truck_step" in got
    elif depth <= 0.1:
        assert not got & {"truck_step", "truck_tilt"}


def test_overlap_area_is_zero_apart_and_the_shared_area_when_over():
    shadow = arm_shadow(BASE, (10.0, 4.5), math.pi / 2, 0.7, 1.0)
    assert overlap_area(shadow, TruckSpec(), np.array([[16.0, 10.0, 0.0]]))[0] == 0.0
    # the truck across the shadow's wedge, 0.7 m wide at the bucket (y = 5.5) narrowing to the base
    # (y = 10): between y = 6.7 and 8.3 it holds 0.7 / 4.5 × (3.3² − 1.7²) / 2 = 0.622 m²
    assert math.isclose(overlap_area(shadow, TruckSpec(), np.array([[10.0, 7.5, 0.0]]))[0], 0.7 / 4.5 * 4.0, rel_tol=1e-9)
