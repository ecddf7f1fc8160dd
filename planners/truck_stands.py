"""Where the truck may stand while an excavator digs, and the stand that costs a cycle least.

The site rules (rules version 2, docs/referee.md) keep the truck's body out of the arm's ground
shadow during a dig's stroke (:func:`earthbench.rules.arm_shadow`), every machine's body out of
the bucket's footprint, and the truck on ground within its grade, cross-slope and step limits
(:func:`earthbench.rules.truck_ground`) that no dig lowers while it stands there. A stand off
the dig area, on such ground and clear of the shadow, keeps them all; issue 49's witness shows what such a stand can still
save: on the bearing of the dig, beyond the contact, the dump costs no swing. ``greedy`` and
``singh-cannon-backhoe`` share this: the truck slides along its heading (no slow turn in place)
during a dig to the stand nearest the dig's bearing, and at a new station it is parked
broadside to where the material lies (docs/DESIGN.md §6).
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import shapely
from shapely.geometry import Polygon

from earthbench.motion import dense_poses, poses_at, turn_drive_turn, wrap
from earthbench.rules import arm_shadow, reach_of, truck_ground
from earthbench.world import ExcavatorSpec, Pose, Scenario

#: Metres the truck's body keeps from the dig area, the arm's shadow and keep-outs: a cell and
#: the referee's sampling of motion, so a stand that just clears them in the plan clears them there.
GAP = 0.15
#: What the truck keeps below its ground limits (grade and cross-slope, rise over run; step, m).
SLOPE_MARGIN, STEP_MARGIN = 0.02, 0.03
#: Spacing (m) of the stands along the truck's heading, and how far either way they go.
STEP, SPAN = 0.1, 6.0
#: A move's samples (t, x, y, yaw).
Sample = tuple[float, float, float, float]
#: Share of its speed and yaw rate limits a machine drives at (``turn_drive_turn``'s default
#: margin), so rounding never breaks a limit.
MARGIN = 0.999
#: Largest turn (rad) between two samples of an arc (the referee joins them by the same arc; the
#: chord strays 2 cm from it at the truck's tightest full-speed radius, for checks on the chords).
ARC_PIECE = 0.15


class TruckStands:
    """The site's geometry for the truck's stands (one per planning session)."""

    def __init__(self, sc: Scenario, spec: ExcavatorSpec, z: np.ndarray):
        """``z``: the planner's grid as it digs (read, never written)."""
        self.sc, self.spec, self.truck, self.z = sc, spec, sc.machines.truck, z
        self.area = Polygon(sc.site.dig_area).buffer(GAP)
        self.keep_outs = [Polygon(k).buffer(GAP) for k in sc.site.keep_outs]
        for p in (self.area, *self.keep_outs):
            shapely.prepare(p)

    def ground_kept(self, poses: np.ndarray) -> np.ndarray:
        """Whether the truck's ground at each of ``poses[k, 3]`` keeps its grade, cross-slope and
        step limits (:func:`earthbench.rules.truck_ground`, with margins)."""
        t = self.truck
        grade, cross, step = truck_ground(self.sc, self.z, t, poses)
        return (grade <= t.max_grade - SLOPE_MARGIN) & (cross <= t.max_cross_slope - SLOPE_MARGIN) & (step <= t.max_step - STEP_MARGIN)

    def path_ok(self, samples: list[tuple[float, float, float, float]] | np.ndarray) -> bool:
        """Whether the truck's ground keeps its limits all along the move ``samples[k, 4]``."""
        p = np.asarray(samples, dtype=float).reshape(-1, 4)
        reach = reach_of(self.truck.body(0.0, 0.0, 0.0))
        for spacing in (1.0, max(self.sc.terrain.resolution, 0.1)):  # most ways that fail, fail coarsely
            if not self.ground_kept(dense_poses(p, spacing, reach)[:, 1:4]).all():
                return False
        return True

    def bodies(self, poses: np.ndarray) -> np.ndarray:
        """The truck's body at each of ``poses[k, 3]`` as shapely polygons."""
        p = np.asarray(poses, dtype=float).reshape(-1, 3)
        return shapely.polygons(self.truck.body(p[:, 0], p[:, 1], p[:, 2]))

    def ground_ok(self, poses: np.ndarray) -> np.ndarray:
        """Whether each stand keeps its body off the dig area and keep-outs, on ground within
        its limits."""
        p = np.asarray(poses, dtype=float).reshape(-1, 3)
        if len(p) == 0:
            return np.zeros(0, dtype=bool)
        polys = self.bodies(p)
        ok = ~shapely.intersects(self.area, polys)
        for k in self.keep_outs:
            ok &= ~shapely.intersects(k, polys)
        if ok.any():
            ok[ok] = self.ground_kept(p[ok])
        return ok

    def in_reach(self, base: Pose, xy: np.ndarray, clearance_pad: float = 0.1) -> np.ndarray:
        """Whether truck centres ``xy[k, 2]`` are in dump reach of ``base`` and the clearance from it."""
        d = np.hypot(xy[:, 0] - base.x, xy[:, 1] - base.y)
        r, e = self.truck.loading_radius, self.spec
        return (d - r <= e.reach_max - 0.05) & (d + r >= e.reach_min + 0.05) & (d >= e.clearance + clearance_pad)

    def line(self, truck: Pose, base: Pose) -> tuple[np.ndarray, np.ndarray]:
        """Stands ``[k, 3]`` along the truck's heading through where it stands, in dump reach of
        ``base``, with their ground kept (where it stands first when it qualifies), and what
        the truck sweeps driving to each (:meth:`swept`)."""
        s = np.concatenate([[0.0], np.arange(STEP, SPAN + 1e-9, STEP), -np.arange(STEP, SPAN + 1e-9, STEP)])
        p = np.column_stack([truck.x + s * math.cos(truck.yaw), truck.y + s * math.sin(truck.yaw), np.full(len(s), truck.yaw)])
        # stands the truck reaches on kept ground, one after the other either way from where it is
        good = self.ground_ok(p)
        run = np.zeros(len(s), dtype=bool)
        for side in (s >= 0, s <= 0):
            idx = np.flatnonzero(side)
            idx = idx[np.argsort(np.abs(s[idx]))]
            run[idx] = np.cumprod(good[idx]).astype(bool)
        keep = run & self.in_reach(base, p[:, :2])
        # the way there keeps the excavator's clearance
        keep &= np.array([_segment_distance(base, (truck.x, truck.y), (x, y)) >= self.spec.clearance + 0.1 for x, y in p[:, :2]])
        return p[keep], self.swept(truck, p[keep])

    def sweep_between(self, samples: list[tuple[float, float, float, float]] | np.ndarray, t0: float, t1: float) -> Polygon | None:
        """What the truck's body covers from ``t0`` to ``t1`` on the move ``samples[k, 4]`` (its
        bodies at poses a cell apart, joined); None when it stands still by then."""
        p = np.asarray(samples, dtype=float).reshape(-1, 4)
        if t0 >= p[-1, 0] or t1 < t0:
            return None
        dense = dense_poses(p, max(self.sc.terrain.resolution, 0.1), reach_of(self.truck.body(0.0, 0.0, 0.0)))
        inside = dense[(dense[:, 0] > t0) & (dense[:, 0] < t1), 1:4]
        ends = poses_at(p, np.array([t0, t1]))
        return shapely.union_all(self.bodies(np.vstack([ends, inside])))

    def shadow(self, base: Pose, contact: tuple[float, float], heading: float, drag: float) -> Polygon:
        """The arm's ground shadow of a dig (:func:`earthbench.rules.arm_shadow`); the truck
        keeps :data:`GAP` from it."""
        return Polygon(arm_shadow(base, contact, heading, self.spec.bucket_width, drag))

    def swept(self, start: Pose, stands: np.ndarray) -> np.ndarray:
        """What the truck's body sweeps driving straight from ``start`` to each stand (same
        yaw): the hull of its body at both ends."""
        if len(stands) == 0:
            return np.zeros(0, dtype=object)
        a = self.truck.body(start.x, start.y, start.yaw)[0]
        b = self.truck.body(stands[:, 0], stands[:, 1], stands[:, 2])
        return shapely.convex_hull(shapely.multipoints(np.concatenate([np.broadcast_to(a, b.shape), b], axis=1)))

    def best_for_dig(self, base: Pose, truck: Pose, stands: tuple[np.ndarray, np.ndarray], contact: tuple[float, float], heading: float,
                     drag: float, dig_start: float, dig_end: float, free_at: float = 0.0,
                     pending: Polygon | None = None) -> tuple[Pose, float, float] | None:
        """The stand of ``stands`` (:meth:`line`: the stands and what the truck sweeps driving
        to each straight from ``truck`` during the dig) whose dump after the dig finishes
        soonest: (stand, its arrival time, the dump's swing in rad). None when the truck
        cannot stay out of the arm's shadow. The truck sets off at ``free_at`` at the earliest;
        ``pending`` is what it still sweeps on its way to ``truck`` (None: it stands there)."""
        poses, sweeps = stands
        if len(poses) == 0:
            return None
        shadow = self.shadow(base, contact, heading, drag)
        if pending is not None and shapely.distance(shadow, pending) <= GAP:
            return None
        ok = shapely.distance(shadow, sweeps) > GAP
        if not ok.any():
            return None
        st = poses[ok]
        dist = np.hypot(st[:, 0] - truck.x, st[:, 1] - truck.y)
        arrive = max(dig_start, free_at) + dist / self.truck.travel_speed  # for the choice; the plan times the real drive
        to_contact = math.atan2(contact[1] - base.y, contact[0] - base.x)
        swing = np.abs(np.asarray(wrap(np.arctan2(st[:, 1] - base.y, st[:, 0] - base.x) - to_contact)))
        done = np.maximum(arrive, dig_end) + swing / self.spec.swing_rate
        k = int(np.argmin(done + 1e-3 * dist))
        return Pose(float(st[k, 0]), float(st[k, 1]), float(st[k, 2])), float(arrive[k]), float(swing[k])

    def drive_times(self, truck: Pose, x: np.ndarray, y: np.ndarray, yaw: np.ndarray,
                    arcs: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """The truck's least time (s) from ``truck`` to each stand ``(x, y, yaw)`` the way
        :func:`drive` goes (turn, drive, turn; or arc, drive, turn; without ``arcs`` the first
        only, as :func:`earthbench.motion.turn_drive_turn`), and the stand's yaw (``yaw`` or its
        reverse, the same body: whichever ends the shorter turn in place)."""
        t = self.truck
        arrive = _arrival(truck, x, y)
        travel = np.arctan2(y - truck.y, x - truck.x)
        turn_in = np.abs(_wrap(travel - truck.yaw))
        turn_in = np.where(np.hypot(x - truck.x, y - truck.y) > 1e-6, np.minimum(turn_in, math.pi - turn_in), 0.0)
        turn_out = np.abs(_wrap(yaw - arrive))
        yaw = np.where(turn_out > math.pi / 2, yaw + math.pi, yaw)  # the same body, the shorter turn
        turn_out = np.minimum(turn_out, math.pi - turn_out)
        time = (turn_in + turn_out) / t.yaw_rate + np.hypot(x - truck.x, y - truck.y) / t.travel_speed
        for side in (1, -1) if arcs else ():  # or on an arc, then straight, then turning in place
            arc_time, heading = arc_times(truck, x, y, t.travel_speed, t.yaw_rate, side)
            time = np.minimum(time, arc_time + np.abs(_wrap(yaw - heading)) / t.yaw_rate)
        return time, _wrap(yaw)

    def parking(self, base: Pose, truck: Pose, bearing: float, buckets: float, arcs: bool = False) -> Iterator[Pose]:
        """Stands for a truck serving ``base`` whose material lies toward ``bearing``, cheapest
        first: the truck's time to get there (turn, drive, turn; with ``arcs`` also arc, drive,
        turn: :func:`drive`) plus ``buckets`` cycles' swing
        between that bearing and the stand. Each stand is offered broadside to the bearing (the
        truck can then slide along the face), radial, or as the truck arrives (no last turn; with ``arcs`` also off an arc);
        all keep the truck's ground, off the dig area, in dump reach."""
        e, t = self.spec, self.truck
        rad = np.arange(e.reach_max + t.loading_radius - 0.1, e.clearance + 0.2, -0.3)
        ang = bearing + np.radians(np.arange(-180, 180, 7.5))
        R, A = np.meshgrid(rad, ang)
        x, y = base.x + R.ravel() * np.cos(A.ravel()), base.y + R.ravel() * np.sin(A.ravel())
        arrive = _arrival(truck, x, y)
        poses, costs = [], []
        headings = [arc_times(truck, x, y, t.travel_speed, t.yaw_rate, side)[1] for side in (1, -1)] if arcs else []
        for yaw in (A.ravel() + math.pi / 2, A.ravel(), arrive, *headings):
            time, yaw = self.drive_times(truck, x, y, yaw, arcs)
            poses.append(np.column_stack([x, y, yaw]))
            costs.append(time + buckets * 2 * np.abs(_wrap(A.ravel() - bearing)) / e.swing_rate)
        here = abs(_wrap(np.array([math.atan2(truck.y - base.y, truck.x - base.x) - bearing])))
        poses.append(np.array([[truck.x, truck.y, truck.yaw]]))
        costs.append(buckets * 2 * here / e.swing_rate)  # staying where it is
        p, c = np.vstack(poses), np.concatenate(costs)
        ok = self.in_reach(base, p[:, :2], 0.3)
        p, c = p[ok], c[ok]
        p = p[np.argsort(c, kind="stable")]
        for start in range(0, len(p), 64):  # the ground is looked at only as far as it is needed
            block = p[start:start + 64]
            for a, b, w in block[self.ground_ok(block)]:
                yield Pose(float(a), float(b), float(w))


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + math.pi) % (2 * math.pi) - math.pi


def _arrival(truck: Pose, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The truck's heading on arriving straight at each ``(x, y)`` (reversing when that turn is shorter)."""
    travel = np.arctan2(y - truck.y, x - truck.x)
    turn_in = np.abs(_wrap(travel - truck.yaw))
    arrive = np.where(turn_in > math.pi / 2, travel + math.pi, travel)
    return np.where(np.hypot(x - truck.x, y - truck.y) > 1e-6, arrive, truck.yaw)


def arc_times(start: Pose, x: np.ndarray, y: np.ndarray, speed: float, yaw_rate: float,
              side: int) -> tuple[np.ndarray, np.ndarray]:
    """Driving from ``start`` forward on the arc of the tightest radius at full speed
    (``speed / yaw_rate``) turning to ``side`` (+1 left, −1 right) until the heading points at
    each goal ``(x, y)``, then straight to it: the time (s; inf where the goal lies inside the
    circle) and the heading on arrival (rad). A truck turns 0.11 rad/s: turning in place first
    costs 7.7 s for 48°, where this arc covers ground meanwhile."""
    v, w = speed * MARGIN, yaw_rate * MARGIN
    radius = speed / yaw_rate
    cx = start.x - side * radius * math.sin(start.yaw)
    cy = start.y + side * radius * math.cos(start.yaw)
    d = np.hypot(x - cx, y - cy)
    inside = d <= radius + 1e-9
    d = np.where(inside, radius + 1.0, d)
    tangent = np.arctan2(y - cy, x - cx) - side * np.arccos(radius / d)  # the angle (from the centre) where it leaves the circle
    swept = np.mod(side * (tangent - (start.yaw - side * math.pi / 2)), 2 * math.pi)
    time = swept / w + np.sqrt(d * d - radius * radius) / v
    return np.where(inside, np.inf, time), _wrap(tangent + side * math.pi / 2)


def drive(start: Pose, goal: tuple[float, float], t0: float, speed: float, yaw_rate: float,
          final_yaw: float | None = None) -> list[Sample]:
    """The faster way from ``start`` to ``goal`` (and ``final_yaw``, turned in place at the end):
    :func:`earthbench.motion.turn_drive_turn`, or an arc at full speed and yaw rate either way
    then straight (:func:`arc_times`), sampled every :data:`ARC_PIECE` of turn."""
    best = turn_drive_turn(start, goal, t0, speed, yaw_rate, final_yaw=final_yaw)
    gx, gy = np.array([goal[0]]), np.array([goal[1]])
    w, radius = yaw_rate * MARGIN, speed / yaw_rate
    for side in (1, -1):
        time, heading = arc_times(start, gx, gy, speed, yaw_rate, side)
        if not math.isfinite(time[0]):
            continue
        turn_out = 0.0 if final_yaw is None else abs(wrap(final_yaw - float(heading[0])))
        if t0 + float(time[0]) + turn_out / w >= best[-1][0] - 1e-9:
            continue
        cx, cy = start.x - side * radius * math.sin(start.yaw), start.y + side * radius * math.cos(start.yaw)
        swept = float(np.mod(side * (float(heading[0]) - start.yaw), 2 * math.pi))
        pieces = max(int(math.ceil(swept / ARC_PIECE)), 1)
        samples: list[Sample] = [(t0, start.x, start.y, start.yaw)]
        for k in range(1, pieces + 1):
            yaw = start.yaw + side * swept * k / pieces
            a = yaw - side * math.pi / 2
            samples.append((t0 + swept * k / pieces / w, cx + radius * math.cos(a), cy + radius * math.sin(a), yaw))
        rest = turn_drive_turn(Pose(*samples[-1][1:]), goal, samples[-1][0], speed, yaw_rate, final_yaw=final_yaw,
                               allow_reverse=False)
        best = samples + rest[1:]
    return best


def _segment_distance(p: Pose, a: tuple[float, float], b: tuple[float, float]) -> float:
    ax, ay = a
    bx, by = b
    dx, dy = bx - ax, by - ay
    n = dx * dx + dy * dy
    t = 0.0 if n < 1e-12 else max(0.0, min(1.0, ((p.x - ax) * dx + (p.y - ay) * dy) / n))
    return math.hypot(ax + t * dx - p.x, ay + t * dy - p.y)
