"""The independent referee: replays a plan on a copy of the heightmap and judges it.

The referee, not the planner, decides what happened (DESIGN §3). It replays actions in time
order, applies every dig to the grid with the flat-cut model of :func:`apply_cut`, transfers
dumped material to the truck, and records every broken rule as a :class:`Violation` (action
index, rule, magnitude). A plan with any violation is invalid: reported, never ranked.

Wheel loader (track ``wheel_loader``, :class:`~earthbench.world.LoaderSpec`): its pose is the
centre of its front axle and its bucket's cutting edge lies ``bucket_offset`` ahead. A
``charge`` starts at the loader's pose, drives the penetration along its heading at ≤ the
penetration speed, and fills the bucket (:func:`charge_cut`) from the material above the floor
that the cutting edge's path (bucket width × penetration) covers, in order along the path, up
to the capacity; what the bucket cannot take stays in place. Loader moves keep the minimum
turning radius between every two samples (radius of the arc through both samples; a turn in
place has radius 0 and is flagged). The *traversable step* rule reads "higher" as **height
above the base level**: the floor (design grade), or without a floor the initial terrain height
under the loader's starting pose. Every point of the axle's path (moves, and a charge after
its cut) is densified to half a cell and the cell containing it must not stand more than
``max_step`` above the base level — so the loader drives on the floor and onto the pile only
where its bucket has cut it down; points off the map are taken as level ground. The raised
bucket ahead of the axle is not checked against the pile during moves (it is carried above
the material), only the axle's path.
A loader dump needs the truck still, the cutting edge within ``dump_reach`` of the truck's
loading circle, the truck's centre within 45° of the loader's heading, and ``min_dump_time``.
Loader–truck clearance is checked like the excavator's.

Tolerances: speeds and rates get ``RATE_TOL`` (1e-3, relative); durations, distances and
depths get ``ABS_TOL`` (1e-6 s or m) so that exact arithmetic by a planner is never punished
while nothing material is rounded in its favour.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely
from shapely.geometry import LineString, Point, Polygon

from .errors import PlanFormatError
from .motion import swing_time, wrap
from .plan import Charge, Dig, Dump, Move, Plan
from .world import ExcavatorSpec, Heightmap, LoaderSpec, Pose, Scenario

RATE_TOL = 1e-3
ABS_TOL = 1e-6

#: Every rule the referee checks, with the sentence a report shows for it.
RULES: dict[str, str] = {
    "malformed": "the plan document could not be read",
    "unknown_machine": "the action names a machine that is not on site",
    "wrong_machine": "the machine cannot perform this action",
    "overlap": "the action starts before the same machine's previous action ended",
    "discontinuous": "a move does not start where the machine is",
    "speed": "travel speed above the machine's limit",
    "yaw_rate": "yaw rate above the machine's limit",
    "heading": "motion not along the machine's heading (forward or reverse)",
    "keep_out": "a machine or bucket enters a keep-out zone",
    "bucket_not_empty": "a dig starts with material still in the bucket",
    "cut_depth": "cut depth above the machine's limit",
    "drag_length": "drag length above the machine's limit",
    "reach": "the stroke leaves the reach annulus around the base",
    "outside_dig_area": "the bucket footprint leaves the dig area",
    "below_floor": "the cut level lies below the floor (design grade)",
    "duration": "the action is shorter than the swing plus its minimum time",
    "truck_moving": "the truck moves during a dump",
    "dump_reach": "the truck is out of the bucket's reach",
    "collision": "machine centres closer than the clearance",
    "entry_pose": "a charge does not start at the loader's pose",
    "penetration_speed": "a charge drives faster than the loader's penetration speed",
    "turning_radius": "a loader move turns tighter than its minimum turning radius",
    "step": "the loader crosses a cell higher than its traversable step above the floor",
}

#: A loader dumps only into a truck whose centre lies within this angle of its heading.
LOADER_DUMP_HALF_ANGLE = math.pi / 4


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
    action: int
    volume: float
    fill: float


@dataclass(frozen=True)
class Verdict:
    """What the referee measured. ``valid`` is True only when ``violations`` is empty."""

    violations: tuple[Violation, ...]
    final_terrain: Heightmap
    loaded_volume: float
    removed_volume: float
    makespan: float
    digs: tuple[DigRecord, ...] = ()
    dumps: int = 0
    travel: dict[str, float] = field(default_factory=dict)
    #: (end time, cumulative loaded volume) after each dump, in replay order: when the truck got what.
    load_curve: tuple[tuple[float, float], ...] = ()

    @property
    def valid(self) -> bool:
        return not self.violations

    def summary(self) -> str:
        if self.valid:
            return "valid"
        rules = sorted({v.rule for v in self.violations})
        return f"invalid ({len(self.violations)} violations: {', '.join(rules)})"


# -- the cut model, shared with planners that want an exact forward model -----------------------

def footprint(contact: tuple[float, float], heading: float, width: float, length: float) -> Polygon:
    """The bucket's rectangle: ``length`` from the contact along ``heading``, ``width`` across."""
    cx, cy = contact
    ux, uy = math.cos(heading), math.sin(heading)
    vx, vy = -uy * width / 2, ux * width / 2
    ex, ey = cx + ux * length, cy + uy * length
    return Polygon([(cx + vx, cy + vy), (ex + vx, ey + vy), (ex - vx, ey - vy), (cx - vx, cy - vy)])


def apply_cut(
    terrain: Heightmap,
    z: np.ndarray,
    contact: tuple[float, float],
    heading: float,
    width: float,
    length: float,
    level: float,
    capacity: float,
) -> float:
    """Cut ``z`` in place down to ``level`` inside the footprint, in drag order, up to capacity.

    Cells whose centre lies in the footprint are lowered to ``level`` one after another along
    the drag; the cell that reaches ``capacity`` is lowered only partly, and the rest stays in
    place. Returns the removed bank volume (m³).
    """
    if capacity <= 0:
        return 0.0
    r = terrain.resolution
    x0, y0 = terrain.origin
    ny, nx = z.shape
    cx, cy = contact
    ux, uy = math.cos(heading), math.sin(heading)
    half = width / 2
    xs = (cx, cx + ux * length)
    ys = (cy, cy + uy * length)
    pad = half + r
    i0 = max(int(math.floor((min(xs) - pad - x0) / r)), 0)
    i1 = min(int(math.ceil((max(xs) + pad - x0) / r)), nx)
    j0 = max(int(math.floor((min(ys) - pad - y0) / r)), 0)
    j1 = min(int(math.ceil((max(ys) + pad - y0) / r)), ny)
    if i0 >= i1 or j0 >= j1:
        return 0.0
    px = x0 + (np.arange(i0, i1) + 0.5) * r - cx
    py = y0 + (np.arange(j0, j1) + 0.5) * r - cy
    along = py[:, None] * uy + px[None, :] * ux
    across = py[:, None] * ux - px[None, :] * uy
    inside = (along >= 0) & (along <= length) & (np.abs(across) <= half)
    jj, ii = np.nonzero(inside)
    if jj.size == 0:
        return 0.0
    order = np.argsort(along[jj, ii], kind="stable")
    jj, ii = jj[order] + j0, ii[order] + i0
    excess = np.maximum(z[jj, ii] - level, 0.0) * (r * r)
    total = np.cumsum(excess)
    full = int(np.searchsorted(total, capacity, side="right"))
    z[jj[:full], ii[:full]] = np.minimum(z[jj[:full], ii[:full]], level)
    removed = float(total[full - 1]) if full else 0.0
    if full < jj.size and removed < capacity:
        part = capacity - removed
        z[jj[full], ii[full]] -= part / (r * r)
        removed = capacity
    return removed


def charge_cut(
    terrain: Heightmap,
    z: np.ndarray,
    spec: LoaderSpec,
    entry: tuple[float, float, float],
    penetration: float,
    level: float,
    capacity: float,
) -> float:
    """Cut ``z`` in place along a charge from ``entry`` (the loader's pose) and return the volume.

    The cutting edge starts ``spec.bucket_offset`` ahead of the pose and sweeps ``penetration``
    metres along the heading; the cells whose centre lies in that ``bucket_width`` wide path are
    lowered to ``level`` in path order until ``capacity`` is reached (the last cell partly),
    exactly as :func:`apply_cut` does for a backhoe drag.
    """
    x, y, yaw = entry
    edge = (x + spec.bucket_offset * math.cos(yaw), y + spec.bucket_offset * math.sin(yaw))
    return apply_cut(terrain, z, edge, yaw, spec.bucket_width, penetration, level, capacity)


def loader_base_level(scenario: Scenario) -> float:
    """The level the traversable-step rule measures from: the floor, or without one the initial
    terrain height under the loader's starting pose."""
    if scenario.site.floor is not None:
        return scenario.site.floor
    p = scenario.machines.loader_pose
    return scenario.terrain.height_at(p.x, p.y) if p is not None else 0.0


def densify(xy: np.ndarray, spacing: float) -> np.ndarray:
    """Points along the polyline ``xy[k, 2]`` no farther apart than ``spacing`` (ends included)."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    if len(xy) < 2:
        return xy
    seg = np.hypot(*np.diff(xy, axis=0).T)
    n = np.maximum(np.ceil(seg / spacing).astype(int), 1)
    i = np.repeat(np.arange(len(seg)), n)
    f = (np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)) / n[i]
    pts = xy[i] + f[:, None] * (xy[i + 1] - xy[i])
    return np.vstack([pts, xy[-1:]])


def cell_heights(terrain: Heightmap, z: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Height of the cell containing each point of ``pts[k, 2]``; NaN for points off the map."""
    pts = np.asarray(pts, dtype=float).reshape(-1, 2)
    ny, nx = z.shape
    i = np.floor((pts[:, 0] - terrain.origin[0]) / terrain.resolution).astype(int)
    j = np.floor((pts[:, 1] - terrain.origin[1]) / terrain.resolution).astype(int)
    ok = (i >= 0) & (i < nx) & (j >= 0) & (j < ny)
    out = np.full(len(pts), np.nan)
    out[ok] = z[j[ok], i[ok]]
    return out


def step_excess(terrain: Heightmap, z: np.ndarray, xy: np.ndarray, base: float, max_step: float) -> tuple[float, int]:
    """Largest height above ``base + max_step`` of the cells the polyline ``xy`` crosses, and the
    index of its densified point (≤ 0 means traversable); the loader's step rule."""
    pts = densify(xy, terrain.resolution / 2)
    h = cell_heights(terrain, z, pts) - base - max_step
    h = np.where(np.isnan(h), -np.inf, h)
    k = int(np.argmax(h))
    return float(h[k]), k


def cut_level(terrain: Heightmap, z: np.ndarray, contact: tuple[float, float], depth: float) -> float:
    """The flat cut level of a dig: the current height at the contact minus the depth."""
    return terrain.height_at(contact[0], contact[1], z) - depth


# -- the referee --------------------------------------------------------------------------------

class _Timeline:
    """A machine's poses over time, piecewise linear through its move samples."""

    def __init__(self, start: Pose, moves: list[Move]):
        samples = [(0.0, start.x, start.y, start.yaw)]
        for m in sorted(moves, key=lambda m: m.t_start):
            samples.extend(m.path)
        a = np.array(samples, dtype=float)
        self.t, self.x, self.y = a[:, 0], a[:, 1], a[:, 2]
        self.yaw = np.unwrap(a[:, 3])
        self.moves = [(m.t_start, m.t_end) for m in moves]

    def pose(self, t: float) -> Pose:
        k = int(np.searchsorted(self.t, t, side="right")) - 1
        if k < 0:
            return Pose(self.x[0], self.y[0], self.yaw[0])
        if k >= len(self.t) - 1:
            return Pose(self.x[-1], self.y[-1], self.yaw[-1])
        t0, t1 = self.t[k], self.t[k + 1]
        f = 0.0 if t1 <= t0 else (t - t0) / (t1 - t0)
        return Pose(
            self.x[k] + f * (self.x[k + 1] - self.x[k]),
            self.y[k] + f * (self.y[k + 1] - self.y[k]),
            self.yaw[k] + f * (self.yaw[k + 1] - self.yaw[k]),
        )

    def positions(self, times: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(times, self.t, self.x), np.interp(times, self.t, self.y)], axis=1)

    def moving_during(self, t0: float, t1: float) -> bool:
        return any(a < t1 - ABS_TOL and b > t0 + ABS_TOL for a, b in self.moves)


class _Replay:
    """State of one judgement; one instance per call of :func:`judge`."""

    def __init__(self, scenario: Scenario, plan: Plan):
        self.sc, self.plan = scenario, plan
        self.terrain = scenario.terrain
        self.z = np.array(scenario.terrain.z, dtype=np.float64)
        self.violations: list[Violation] = []
        self.dig_area = Polygon(scenario.site.dig_area)
        shapely.prepare(self.dig_area)
        self.dig_area_tol = self.dig_area.buffer(ABS_TOL)
        shapely.prepare(self.dig_area_tol)
        self.keep_outs = [Polygon(k) for k in scenario.site.keep_outs]
        for k in self.keep_outs:
            shapely.prepare(k)
        m = scenario.machines
        self.specs = {"excavator": m.excavator, "truck": m.truck}
        if m.loader is not None:
            self.specs["loader"] = m.loader
            self.base = loader_base_level(scenario)
        moves: dict[str, list[Move]] = {mid: [] for mid in m.ids}
        for a in plan.actions:
            if isinstance(a, Move) and a.machine in moves:
                moves[a.machine].append(a)
            elif isinstance(a, Charge) and a.machine in moves:  # a charge moves the loader too
                (x, y, yaw), (ex, ey, _) = a.entry, a.end
                if a.t_end > a.t_start:
                    moves[a.machine].append(Move(a.machine, ((a.t_start, x, y, yaw), (a.t_end, ex, ey, yaw))))
        self.timelines = {mid: _Timeline(m.pose(mid), moves[mid]) for mid in m.ids}
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

    def flag(self, n: int | None, rule: str, magnitude: float, message: str) -> None:
        self.violations.append(Violation(n, rule, float(magnitude), message))

    def run(self) -> Verdict:
        order = sorted(range(len(self.plan.actions)), key=lambda n: (self.plan.actions[n].t_start, n))
        for n in order:
            a = self.plan.actions[n]
            if a.machine not in self.pose:
                self.flag(n, "unknown_machine", 1.0, f"no machine {a.machine!r}; on site: {', '.join(self.pose)}")
                continue
            if a.t_start < self.busy_until[a.machine] - ABS_TOL:
                gap = self.busy_until[a.machine] - a.t_start
                self.flag(n, "overlap", gap, f"{a.machine} is busy until t={self.busy_until[a.machine]:.3f} s")
            if isinstance(a, Move):
                self.move(n, a)
            elif isinstance(a, Dig):
                self.dig(n, a)
            elif isinstance(a, Dump):
                self.dump(n, a)
            elif isinstance(a, Charge):
                self.charge(n, a)
            self.busy_until[a.machine] = max(self.busy_until[a.machine], a.t_end)
        self.collisions()
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
        )

    # -- motion ------------------------------------------------------------------------------
    def move(self, n: int, a: Move) -> None:
        spec = self.specs[a.machine]
        p = np.array(a.path, dtype=float)
        here = self.pose[a.machine]
        t, x, y, yaw = p[0]
        gap = math.hypot(x - here.x, y - here.y)
        turn = abs(wrap(yaw - here.yaw))
        if gap > ABS_TOL or turn > ABS_TOL:
            self.flag(n, "discontinuous", max(gap, turn), f"{a.machine} is at ({here.x:.3f}, {here.y:.3f}, yaw {here.yaw:.3f}) but the move starts at ({x:.3f}, {y:.3f}, yaw {yaw:.3f})")
        dt = np.diff(p[:, 0])
        dx, dy = np.diff(p[:, 1]), np.diff(p[:, 2])
        dist = np.hypot(dx, dy)
        dyaw = (np.diff(p[:, 3]) + math.pi) % (2 * math.pi) - math.pi
        speed = dist / dt
        rate = np.abs(dyaw) / dt
        k = int(np.argmax(speed))
        if speed[k] > spec.travel_speed * (1 + RATE_TOL):
            self.flag(n, "speed", speed[k] - spec.travel_speed, f"{a.machine} at {speed[k]:.4f} m/s between samples {k} and {k + 1}; limit {spec.travel_speed} m/s")
        k = int(np.argmax(rate))
        if rate[k] > spec.yaw_rate * (1 + RATE_TOL):
            self.flag(n, "yaw_rate", rate[k] - spec.yaw_rate, f"{a.machine} turns at {rate[k]:.4f} rad/s between samples {k} and {k + 1}; limit {spec.yaw_rate} rad/s")
        mid = p[:-1, 3] + dyaw / 2
        lateral = np.abs(dx * np.sin(mid) - dy * np.cos(mid))
        k = int(np.argmax(lateral))
        if lateral[k] > spec.chord_tolerance:
            self.flag(n, "heading", lateral[k], f"{a.machine} slides {lateral[k]:.3f} m sideways between samples {k} and {k + 1}; tolerance {spec.chord_tolerance} m")
        if self.keep_outs:
            line = LineString(p[:, 1:3]) if dist.sum() > 0 else Point(p[0, 1:3])
            for ko in self.keep_outs:
                if line.intersects(ko):
                    depth = ko.boundary.distance(line) if not ko.contains(line) else 1.0
                    self.flag(n, "keep_out", max(depth, ABS_TOL), f"{a.machine}'s path enters a keep-out zone")
        if isinstance(spec, LoaderSpec):
            self._loader_move(n, a, spec, p, dist, dyaw)
        self.travel[a.machine] += float(dist.sum())
        self.pose[a.machine] = Pose(float(p[-1, 1]), float(p[-1, 2]), float(p[-1, 3]))

    # -- wheel loader ------------------------------------------------------------------------------
    def _loader_move(self, n: int, a: Move, spec: LoaderSpec, p: np.ndarray, dist: np.ndarray, dyaw: np.ndarray) -> None:
        ang = np.abs(dyaw)
        with np.errstate(divide="ignore", invalid="ignore"):
            radius = np.where(ang > 1e-12, dist / (2.0 * np.sin(ang / 2.0)), np.inf)
        k = int(np.argmin(radius))
        if radius[k] < spec.min_turning_radius * (1 - RATE_TOL) - ABS_TOL:
            what = "turns in place" if dist[k] <= ABS_TOL else f"turns on a {radius[k]:.3f} m radius"
            self.flag(n, "turning_radius", spec.min_turning_radius - radius[k], f"{a.machine} {what} between samples {k} and {k + 1}; minimum {spec.min_turning_radius} m")
        self._step(n, a.machine, p[:, 1:3], spec)

    def _step(self, n: int, machine: str, xy: np.ndarray, spec: LoaderSpec) -> None:
        excess, _ = step_excess(self.terrain, self.z, xy, self.base, spec.max_step)
        if excess > ABS_TOL:
            self.flag(n, "step", excess, f"{machine} crosses a cell {spec.max_step + excess:.3f} m above the base level {self.base:g} m; traversable step {spec.max_step} m")

    def charge(self, n: int, a: Charge) -> None:
        spec = self.specs.get(a.machine)
        if not isinstance(spec, LoaderSpec):
            self.flag(n, "wrong_machine", 1.0, f"{a.machine} cannot charge; only a wheel loader charges")
            return
        here = self.pose[a.machine]
        x, y, yaw = a.entry
        gap, turn = math.hypot(x - here.x, y - here.y), abs(wrap(yaw - here.yaw))
        if gap > ABS_TOL or turn > ABS_TOL:
            self.flag(n, "entry_pose", max(gap, turn), f"{a.machine} is at ({here.x:.3f}, {here.y:.3f}, yaw {here.yaw:.3f}) but the charge enters at ({x:.3f}, {y:.3f}, yaw {yaw:.3f})")
        if self.bucket > ABS_TOL:
            self.flag(n, "bucket_not_empty", self.bucket, f"the bucket still holds {self.bucket:.4f} m³")
        dur = a.t_end - a.t_start
        speed = a.penetration / dur if dur > 0 else math.inf
        if speed > spec.penetration_speed * (1 + RATE_TOL):
            self.flag(n, "penetration_speed", speed - spec.penetration_speed, f"the charge drives {a.penetration:.3f} m in {dur:.3f} s ({speed:.4f} m/s); limit {spec.penetration_speed} m/s")
        if dur < spec.min_charge_time - ABS_TOL:
            self.flag(n, "duration", spec.min_charge_time - dur, f"charge lasts {dur:.3f} s; the loader needs at least {spec.min_charge_time} s")
        edge = (x + spec.bucket_offset * math.cos(yaw), y + spec.bucket_offset * math.sin(yaw))
        fp = footprint(edge, yaw, spec.bucket_width, a.penetration)
        if not self.dig_area_tol.contains(fp):
            out = fp.difference(self.dig_area).area
            self.flag(n, "outside_dig_area", max(out, ABS_TOL), f"{out:.4f} m² of the bucket's path lies outside the dig area")
        ex, ey, _ = a.end
        axle = LineString([(x, y), (ex, ey)])
        for ko in self.keep_outs:
            if fp.intersects(ko) or axle.intersects(ko):
                self.flag(n, "keep_out", max(fp.intersection(ko).area, ABS_TOL), "the loader or its bucket enters a keep-out zone")
        level = self.sc.site.floor if self.sc.site.floor is not None else self.base
        vol = charge_cut(self.terrain, self.z, spec, a.entry, a.penetration, level, spec.bucket_capacity - self.bucket)
        self.bucket += vol
        self.removed += vol
        self.digs.append(DigRecord(n, vol, vol / spec.bucket_capacity))
        self._step(n, a.machine, np.array([[x, y], [ex, ey]]), spec)
        self.travel[a.machine] += a.penetration
        self.pose[a.machine] = Pose(ex, ey, yaw)

    def _loader_dump(self, n: int, a: Dump, spec: LoaderSpec) -> None:
        truck_spec = self.specs["truck"]
        truck = self.timelines["truck"]
        if truck.moving_during(a.t_start, a.t_end):
            self.flag(n, "truck_moving", 1.0, "the truck moves while the bucket is emptied")
        pose = self.timelines[a.machine].pose(a.t_start)
        tpos = truck.pose(a.t_start)
        edge = (pose.x + spec.bucket_offset * math.cos(pose.yaw), pose.y + spec.bucket_offset * math.sin(pose.yaw))
        gap = math.hypot(tpos.x - edge[0], tpos.y - edge[1]) - truck_spec.loading_radius
        if gap > spec.dump_reach + ABS_TOL:
            self.flag(n, "dump_reach", gap - spec.dump_reach, f"the bucket edge is {gap:.3f} m from the truck's loading circle; dump reach {spec.dump_reach} m")
        off = abs(wrap(math.atan2(tpos.y - pose.y, tpos.x - pose.x) - pose.yaw))
        if off > LOADER_DUMP_HALF_ANGLE + ABS_TOL:
            self.flag(n, "dump_reach", off - LOADER_DUMP_HALF_ANGLE, f"the truck lies {math.degrees(off):.1f}° off the loader's heading; at most {math.degrees(LOADER_DUMP_HALF_ANGLE):.0f}°")
        if a.t_end - a.t_start < spec.min_dump_time - ABS_TOL:
            self.flag(n, "duration", spec.min_dump_time - (a.t_end - a.t_start), f"dump lasts {a.t_end - a.t_start:.3f} s; the loader needs {spec.min_dump_time} s")
        take = min(self.bucket, max(truck_spec.capacity - self.loaded, 0.0))
        self.loaded += take
        self.bucket -= take
        self.dumps += 1
        self.load_curve.append((a.t_end, self.loaded))

    # -- excavator actions ---------------------------------------------------------------------
    def _swing_time(self, base: Pose, target: tuple[float, float], spec: ExcavatorSpec) -> tuple[float, float]:
        """The swing time (the planners' definition, :func:`earthbench.motion.swing_time`) and the bearing."""
        bearing = math.atan2(target[1] - base.y, target[0] - base.x)
        return swing_time(base, self.turn, target, spec), bearing

    def dig(self, n: int, a: Dig) -> None:
        spec = self.specs.get(a.machine)
        if a.machine != "excavator" or not isinstance(spec, ExcavatorSpec):
            self.flag(n, "wrong_machine", 1.0, f"{a.machine} cannot dig; only the excavator digs")
            return
        base = self.timelines[a.machine].pose(a.t_start)
        if self.bucket > ABS_TOL:
            self.flag(n, "bucket_not_empty", self.bucket, f"the bucket still holds {self.bucket:.4f} m³")
        if a.depth > spec.max_cut_depth + ABS_TOL:
            self.flag(n, "cut_depth", a.depth - spec.max_cut_depth, f"depth {a.depth:.4f} m; limit {spec.max_cut_depth} m")
        if a.drag_length > spec.max_drag_length + ABS_TOL:
            self.flag(n, "drag_length", a.drag_length - spec.max_drag_length, f"drag {a.drag_length:.4f} m; limit {spec.max_drag_length} m")
        end = (a.contact[0] + math.cos(a.heading) * a.drag_length, a.contact[1] + math.sin(a.heading) * a.drag_length)
        for label, pt in (("contact", a.contact), ("drag end", end)):
            r = math.hypot(pt[0] - base.x, pt[1] - base.y)
            if r > spec.reach_max + ABS_TOL or r < spec.reach_min - ABS_TOL:
                off = max(r - spec.reach_max, spec.reach_min - r)
                self.flag(n, "reach", off, f"{label} is {r:.3f} m from the base; reach {spec.reach_min}–{spec.reach_max} m")
        fp = footprint(a.contact, a.heading, spec.bucket_width, a.drag_length)
        if not self.dig_area_tol.contains(fp):
            out = fp.difference(self.dig_area).area
            self.flag(n, "outside_dig_area", max(out, ABS_TOL), f"{out:.4f} m² of the bucket footprint lies outside the dig area")
        for ko in self.keep_outs:
            if fp.intersects(ko):
                self.flag(n, "keep_out", max(fp.intersection(ko).area, ABS_TOL), "the bucket footprint enters a keep-out zone")
        swing_t, bearing = self._swing_time(base, a.contact, spec)
        need = swing_t + spec.min_stroke_time
        if a.t_end - a.t_start < need - ABS_TOL:
            self.flag(n, "duration", need - (a.t_end - a.t_start), f"dig lasts {a.t_end - a.t_start:.3f} s; the swing and stroke need {need:.3f} s")
        level = cut_level(self.terrain, self.z, a.contact, a.depth)
        floor = self.sc.site.floor
        if floor is not None and level < floor - ABS_TOL:
            self.flag(n, "below_floor", floor - level, f"cut level {level:.4f} m is below the floor {floor} m")
            level = floor
        vol = apply_cut(self.terrain, self.z, a.contact, a.heading, spec.bucket_width, a.drag_length, level, spec.bucket_capacity - self.bucket)
        self.bucket += vol
        self.removed += vol
        self.digs.append(DigRecord(n, vol, vol / spec.bucket_capacity))
        self.turn = bearing - base.yaw

    def dump(self, n: int, a: Dump) -> None:
        spec = self.specs.get(a.machine)
        if isinstance(spec, LoaderSpec):
            self._loader_dump(n, a, spec)
            return
        if a.machine != "excavator" or not isinstance(spec, ExcavatorSpec):
            self.flag(n, "wrong_machine", 1.0, f"{a.machine} cannot dump into the truck")
            return
        truck_spec = self.specs["truck"]
        truck = self.timelines["truck"]
        if truck.moving_during(a.t_start, a.t_end):
            self.flag(n, "truck_moving", 1.0, "the truck moves while the bucket is emptied")
        base = self.timelines[a.machine].pose(a.t_start)
        tpos = truck.pose(a.t_start)
        dist = math.hypot(tpos.x - base.x, tpos.y - base.y)
        r = truck_spec.loading_radius
        if dist - r > spec.reach_max + ABS_TOL or dist + r < spec.reach_min - ABS_TOL:
            off = max(dist - r - spec.reach_max, spec.reach_min - dist - r)
            self.flag(n, "dump_reach", off, f"the truck is {dist:.3f} m from the base; its loading area is out of reach")
        swing_t, bearing = self._swing_time(base, (tpos.x, tpos.y), spec)
        need = swing_t + spec.min_dump_time
        if a.t_end - a.t_start < need - ABS_TOL:
            self.flag(n, "duration", need - (a.t_end - a.t_start), f"dump lasts {a.t_end - a.t_start:.3f} s; the swing and dump need {need:.3f} s")
        take = min(self.bucket, max(truck_spec.capacity - self.loaded, 0.0))
        self.loaded += take
        self.bucket -= take
        self.dumps += 1
        self.load_curve.append((a.t_end, self.loaded))
        self.turn = bearing - base.yaw

    # -- collisions ------------------------------------------------------------------------------
    def collisions(self) -> None:
        for machine in ("excavator", "loader"):
            if machine in self.timelines:
                self._collision(machine)

    def _collision(self, machine: str) -> None:
        exc, truck = self.timelines[machine], self.timelines["truck"]
        times = np.unique(np.concatenate([exc.t, truck.t]))
        d = np.linalg.norm(exc.positions(times) - truck.positions(times), axis=1)
        clearance = self.specs[machine].clearance
        bad = d < clearance - ABS_TOL
        if not bad.any():
            return
        k = int(np.argmin(d))
        who = [n for n, a in enumerate(self.plan.actions) if isinstance(a, (Move, Charge)) and a.t_start - ABS_TOL <= times[k] <= a.t_end + ABS_TOL]
        self.flag(who[0] if who else None, "collision", clearance - d[k], f"{machine} and truck {d[k]:.3f} m apart at t={times[k]:.3f} s ({int(bad.sum())} samples); clearance {clearance} m")


def judge(scenario: Scenario, plan: Plan | dict | str) -> Verdict:
    """Replay ``plan`` on ``scenario`` and return the verdict.

    ``plan`` may be a :class:`Plan`, a plan document (dict) or JSON text; a document that
    cannot be read gives an invalid verdict with a ``malformed`` violation, never an exception.
    """
    try:
        if isinstance(plan, Plan):  # built in code: check its form the same way as a document's
            plan = Plan.from_dict(plan.to_dict())
        else:
            plan = Plan.from_dict(plan) if isinstance(plan, dict) else Plan.from_json(plan)
    except (PlanFormatError, TypeError, ValueError, AttributeError) as exc:
        v = Violation(None, "malformed", 1.0, str(exc))
        return Verdict((v,), scenario.terrain, 0.0, 0.0, 0.0)
    return _Replay(scenario, plan).run()
