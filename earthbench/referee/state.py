"""The judge's state as it replays a plan (:class:`Replay`: its heightmap, truck load, machine
poses and violations so far), the verdict it returns, and the rules every machine shares:
motion between samples, keep-out zones, the map's edge and machine–machine clearance along the
swept paths. (Up to 0.2.0 this module was ``earthbench.referee.replay``; that name still
imports, with a warning, for a release.)

Motion between two samples is the arc of :mod:`earthbench.motion`; every rule here samples it
with :func:`~earthbench.motion.dense_poses` at half a cell (and so that no footprint corner
moves more than that between two poses), so a plan cannot pass by being sampled sparsely.
"""

from __future__ import annotations

import bisect
import hashlib
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely

from ..cut import Cut, cut_along, cut_heights, lowered, path_cells
from ..motion import ABS_TOL, RATE_TOL, arcs, dense_poses, poses_at, sample_yaws, wrap
from ..plan import Charge, Move, Plan
from ..soil import cut_levels, hard_top, slump_box, slump_cells
from ..rules import Spec
from ..rules import bodies_touch as _bodies_touch
from ..rules import off_map_excess as _off_map_excess
from ..rules import reach_of as _reach_of
from ..world import Pose, Scenario, TruckSpec

#: The chord (m) below which the heading rule's lateral slack shrinks in proportion: a sample
#: may leave its arc by ``chord_tolerance`` over a chord this long or longer, and by that share
#: of it over a shorter one, so no chain of short steps slides a machine sideways (rules 2).
SLIP_LENGTH = 1.0


#: The version of the rules below. Bumped whenever a rule is added or changes what it refuses,
#: so a stored verdict says which rules judged it (docs/referee.md, "Rules versions"): 1 until
#: 0.x (no row recorded it), 2 adds the machines near a dig and the truck's ground.
RULES_VERSION = 2

#: Every rule the referee checks, with the sentence a report shows for it.
RULES: dict[str, str] = {
    "malformed": "the plan document could not be read",
    "unknown_machine": "the action names a machine that is not on site",
    "wrong_machine": "the machine cannot perform this action",
    "overlap": "the action starts before the same machine's previous action ended",
    "discontinuous": "a move does not start where the machine is",
    "speed": "travel speed along the arc between two samples above the machine's limit",
    "yaw_rate": "yaw rate above the machine's limit",
    "heading": "no arc along both samples' headings (forward or reverse) joins the two samples",
    "keep_out": "a machine's footprint or bucket enters a keep-out zone anywhere along its path",
    "off_map": "a machine's footprint leaves the map, whose outside is not open ground",
    "bucket_not_empty": "a dig starts with material still in the bucket",
    "cut_depth": "cut depth above the machine's limit",
    "drag_length": "drag length above the machine's limit",
    "reach": "the stroke leaves the reach annulus around the base",
    "outside_dig_area": "the bucket footprint leaves the dig area",
    "below_floor": "the cut level lies below the floor (design grade)",
    "undermining": "the excavator cuts under or too close to its own tracks",
    "tilt": "the excavator works standing on ground steeper than its limit",
    "duration": "the action is shorter than the swing plus its minimum time",
    "truck_moving": "the truck moves during a dump",
    "dump_reach": "the truck is out of the bucket's reach",
    "collision": "machines closer than the clearance, or their footprints touch, anywhere along their paths",
    "entry_pose": "a charge does not start at the loader's pose",
    "penetration_speed": "a charge drives faster than the loader's penetration speed",
    "overfill": "the cutting edge pushes on through material after the bucket is full",
    "turning_radius": "a loader move turns tighter than its minimum turning radius",
    "step": "a loader's wheels cross a cell higher than its traversable step above the floor",
    "arm_over_machine": "during a dig's stroke another machine's body stands in the arm's ground shadow (base to bucket)",
    "dig_under_machine": "a dig's or charge's bucket footprint reaches under a machine's footprint (the digger's own included)",
    "truck_tilt": "the truck drives or stands on ground steeper than its grade or cross-slope limit",
    "truck_step": "the ground under the truck departs from its plane by more than its step (a bank, a hole, a cut's face)",
    "truck_undercut": "a dig lowers ground the truck stands on",
}


@dataclass(frozen=True)
class Violation:
    """One broken rule: the action's index in the plan (None: the plan as a whole)."""

    action: int | None
    rule: str
    magnitude: float
    message: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"action": self.action, "rule": self.rule, "magnitude": self.magnitude, "message": self.message}


@dataclass(frozen=True)
class DigRecord:
    """One dig or charge: the bank volume it really removed, that ÷ the bucket's capacity, and
    (only on a scenario with soil) ``nominal``: what the public cut model
    (:mod:`earthbench.cut`) removes on the same ground, the planner's best prediction."""

    action: int
    volume: float
    fill: float
    nominal: float | None = None

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"action": self.action, "volume": self.volume, "fill": self.fill}
        if self.nominal is not None:
            d["nominal"] = self.nominal
        return d


@dataclass(frozen=True)
class Verdict:
    """What the referee measured. ``valid`` is True only when ``violations`` is empty."""

    violations: tuple[Violation, ...]
    final_terrain: Any
    loaded_volume: float
    removed_volume: float
    makespan: float
    digs: tuple[DigRecord, ...] = ()
    dumps: int = 0
    travel: dict[str, float] = field(default_factory=dict)
    #: (end time, cumulative loaded volume) after each dump, in replay order: when the truck got what.
    load_curve: tuple[tuple[float, float], ...] = ()
    #: Where each machine stands when the plan ends (what a closed-loop step continues from).
    final_poses: dict[str, Pose] = field(default_factory=dict)
    #: The excavator's upper body relative to its base yaw when the plan ends (rad).
    final_turn: float = 0.0
    #: Bank m³ left in the bucket when the plan ends (a dump into a full truck leaves some).
    final_bucket: float = 0.0

    @property
    def valid(self) -> bool:
        return not self.violations

    def to_dict(self) -> dict[str, Any]:
        """The verdict as plain JSON values; the final terrain as the sha256 of its heights
        (little-endian float64), so two verdicts compare byte for byte."""
        z = np.ascontiguousarray(self.final_terrain.z, dtype="<f8")
        return {
            "valid": self.valid,
            "violations": [v.to_dict() for v in self.violations],
            "loaded_volume": self.loaded_volume,
            "removed_volume": self.removed_volume,
            "makespan": self.makespan,
            "digs": [d.to_dict() for d in self.digs],
            "dumps": self.dumps,
            "travel": dict(self.travel),
            "load_curve": [list(p) for p in self.load_curve],
            "final_terrain_sha256": hashlib.sha256(z.tobytes()).hexdigest(),
        }

    def summary(self) -> str:
        if self.valid:
            return "valid"
        rules = sorted({v.rule for v in self.violations})
        return f"invalid ({len(self.violations)} violations: {', '.join(rules)})"


def _polygons(corners: np.ndarray) -> np.ndarray:
    return shapely.polygons(np.concatenate([corners, corners[:, :1]], axis=1))


class Timeline:
    """A machine's samples over time (its start, then every move and charge), on the motion model."""

    def __init__(self, start: Pose, moves: list[Move]):
        samples = [(0.0, start.x, start.y, start.yaw)]
        for m in sorted(moves, key=lambda m: m.t_start):
            samples.extend(m.path)
        self.path = np.array(samples, dtype=float)
        self.arc = arcs(self.path) if len(self.path) > 1 else None
        self.times = self.path[:, 0].tolist()
        self.yaw0 = sample_yaws(self.path, self.arc).tolist() if self.arc is not None else []
        self.moves = [(m.t_start, m.t_end) for m in moves]

    def poses(self, times: np.ndarray) -> np.ndarray:
        return poses_at(self.path, times, self.arc)

    def rates(self, times: np.ndarray, reach: float) -> np.ndarray:
        """Speed of the centre plus yaw rate × ``reach`` (a body corner) at ``times``."""
        if self.arc is None:
            return np.zeros(len(times))
        k = np.clip(np.searchsorted(self.path[:, 0], times, side="right") - 1, 0, len(self.path) - 2)
        dt = self.arc["dt"][k]
        with np.errstate(divide="ignore", invalid="ignore"):
            v = np.where(dt > 0, (self.arc["length"][k] + np.abs(self.arc["dyaw"][k]) * reach) / dt, 0.0)
        inside = (times >= self.path[0, 0]) & (times <= self.path[-1, 0])
        return np.where(inside, v, 0.0)

    def pose(self, t: float) -> Pose:
        """The pose at ``t`` (:func:`~earthbench.motion.poses_at` for one time, in plain floats)."""
        p, a = self.path, self.arc
        if a is None or t <= p[0, 0]:
            return Pose(float(p[0, 1]), float(p[0, 2]), float(p[0, 3]))
        if t >= self.times[-1]:
            return Pose(float(p[-1, 1]), float(p[-1, 2]), self.yaw0[-1])
        k = min(bisect.bisect_right(self.times, t) - 1, len(p) - 2)
        dt = float(a["dt"][k])
        f = min(max((t - p[k, 0]) / dt, 0.0), 1.0) if dt > 0 else 1.0
        dyaw, th0, length = float(a["dyaw"][k]), float(a["theta0"][k]), float(a["length"][k])
        if abs(dyaw) < 1e-9:
            x = p[k, 1] + length * f * math.cos(th0 + f * dyaw / 2)
            y = p[k, 2] + length * f * math.sin(th0 + f * dyaw / 2)
        else:
            x = p[k, 1] + length / dyaw * (math.sin(th0 + f * dyaw) - math.sin(th0))
            y = p[k, 2] + length / dyaw * (math.cos(th0) - math.cos(th0 + f * dyaw))
        return Pose(float(x), float(y), float(self.yaw0[k] + f * dyaw))

    def moving_during(self, t0: float, t1: float) -> bool:
        return any(a < t1 - ABS_TOL and b > t0 + ABS_TOL for a, b in self.moves)


class Replay:
    """State of one judgement: the grid being cut, the machines' poses, bucket and truck loads."""

    def __init__(self, scenario: Scenario, plan: Plan):
        self.sc, self.plan = scenario, plan
        self.terrain = scenario.terrain
        self.z = np.array(scenario.terrain.z, dtype=np.float64)
        self.violations: list[Violation] = []
        self.dig_area = shapely.Polygon(scenario.site.dig_area)
        shapely.prepare(self.dig_area)
        self.dig_area_tol = self.dig_area.buffer(ABS_TOL)
        shapely.prepare(self.dig_area_tol)
        self.keep_outs = [shapely.Polygon(k) for k in scenario.site.keep_outs]
        for k in self.keep_outs:
            shapely.prepare(k)
        self.spacing = scenario.terrain.resolution / 2
        m = scenario.machines
        self.specs: dict[str, Spec] = {"truck": m.truck}
        if m.excavator is not None:
            self.specs["excavator"] = m.excavator
        if m.loader is not None:
            self.specs["loader"] = m.loader
        self.timelines = self._timelines()
        self.busy_until = {mid: 0.0 for mid in m.ids}
        self.pose = {mid: m.pose(mid) for mid in m.ids}
        self.turn = 0.0  # excavator's upper body angle relative to its base yaw
        self.bucket = 0.0
        self.loaded = 0.0
        self.removed = 0.0
        self.digs: list[DigRecord] = []
        self.dumps = 0
        self.load_curve: list[tuple[float, float]] = []
        self.travel = {mid: 0.0 for mid in m.ids}
        self.station: tuple[Pose, float, float] | None = None  # excavator: pose, track level, tilt
        self.memo: dict[Any, Any] = {}  # what a rule computes once per judgement (e.g. the cells under a parked truck)
        self.soil = scenario.soil
        #: bank m³ the truck holds: its capacity counts loose m³ (``Soil.swell``)
        self.truck_capacity = m.truck.capacity if self.soil is None else m.truck.capacity / self.soil.swell
        #: the last cut's slump window, the cells it lowered and the most it lowered one, until :meth:`settle`
        self._unsettled: tuple[tuple[int, int, int, int], np.ndarray, np.ndarray, float] | None = None
        #: with soil and a loader, the firm ground: the heights less the loose material slumping left on top
        self.firm: np.ndarray | None = None if self.soil is None or m.loader is None else self.z.copy()
        #: with soil, the top of its harder layer under every cell (None: no such layer)
        self.hard_top = None if self.soil is None else hard_top(self.soil, self.sc.terrain.z)

    def _timelines(self) -> dict[str, Timeline]:
        m = self.sc.machines
        moves: dict[str, list[Move]] = {mid: [] for mid in m.ids}
        for a in self.plan.actions:
            if isinstance(a, Move) and a.machine in moves:
                moves[a.machine].append(a)
            elif isinstance(a, Charge) and a.machine in moves:  # a charge moves the loader too
                (x, y, yaw), (ex, ey, _) = a.entry, a.end
                if a.t_end > a.t_start:
                    moves[a.machine].append(Move(a.machine, ((a.t_start, x, y, yaw), (a.t_end, ex, ey, yaw))))
        return {mid: Timeline(m.pose(mid), moves[mid]) for mid in m.ids}

    def extend(self, actions: tuple[Any, ...]) -> range:
        """Append a closed-loop step's actions to the plan being replayed (docs/DESIGN.md §6);
        returns their indices. They start no earlier than the plan so far ends, so replaying
        them next gives the state a replay of the whole plan would."""
        n0 = len(self.plan.actions)
        self.plan = Plan(self.plan.actions + tuple(actions))
        self.timelines = self._timelines()
        return range(n0, len(self.plan.actions))

    def flag(self, n: int | None, rule: str, magnitude: float, message: str) -> None:
        self.violations.append(Violation(n, rule, float(magnitude), message))

    def truck_for_dump(self, n: int, t_start: float, t_end: float) -> Pose:
        """Where the truck stands for a dump from ``t_start`` to ``t_end``; a truck that moves
        meanwhile breaks ``truck_moving`` (both machines' dump rule)."""
        truck = self.timelines["truck"]
        if truck.moving_during(t_start, t_end):
            self.flag(n, "truck_moving", 1.0, "the truck moves while the bucket is emptied")
        return truck.pose(t_start)

    def empty_bucket(self, t_end: float) -> None:
        """A dump ending at ``t_end`` moves the bucket's load into the truck, up to its capacity."""
        take = min(self.bucket, max(self.truck_capacity - self.loaded, 0.0))
        self.loaded += take
        self.bucket -= take
        self.dumps += 1
        self.load_curve.append((t_end, self.loaded))

    def verdict(self) -> Verdict:
        return Verdict(
            violations=tuple(self.violations),
            final_terrain=self.terrain.with_z(self.z),
            loaded_volume=self.loaded,
            removed_volume=self.removed,
            makespan=self.plan.makespan,
            digs=tuple(self.digs),
            dumps=self.dumps,
            travel=self.travel,
            load_curve=tuple(self.load_curve),
            final_poses={mid: tl.pose(self.plan.makespan) for mid, tl in self.timelines.items()},
            final_turn=self.turn,
            final_bucket=self.bucket,
        )

    # -- cutting -----------------------------------------------------------------------------
    def cut(
        self,
        contact: tuple[float, float],
        heading: float,
        width: float,
        length: float,
        level: float,
        bucket_capacity: float,
        depth: float | None,
        cells: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> tuple[Cut, Cut | None]:
        """Cut the grid along a stroke or charge into a bucket of ``bucket_capacity`` that
        already holds ``self.bucket``; returns the cut and, with soil, the nominal one.

        Without soil this is :func:`~earthbench.cut.cut_along`. With soil the bucket really
        holds ``fill_factor × bucket_capacity`` bank m³, the harder layer limits the level
        (:func:`~earthbench.soil.cut_levels`), and :meth:`settle` must follow once the rules
        that look at the fresh cut have been checked; the nominal cut is what the public cut
        model does to the same ground (:func:`~earthbench.cut.cut_heights` on the heights read
        once for both).
        """
        if cells is None:
            cells = path_cells(self.terrain, self.z.shape, contact, heading, width, length)
        budget = bucket_capacity - self.bucket
        if self.soil is None:
            return cut_along(self.terrain, self.z, contact, heading, width, length, level, budget, cells), None
        jj, ii, along = cells
        area = self.terrain.resolution * self.terrain.resolution
        heights = self.z[jj, ii]
        nominal = cut_heights(heights, along, level, budget, area)[0]
        levels = cut_levels(self.soil, None if self.hard_top is None else self.hard_top[jj, ii], heights, level)
        real, full, part = cut_heights(heights, along, levels, self.soil.fill_factor * bucket_capacity - self.bucket, area)
        n = full + (part > 0)  # the cells this cut lowers, in path order
        if n:
            was, now = heights[:n], lowered(heights, levels, full, part)
            cj, ci = jj[:n], ii[:n]
            self.z[cj, ci] = now
            lost = was - now
            cut = lost > 1e-12
            if depth is None:  # the highest face the cut can leave
                depth = float(np.max(heights - level, initial=0.0))
            drop = float(np.maximum.reduce(lost))
            if drop > 1e-12:
                window = slump_box(self.z.shape, jj, ii, self.terrain.resolution, depth, self.soil.repose_deg, drop)
                self._unsettled = (window, cj[cut], ci[cut], drop)
            if self.firm is not None:  # the firm ground is never above the heights: only cut cells change
                self.firm[cj, ci] = np.minimum(self.firm[cj, ci], now)
        return real, nominal

    def settle(self) -> None:
        """Slump the faces the last cut left steeper than the soil's angle of repose."""
        if self.soil is not None and self._unsettled is not None:
            (j0, j1, i0, i1), jj, ii, drop = self._unsettled
            slump_cells(self.z, self.terrain.resolution, self.soil.repose_deg, jj, ii, drop, (j0, j1, i0, i1))
            if self.firm is not None:  # what fell is loose: the firm ground only ever goes down
                np.minimum(self.firm[j0:j1, i0:i1], self.z[j0:j1, i0:i1], out=self.firm[j0:j1, i0:i1])
        self._unsettled = None

    @property
    def ground(self) -> np.ndarray:
        """The ground a wheel stands on: the heights, less (with soil) the loose material that
        slumped, which a loader drives over and through."""
        return self.z if self.firm is None else self.firm

    # -- motion ------------------------------------------------------------------------------
    def move(self, n: int, a: Move) -> dict[str, np.ndarray]:
        """Check one move against the rules every machine shares; returns its arcs."""
        spec = self.specs[a.machine]
        p = np.array(a.path, dtype=float)
        here = self.pose[a.machine]
        t, x, y, yaw = p[0]
        gap = math.hypot(x - here.x, y - here.y)
        turn = abs(wrap(yaw - here.yaw))
        if gap > ABS_TOL or turn > ABS_TOL:
            self.flag(
                n,
                "discontinuous",
                max(gap, turn),
                f"{a.machine} is at ({here.x:.3f}, {here.y:.3f}, yaw {here.yaw:.3f})"
                f" but the move starts at ({x:.3f}, {y:.3f}, yaw {yaw:.3f})",
            )
        arc = arcs(p)
        limits = (("speed", arc["length"] / arc["dt"], spec.travel_speed, "m/s", "at {:.4f} m/s along the arc"),
                  ("yaw_rate", np.abs(arc["dyaw"]) / arc["dt"], spec.yaw_rate, "rad/s", "turns at {:.4f} rad/s"))
        for rule, rates, limit, unit, doing in limits:
            k = int(np.argmax(rates))
            if rates[k] > limit * (1 + RATE_TOL):
                self.flag(n, rule, rates[k] - limit,
                          f"{a.machine} {doing.format(rates[k])} between samples {k} and {k + 1}; limit {limit} {unit}")
        slack = spec.chord_tolerance * np.minimum(1.0, arc["chord"] / SLIP_LENGTH)
        k = int(np.argmax(arc["lateral"] - slack))
        if arc["lateral"][k] > slack[k]:
            self.flag(
                n,
                "heading",
                arc["lateral"][k],
                f"no arc along the headings joins samples {k} and {k + 1}: {a.machine} slides {arc['lateral'][k]:.3f}"
                f" m sideways over a {arc['chord'][k]:.3f} m chord; tolerance {slack[k]:.4f} m",
            )
        self.swept(n, a.machine, p, arc)
        self.travel[a.machine] += float(arc["length"].sum())
        self.pose[a.machine] = Pose(float(p[-1, 1]), float(p[-1, 2]), float(p[-1, 3]))
        return arc

    def swept(self, n: int, machine: str, path: np.ndarray, arc: dict[str, np.ndarray] | None = None) -> None:
        """Keep-out zones and the map's edge for the machine's outline along ``path``."""
        if not self.keep_outs and self.sc.outside_open:
            return
        spec = self.specs[machine]
        reach = _reach_of(spec.outline(0.0, 0.0, 0.0))
        only = None
        if len(path) > 1:  # arcs whose outline stays clear of the map's edge and every zone
            a = arcs(path) if arc is None else arc
            travel = a["length"] + np.abs(a["dyaw"]) * reach
            room = np.full(len(path), np.inf)
            if not self.sc.outside_open:
                xmin, xmax, ymin, ymax = self.terrain.extent
                room = np.minimum.reduce([path[:, 1] - xmin, xmax - path[:, 1], path[:, 2] - ymin, ymax - path[:, 2]])
            for ko in self.keep_outs:
                room = np.minimum(room, shapely.distance(ko, shapely.points(path[:, 1:3])))
            only = (room[:-1] + room[1:] - travel) / 2 <= reach + ABS_TOL
        dense = dense_poses(path, self.spacing, reach, only=only, arc=None if len(path) < 2 else a)
        if not self.sc.outside_open:
            out = _off_map_excess(self.sc, spec, dense[:, 1:4])
            k = int(np.argmax(out))
            if out[k] > ABS_TOL:
                self.flag(
                    n,
                    "off_map",
                    out[k],
                    f"{machine}'s footprint leaves the map by {out[k]:.3f} m"
                    f" at ({dense[k, 1]:.2f}, {dense[k, 2]:.2f}), t={dense[k, 0]:.2f} s",
                )
        if self.keep_outs:
            polys = _polygons(spec.outline(dense[:, 1], dense[:, 2], dense[:, 3]))
            for ko in self.keep_outs:
                hit = shapely.intersects(polys, ko)
                if hit.any():
                    k = int(np.argmax(hit))
                    depth = float(shapely.area(shapely.intersection(polys[hit], ko)).max())
                    self.flag(
                        n,
                        "keep_out",
                        max(depth, ABS_TOL),
                        f"{machine}'s footprint enters a keep-out zone at ({dense[k, 1]:.2f}, {dense[k, 2]:.2f}), t={dense[k, 0]:.2f} s",
                    )

    # -- clearance ------------------------------------------------------------------------------
    def collisions(self) -> None:
        for machine in ("excavator", "loader"):
            if machine in self.timelines:
                self._collision(machine)

    def _collision(self, machine: str) -> None:
        """Centre distance and footprint contact along both swept paths at once.

        Between two consecutive sample times of either machine each one drives a piece of one
        arc at constant speed and yaw rate, so the distance between them cannot dip below
        ``(d0 + d1 − S) / 2`` for the distances ``d0, d1`` at the ends and ``S`` the sum of
        what both centres (and body corners, by the turn) travel. Intervals whose bound stays
        above the clearance and the bodies' reach are clear; the others are sampled so that
        neither machine moves more than half a cell (at least 2.5 cm) between two times.
        """
        me, truck = self.timelines[machine], self.timelines["truck"]
        spec, tspec = self.specs[machine], self.specs["truck"]
        assert not isinstance(spec, TruckSpec)  # the excavator or the loader, each with its clearance to the truck
        reach_a, reach_b = _reach_of(spec.body(0.0, 0.0, 0.0)), _reach_of(tspec.body(0.0, 0.0, 0.0))
        step = max(self.spacing, 0.025)
        times = np.unique(np.concatenate([me.path[:, 0], truck.path[:, 0]]))
        pa, pb = me.poses(times), truck.poses(times)
        d = np.hypot(pa[:, 0] - pb[:, 0], pa[:, 1] - pb[:, 1])
        if len(times) > 1:
            mid = (times[:-1] + times[1:]) / 2
            dt = np.diff(times)
            S = (me.rates(mid, reach_a) + truck.rates(mid, reach_b)) * dt
            near = (d[:-1] + d[1:] - S) / 2 <= max(spec.clearance, reach_a + reach_b) + ABS_TOL
            if near.any():
                n = np.maximum(np.ceil(S[near] / step).astype(int), 1)
                at = np.repeat(np.nonzero(near)[0], n)
                f = (np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n, n)
                extra = times[at] + f * dt[at]
                times = np.concatenate([times, extra])
                pa, pb = np.vstack([pa, me.poses(extra)]), np.vstack([pb, truck.poses(extra)])
                d = np.hypot(pa[:, 0] - pb[:, 0], pa[:, 1] - pb[:, 1])
        clearance = spec.clearance
        bad = d < clearance - ABS_TOL
        k = int(np.argmin(d))
        if bad.any():
            self.flag(
                self._active(times[k]),
                "collision",
                clearance - d[k],
                f"{machine} and truck {d[k]:.3f} m apart at t={times[k]:.3f} s; clearance {clearance} m",
            )
            return
        touch = _bodies_touch(spec, pa, tspec, pb)
        if touch.any():
            t = times[int(np.argmax(touch))]
            self.flag(self._active(t), "collision", 1.0, f"{machine}'s and the truck's footprints touch at t={t:.3f} s")

    def _active(self, t: float) -> int | None:
        who = [
            n for n, a in enumerate(self.plan.actions) if isinstance(a, (Move, Charge)) and a.t_start - ABS_TOL <= t <= a.t_end + ABS_TOL
        ]
        return who[0] if who else None

