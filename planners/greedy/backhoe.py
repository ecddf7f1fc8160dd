"""``greedy``: the floor every other backhoe planner must beat.

From where it stands, the excavator digs the reachable stroke that loads the truck fastest
(its volume over the time until its dump ends, among strokes filling at least ``min_fill`` of a
bucket), swings to the truck and dumps, and repeats. During each dig the truck slides along its
heading to the stand nearest the dig's bearing that keeps its body out of the arm's shadow, off
the dig area and on ground within its limits (``planners/truck_stands.py``, rules version 2), so
a dump swings little. When nothing in reach is worth a dig, it drives to the station with the
most material in reach (less a travel penalty) and the truck is parked toward that material,
broadside to it (the cheapest stand in travel and swing). The two drive at once when they keep
the clearance at every instant, the truck on an arc when that beats turning in place
(``truck_stands.drive``), and the excavator digs while the truck drives to it. For a target of
8 buckets or more it may first drive to the station where the target swings least
(``opening.py``, issue 49). Dig volumes are screened with a vectorised estimate and the best few
confirmed with the referee's own cut model (and, on the realistic track, the soil's slump), so
the planner's predicted volume equals the referee's.

Closed loop (``closed_loop = true``, docs/DESIGN.md §6): each step plans from the observation
(the terrain as it now is, the machines where they stand, the load the truck reports) up to
and including the next dump, so the planner digs on until the truck really holds the target.
The stations it has visited, and (1.5.1) the contacts whose dig the truck's load showed came back
empty, are remembered from step to step (``closed_loop.Carried``).

Cost is linear in the work: a dig scores the ~1,000 strokes around the base with array operations (heights looked
up for all contacts at once; only the strokes whose cut level or points a dig has changed estimated again; a
stroke's path cells found once, its trial cut measured without applying it and the undermining check applying it
and putting the path's cells back, never a copy of the map), and a relocation scores the stations, in blocks of
128, from row-wise prefix sums of the material, one interval sum per grid row a station reaches, again only the
stations within reach of what was dug since the last relocation; the truck's way to a station is tested before
the tilt, as most rejected stations fail the truck.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry import Point, Polygon

from earthbench.cut import apply_cut, cut_along, path_cells, path_window
from earthbench.motion import ABS_TOL, min_dig_time, min_dump_time, turn_drive_turn, wrap
from earthbench.plan import Dig, Dump, Move, Plan, Prediction
from earthbench.planner import closed_loop_setting
from earthbench.rules import track_level_and_tilt
from earthbench.soil import slump
from earthbench.world import ExcavatorSpec, Heightmap, Pose, Scenario, TruckSpec

from ..backhoe_loop import BackhoeLoopPlanner
from ..stability import Stroke, margins, path_undermines
from ..truck_stands import TruckStands
from .closed_loop import Carried, away_from
from .moves import Moves
from .opening import Opening

_EPS_T = 1e-6  # seconds added to minimum durations so rounding never makes them short
_DRIVE_PAD = 0.5  # metres a dig's arm shadow keeps from where the truck still drives (see still_driving)
_BASE_BLOCK = 128  # stations scored together by reachable_volume (see there)
_ENOUGH = 4.0  # a relocation counts a station's material up to this many times what is still needed
PathCells = tuple[np.ndarray, np.ndarray, np.ndarray]  # earthbench.cut.path_cells: rows, columns, distance along


@dataclass(frozen=True)
class GreedyConfig:
    min_fill: float = 0.6
    """A dig must fill at least this fraction of the bucket, else the excavator relocates."""
    full_share: float = 0.9
    """A stroke must load at least this share of what the fullest one would (up to what is
    still needed); among those the one that loads fastest is dug."""
    radial_step: float = 0.25
    """Spacing (m) of candidate contacts along the radius."""
    arc_step: float = 0.35
    """Spacing (m) of candidate contacts along each arc."""
    station_step: float = 1.0
    """Spacing (m) of the grid of candidate stations."""
    truck_distance: float = 4.6
    """Preferred centre distance (m) from the excavator to the truck at a station."""
    travel_penalty: float = 0.05
    """m³ of reachable material worth one metre of travel when choosing a station (the metres the
    excavator would drive in the time its way there takes, turning included)."""
    max_actions: int = 2000
    closed_loop: bool = closed_loop_setting()
    """Replan after every dump from the observed terrain and truck load."""
    scan_margin: float | None = None
    """Metres kept above the undermining line for the scan's error; None: derived from the
    observation (``planners/stability.py``: 0 on the exact track)."""


def _referee_order(a: Dig | Dump | Move) -> tuple[float, int]:
    """The order the referee replays a plan in (by start time), the excavator's action first
    where a truck move starts at the same time: a replay's terrain then changes as time goes."""
    return (a.path[0][0], 1) if isinstance(a, Move) else (a.t_start, 0)


@dataclass(frozen=True)
class _Dig:
    """A chosen stroke and the stand the truck takes for its dump."""

    score: float
    volume: float
    contact: tuple[float, float]
    heading: float
    depth: float
    stand: Pose
    arrive: float


class GreedyPlanner(BackhoeLoopPlanner["GreedySession", Carried]):
    """Fullest reachable bucket first; relocate when nothing in reach is worth a dig."""

    name = "greedy"
    version = "1.5.1"
    Config = GreedyConfig

    def plan(self, scenario: Scenario) -> Plan:
        return GreedySession(scenario, self.config).run()

    def session(self, scenario: Scenario) -> GreedySession:
        return GreedySession(scenario, self.config)

    def _carry(self, session: GreedySession) -> Carried:
        return Carried()

    def _one_dump(self, session: GreedySession, carried: Carried) -> Plan:
        carried.judge_last(session.loaded)
        session.barren, before = carried.barren, session.loaded
        plan = session.run(carried.visited, max_dumps=1)
        carried.remember(plan, session.bucket, before)
        return plan


class GreedySession(Moves, Opening):
    """One greedy plan in the making: the site as dug so far, the machines, the clock and the load."""

    def __init__(self, sc: Scenario, cfg: GreedyConfig):
        self.sc, self.cfg = sc, cfg
        self.exc: ExcavatorSpec = sc.machines.excavator  # type: ignore[assignment]
        self.truck_spec: TruckSpec = sc.machines.truck
        self.terrain: Heightmap = sc.terrain
        self.z = np.array(sc.terrain.z)
        self.floor = sc.site.floor if sc.site.floor is not None else -math.inf
        self.dig_area = Polygon(sc.site.dig_area)
        shapely.prepare(self.dig_area)
        self.keep_outs = [Polygon(k) for k in sc.site.keep_outs]
        self.margins = margins(sc, cfg.scan_margin)
        self.base: Pose = sc.machines.excavator_pose  # type: ignore[assignment]
        self.truck: Pose = sc.machines.truck_pose
        self.turn = 0.0
        self.t = 0.0
        self.truck_ready = 0.0  # when the truck stands still where it is going
        self.truck_path: list[tuple[float, float, float, float]] = []  # its last move (samples)
        self.loaded, self.bucket = 0.0, 0.0  # the truck's load; the last dig's volume
        self.barren: list[tuple[float, float]] = []  # contacts not to dig again (closed loop: Carried)
        self.actions: list = []
        self.stands = TruckStands(sc, self.exc, self.z)
        self._line: tuple[tuple[Pose, Pose], tuple[np.ndarray, np.ndarray]] | None = None
        xs, ys = self.terrain.cell_centres()
        self.cx, self.cy = np.meshgrid(xs, ys)
        self.in_area = shapely.contains_xy(self.dig_area, self.cx, self.cy)
        self._strokes: tuple[tuple[float, float], tuple[np.ndarray, ...]] | None = None
        self._estimates: tuple[tuple[float, float], np.ndarray, np.ndarray] | None = None  # station, levels, volumes
        self._cut_since: list[tuple[slice, slice]] = []  # grid windows dug since the estimates were made
        self._stations: tuple[np.ndarray, np.ndarray] | None = None  # station grid, its volumes
        self._dug_since: list[tuple[slice, slice]] = []  # grid windows dug since the stations were scored

    # -- the loop ----------------------------------------------------------------------------
    def run(self, visited: set[tuple[float, float]] | None = None, max_dumps: int | None = None) -> Plan:
        """Plan until the goal is loaded (or ``max_dumps`` dumps: one closed-loop step)."""
        target = self.sc.task.target_volume
        goal = min(target, self.truck_spec.capacity)
        visited = set() if visited is None else visited
        start, dumps, parked = self.loaded, 0, False
        if not self.actions and self.loaded <= 1e-9:
            self.opening(visited)  # stay, or first drive where the target's buckets swing least
        while self.loaded < goal - 1e-9 and len(self.actions) < self.cfg.max_actions:
            need = goal - self.loaded
            threshold = min(self.cfg.min_fill * self.exc.bucket_capacity, need)
            best, fullest = self.best_dig(min(need, self.exc.bucket_capacity), threshold, need)
            if best is None and fullest is not None and fullest[0] >= threshold - 1e-9 and not parked:
                # soil worth a dig, but the truck stands nowhere it may from here: park it anew
                parked = True
                if self.relocate(visited, stay=True, toward=fullest[1]):
                    continue
            if best is None:
                parked = False
                if not self.relocate(visited):
                    break
                continue
            parked = False
            self.dig(best)
            self.dump()
            dumps += 1
            if max_dumps is not None and dumps >= max_dumps:
                break
        return Plan(
            tuple(sorted(self.actions, key=_referee_order)),
            Prediction(volume=self.loaded - start, makespan=self.t),
            {"planner": "greedy", "stations": len(visited)},
        )

    # -- digging -----------------------------------------------------------------------------
    def strokes(self) -> tuple[np.ndarray, ...]:
        """The strokes open from the current base: contacts (n×2), headings toward the base,
        the flat grid indices (n×m) of the points sampled across each bucket footprint, and the
        row and column range of those points (4×n: first row, last row, first and last column).

        Only geometry (reach, dig area, keep-outs), so it is worked out once per station.
        """
        key = (self.base.x, self.base.y)
        if self._strokes is not None and self._strokes[0] == key:
            return self._strokes[1]
        e, c = self.exc, self.cfg
        L = e.max_drag_length
        radii = np.arange(e.reach_min + L, e.reach_max + 1e-9, c.radial_step)
        pts, heads = [], []
        for r in radii:
            n = max(int(2 * math.pi * r / c.arc_step), 8)
            ang = np.arange(n) * (2 * math.pi / n)
            pts.append(np.stack([self.base.x + r * np.cos(ang), self.base.y + r * np.sin(ang)], axis=1))
            heads.append(ang + math.pi)
        p = np.concatenate(pts)
        h = np.concatenate(heads)
        xmin, xmax, ymin, ymax = self.terrain.extent
        keep = (p[:, 0] > xmin) & (p[:, 0] < xmax) & (p[:, 1] > ymin) & (p[:, 1] < ymax)
        p, h = p[keep], h[keep]
        if len(p):
            u = np.stack([np.cos(h), np.sin(h)], axis=1)
            v = np.stack([-u[:, 1], u[:, 0]], axis=1) * (e.bucket_width / 2)
            end = p + u * L
            rings = np.stack([p + v, end + v, end - v, p - v], axis=1)
            polys = shapely.polygons(rings)
            ok = shapely.contains(self.dig_area, polys)
            for ko in self.keep_outs:
                ok &= ~shapely.intersects(ko, polys)
            p, h = p[ok], h[ok]
        # the estimate's sample points: cell-sized steps along the drag and across the bucket
        r = self.terrain.resolution
        along = np.arange(r / 2, L, r)
        across = np.arange(-e.bucket_width / 2 + r / 2, e.bucket_width / 2, r)
        A, C = np.meshgrid(along, across)
        A, C = A.ravel(), C.ravel()
        ux, uy = np.cos(h)[:, None], np.sin(h)[:, None]
        x = p[:, :1] + A * ux - C * uy
        y = p[:, 1:] + A * uy + C * ux
        x0, y0 = self.terrain.origin
        ny, nx = self.z.shape
        i = np.clip(((x - x0) / r).astype(int), 0, nx - 1)
        j = np.clip(((y - y0) / r).astype(int), 0, ny - 1)
        box = np.stack([j.min(axis=1), j.max(axis=1), i.min(axis=1), i.max(axis=1)]) if len(p) else np.zeros((4, 0), int)
        self._strokes = (key, (p, h, j * nx + i, box))
        return self._strokes[1]

    def candidates(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The strokes worth a cut on today's terrain: contacts, headings, cut depths, cut levels
        and estimated volumes (:meth:`estimate`)."""
        p, h, cells, box = self.strokes()
        zc = self.terrain.heights_at(p[:, 0], p[:, 1], self.z)
        depth = np.minimum(self.exc.max_cut_depth, zc - self.floor)
        level = zc - depth
        est = self.estimate(cells, box, level)
        good = depth > 0.02
        good &= away_from(p, self.barren, self.exc.bucket_width)  # closed loop: not where a dig came back empty
        return p[good], h[good], depth[good], level[good], est[good]

    def estimate(self, cells: np.ndarray, box: np.ndarray, level: np.ndarray) -> np.ndarray:
        """Vectorised volume estimate: excess above the cut level at points across the bucket.

        A stroke's estimate changes only when its cut level does or a dig has touched its
        points, so between digs at one station only those strokes are estimated again.
        """
        key = (self.base.x, self.base.y)
        if self._estimates is None or self._estimates[0] != key:
            stale, vol = np.ones(len(level), bool), np.zeros(len(level))
        else:
            stale, vol = self._estimates[1] != level, self._estimates[2]
            for rows, cols in self._cut_since:
                stale |= (box[0] < rows.stop) & (box[1] >= rows.start) & (box[2] < cols.stop) & (box[3] >= cols.start)
        self._cut_since.clear()
        r = self.terrain.resolution
        vol[stale] = np.maximum(np.take(self.z, cells[stale]) - level[stale, None], 0.0).sum(axis=1) * (r * r)
        self._estimates = (key, level, vol)
        return np.minimum(vol, self.exc.bucket_capacity)

    def best_dig(self, want: float, threshold: float,
                 need: float | None = None) -> tuple[_Dig | None, tuple[float, tuple[float, float]] | None]:
        """The stroke that loads fastest (its volume, up to ``want``, over the time until its dump
        ends) among those filling at least ``threshold`` and nearly as much as the fullest
        (``full_share``; none leaving more whole buckets of ``need`` to dig) with the truck out
        of the arm's shadow at a stand on its way (:mod:`..truck_stands`); and the fullest stroke with its contact,
        whether or not the truck can serve it from there.

        The candidates: the fullest few, and the few that load fastest were the truck to stay
        where it stands (the swing to the truck's bearing priced), confirmed with the referee's
        cut model and undermining rule.
        """
        need = want if need is None else need
        p, h, depth, level, est = self.candidates()
        if len(p) == 0:
            return None, None
        e = self.exc
        fill = np.minimum(est, want * 1.05)
        bearing = np.arctan2(p[:, 1] - self.base.y, p[:, 0] - self.base.x)
        to_truck = math.atan2(self.truck.y - self.base.y, self.truck.x - self.base.x)
        swing = (np.abs(wrap(bearing - self.base.yaw - self.turn)) + np.abs(wrap(bearing - to_truck))) / e.swing_rate
        rate = np.where(fill >= threshold - 1e-9, fill, 0.0) / (e.min_stroke_time + e.min_dump_time + swing)
        order = list(dict.fromkeys([*np.argsort(-fill)[:6].tolist(), *np.argsort(-rate)[:10].tolist()]))
        best: _Dig | None = None
        fullest: tuple[float, tuple[float, float]] | None = None
        track_level = self.station()[0]
        confirmed = []
        for k in order:
            contact, heading = (float(p[k, 0]), float(p[k, 1])), float(h[k])
            cells = path_cells(self.terrain, self.z.shape, contact, heading, e.bucket_width, e.max_drag_length)
            if self.undermines(contact, heading, float(level[k]), track_level, cells):
                continue  # the referee's undermining rule
            vol = self.trial_cut(contact, heading, float(level[k]), cells)
            if fullest is None or vol > fullest[0] + 1e-9:
                fullest = (vol, contact)
            if vol >= threshold - 1e-9:
                dur = min_dig_time(self.base, self.turn, contact, e) + _EPS_T
                confirmed.append((min(vol, want) / (dur + e.min_dump_time), vol, contact, heading, k, dur))
        # a part bucket costs a whole cycle: only strokes nearly as full as the fullest, and
        # none that leaves more buckets to dig than the fullest would
        if fullest is not None and confirmed:
            most = min(fullest[0], want)
            cap = self.exc.bucket_capacity
            left = math.ceil((need - most) / cap - 1e-6)
            confirmed = [c for c in confirmed if min(c[1], want) >= self.cfg.full_share * most - 1e-9
                         and math.ceil((need - min(c[1], want)) / cap - 1e-6) <= left]
        # best first by the rate were the truck to wait for nothing at the stand nearest the
        # dig's bearing: none after can beat a rate found
        stands = self.truck_line()
        if len(stands[0]) == 0:
            return None, fullest
        bearings = np.arctan2(stands[0][:, 1] - self.base.y, stands[0][:, 0] - self.base.x)
        for i, c in enumerate(confirmed):
            least = float(np.abs(wrap(bearings - math.atan2(c[2][1] - self.base.y, c[2][0] - self.base.x))).min())
            confirmed[i] = (min(c[1], want) / (c[5] + e.min_dump_time + least / e.swing_rate), *c[1:])
        pending = self.still_driving()
        for bound, vol, contact, heading, k, dur in sorted(confirmed, key=lambda c: -c[0]):
            if best is not None and bound <= best.score + 1e-12:
                break
            stand = self.stands.best_for_dig(self.base, self.truck, stands, contact, heading, e.max_drag_length,
                                             self.t, self.t + dur, self.truck_ready, pending)
            if stand is None:
                continue  # the arm would pass over the truck wherever it stands
            cycle = max(stand[1], self.t + dur) - self.t + stand[2] / e.swing_rate + e.min_dump_time
            score = min(vol, want) / cycle
            if best is None or score > best.score + 1e-12:
                best = _Dig(score, vol, contact, heading, float(depth[k]), stand[0], stand[1])
        return best, fullest

    def still_driving(self) -> Polygon | None:
        """What the truck's body still covers from now to the end of the move it is on (None: it
        stands still), grown by :data:`_DRIVE_PAD`: a dig meanwhile keeps its arm's shadow that far
        from it, so the truck never passes under the arm nor drives over ground a cut (and its
        slump) lowered."""
        if self.truck_ready <= self.t or not self.truck_path:
            return None
        sweep = self.stands.sweep_between(self.truck_path, self.t, self.truck_ready)
        return None if sweep is None else sweep.buffer(_DRIVE_PAD)

    def truck_line(self) -> tuple[np.ndarray, np.ndarray]:
        """The stands along the truck's heading it may take for a dig here (kept per truck pose)."""
        key = (self.truck, self.base)
        if self._line is None or self._line[0] != key:
            self._line = (key, self.stands.line(self.truck, self.base))
        return self._line[1]

    def trial_cut(self, contact: tuple[float, float], heading: float, level: float, cells: PathCells) -> float:
        """The referee's volume for one stroke (``cells``: its :func:`path_cells`), the grid
        left as it is."""
        e = self.exc
        return cut_along(self.terrain, self.z, contact, heading, e.bucket_width, e.max_drag_length, level,
                         e.bucket_capacity, cells, apply=False).volume

    def undermines(self, contact: tuple[float, float], heading: float, level: float, track_level: float,
                   cells: PathCells) -> bool:
        """Whether the stroke along ``cells`` (its :func:`path_cells`) breaks the referee's
        undermining rule: the cut applied to the grid for the check, then its path put back."""
        margin = self.margins.undermining
        if level >= track_level + margin:
            return False  # nothing is cut below the tracks' ground
        # on a scan (the realistic track) the bucket may fill later than planned and drag on toward
        # the tracks: where the scan hides a face below an edge (a cab's view) it fills it from above,
        # so the true face holds less than the scan shows; the whole drag is checked there, cut to
        # greedy's own level (``lowest``), not to the floor as singh-cannon-backhoe assumes
        e = self.exc
        stroke = Stroke(contact, heading, e.max_drag_length, level, e.bucket_capacity, cells, level)
        return path_undermines(self.sc, self.z, self.base, track_level, stroke, max(ABS_TOL, margin))

    def _window(self, contact: tuple[float, float], heading: float) -> tuple[slice, slice]:
        """Rows and columns of the grid holding every cell a stroke from ``contact`` may cut."""
        e = self.exc
        return path_window(self.terrain, self.z.shape, contact, heading, e.bucket_width, e.max_drag_length)

    def dig(self, best: _Dig) -> None:
        e = self.exc
        contact, heading, depth = best.contact, best.heading, best.depth
        dur = min_dig_time(self.base, self.turn, contact, e) + _EPS_T
        level = self.terrain.height_at(contact[0], contact[1], self.z) - depth
        rows, cols = self._window(contact, heading)
        # the faces the cut leaves slump (the referee's soil model); modelled where it matters to
        # the undermining rule, a cut below the tracks' ground (elsewhere greedy 1.2's plans stand)
        slumps = self.sc.soil is not None and level < self.station()[0] + self.margins.undermining
        if slumps:
            run = (2 * e.max_cut_depth + e.max_drag_length) / math.tan(math.radians(self.sc.soil.repose_deg))  # the slope's run
            pad = int(math.ceil(run / self.terrain.resolution)) + 2
            rows = slice(max(rows.start - pad, 0), min(rows.stop + pad, self.z.shape[0]))
            cols = slice(max(cols.start - pad, 0), min(cols.stop + pad, self.z.shape[1]))
            before = self.z[rows, cols].copy()
        self.bucket = apply_cut(self.terrain, self.z, contact, heading, e.bucket_width, e.max_drag_length, level, e.bucket_capacity)
        if slumps:
            assert self.sc.soil is not None
            slump(self.z, self.terrain.resolution, self.sc.soil.repose_deg, before, (rows.start, rows.stop, cols.start, cols.stop))
        self._cut_since.append((rows, cols))
        self._dug_since.append(self._cut_since[-1])
        if math.hypot(best.stand.x - self.truck.x, best.stand.y - self.truck.y) > 1e-9:
            # the truck slides along its heading during the dig, clear of the arm's shadow
            path = turn_drive_turn(self.truck, (best.stand.x, best.stand.y), max(self.t, self.truck_ready),
                                   self.truck_spec.travel_speed, self.truck_spec.yaw_rate)
            self.actions.append(Move("truck", tuple(path)))
            self.truck_path = path
            self.truck = Pose(path[-1][1], path[-1][2], path[-1][3])
            self.truck_ready = path[-1][0]
        self.actions.append(Dig("excavator", self.t, self.t + dur, contact, heading, depth, e.max_drag_length))
        self.t += dur
        self.turn = math.atan2(contact[1] - self.base.y, contact[0] - self.base.x) - self.base.yaw

    def dump(self) -> None:
        e = self.exc
        target = (self.truck.x, self.truck.y)
        self.t = max(self.t, self.truck_ready)
        dur = min_dump_time(self.base, self.turn, target, e) + _EPS_T
        self.actions.append(Dump("excavator", self.t, self.t + dur))
        self.t += dur
        self.loaded += min(self.bucket, self.truck_spec.capacity - self.loaded)
        self.turn = math.atan2(target[1] - self.base.y, target[0] - self.base.x) - self.base.yaw

    def station(self, base: Pose | None = None) -> tuple[float, float]:
        """The referee's ground level under the tracks and tilt at ``base`` (default: here)."""
        b = base or self.base
        if base is None and getattr(self, "_station", (None,))[0] == b:
            return self._station[1]
        out = track_level_and_tilt(self.sc, self.z, self.exc, b)
        if base is None:
            self._station = (b, out)
        return out

    # -- relocation ----------------------------------------------------------------------------
    def truck_in_reach(self, base: Pose | None = None, truck: Pose | None = None) -> bool:
        b, tr = base or self.base, truck or self.truck
        d = math.hypot(tr.x - b.x, tr.y - b.y)
        r = self.truck_spec.loading_radius
        return d - r <= self.exc.reach_max - 1e-3 and d + r >= self.exc.reach_min + 1e-3 and d >= self.exc.clearance + 0.05

    def reachable_volume(self, bases: np.ndarray) -> np.ndarray:
        """Material (m³, up to two cut depths a cell) in the dig area whose cell centres lie in
        each base's dig annulus, for all ``bases`` (n×2) at once.

        Each grid row meets the annulus in at most two column intervals; row-wise prefix sums
        of the material give each interval's sum in O(1), so a base costs one lookup per row
        in reach rather than a pass over the whole map. Bases go in blocks of
        :data:`_BASE_BLOCK`: a base's sum does not depend on its block, and small blocks reuse
        the same memory, where one (bases × rows) block over a 96 × 48 m map faulted in
        hundreds of MB of fresh pages (0.3 s of kernel time, more than the arithmetic).
        """
        e, hm = self.exc, self.terrain
        r, (x0, y0) = hm.resolution, hm.origin
        r_in, r_out = e.reach_min + e.max_drag_length, e.reach_max
        ny, nx = self.z.shape
        offsets = np.arange(int(math.ceil(2 * r_out / r)) + 2)
        if len(bases) == 0:
            return np.zeros(0)
        # only the rows some base reaches
        first = np.floor((bases[:, 1] - r_out - y0) / r).astype(int)
        band = slice(max(int(first.min()), 0), min(int(first.max()) + len(offsets), ny))
        if band.start >= band.stop:
            return np.zeros(len(bases))
        excess = np.where(self.in_area[band], np.clip(self.z[band] - self.floor, 0.0, e.max_cut_depth * 2), 0.0)
        w = np.where(excess > 1e-3, excess * hm.cell_area, 0.0)
        prefix = np.zeros((w.shape[0], nx + 1))
        np.cumsum(w, axis=1, out=prefix[:, 1:])
        def span(bx: np.ndarray, jc: np.ndarray, half: np.ndarray, closed: bool) -> np.ndarray:
            """Sum of each row's cells with centre within ``half`` of bx (closed or open)."""
            lo = (bx - half - x0) / r - 0.5
            hi = (bx + half - x0) / r - 0.5
            i_lo = np.ceil(lo) if closed else np.floor(lo) + 1
            i_hi = np.floor(hi) if closed else np.ceil(hi) - 1
            i_lo = np.clip(i_lo, 0, nx).astype(int)
            i_hi = np.clip(i_hi + 1, 0, nx).astype(int)  # exclusive end
            return np.where(i_hi > i_lo, prefix[jc, i_hi] - prefix[jc, i_lo], 0.0)

        out = np.zeros(len(bases))
        for start in range(0, len(bases), _BASE_BLOCK):
            block = bases[start:start + _BASE_BLOCK]
            bx, by = block[:, :1], block[:, 1:]
            # rows whose centre may lie within r_out of each base: (bases × rows in reach)
            j = np.floor((by - r_out - y0) / r).astype(int) + offsets
            dy2 = (y0 + (j + 0.5) * r - by) ** 2
            rows = (j >= 0) & (j < ny) & (dy2 <= r_out**2)
            jc = np.clip(j - band.start, 0, w.shape[0] - 1)
            outer = span(bx, jc, np.sqrt(np.maximum(r_out**2 - dy2, 0.0)), closed=True)
            inner = np.where(dy2 < r_in**2, span(bx, jc, np.sqrt(np.maximum(r_in**2 - dy2, 0.0)), closed=False), 0.0)
            out[start:start + len(block)] = np.where(rows, outer - inner, 0.0).sum(axis=1)
        return out

    def station_grid(self) -> tuple[np.ndarray, np.ndarray]:
        """The relocation grid's x and y (``station_step`` apart, a drag beyond the map on every
        side), as ``np.meshgrid`` gives them."""
        xmin, xmax, ymin, ymax = self.terrain.extent
        pad = self.exc.reach_min + self.exc.max_drag_length
        s = self.cfg.station_step
        return np.meshgrid(np.arange(xmin - pad, xmax + pad + 1e-9, s), np.arange(ymin - pad, ymax + pad + 1e-9, s))

    def station_volumes(self, bases: np.ndarray) -> np.ndarray:
        """:meth:`reachable_volume` of the station grid ``bases``, kept between relocations:
        only the stations within reach of what was dug since are scored again, so a relocation
        costs what the digs changed, not the size of the map."""
        cached = self._stations
        if cached is None or cached[0].shape != bases.shape or not np.array_equal(cached[0], bases):
            vol = self.reachable_volume(bases)
        else:
            vol = cached[1]
            if self._dug_since:
                r, (x0, y0), reach = self.terrain.resolution, self.terrain.origin, self.exc.reach_max + self.terrain.resolution
                rows = (min(w[0].start for w in self._dug_since), max(w[0].stop for w in self._dug_since))
                cols = (min(w[1].start for w in self._dug_since), max(w[1].stop for w in self._dug_since))
                near = ((bases[:, 0] >= x0 + cols[0] * r - reach) & (bases[:, 0] <= x0 + cols[1] * r + reach)
                        & (bases[:, 1] >= y0 + rows[0] * r - reach) & (bases[:, 1] <= y0 + rows[1] * r + reach))
                vol[near] = self.reachable_volume(bases[near])
        self._dug_since.clear()
        self._stations = (bases, vol)
        return vol

    def relocate(self, visited: set[tuple[float, float]], stay: bool = False,
                 toward: tuple[float, float] | None = None) -> bool:
        """Drive to a new station (or, with ``stay``, only bring the truck, parked toward the
        contact ``toward``); False if none works."""
        if stay:
            return self._go(self.base, toward)
        gx, gy = self.station_grid()
        bases = np.stack([gx.ravel(), gy.ravel()], axis=1)
        vol = self.station_volumes(bases)
        travel = np.hypot(bases[:, 0] - self.base.x, bases[:, 1] - self.base.y)
        # material beyond a few times what is still needed makes a station no better, only its way there
        # (the excavator's drive time, its slow turn counted); not on a scan, where a near station's tilt
        # read from it broke the rule on the true ground (standard-realistic bench-sand-cab s1, closed loop)
        if self.sc.soil is None:
            need = min(self.sc.task.target_volume, self.truck_spec.capacity) - self.loaded
            score = np.minimum(vol, _ENOUGH * need) - self.cfg.travel_penalty * self.exc_drive_times(bases) * self.exc.travel_speed
        else:
            score = vol - self.cfg.travel_penalty * travel
        for k in np.argsort(-score):
            if vol[k] < self.cfg.min_fill * self.exc.bucket_capacity:
                return False
            key = (round(float(bases[k, 0]), 3), round(float(bases[k, 1]), 3))
            if key in visited or travel[k] < 1e-6:
                continue
            if any(ko.contains(Point(key)) for ko in self.keep_outs):
                continue
            visited.add(key)
            # the truck's way first: on a large site most high-scoring stations lie deep in the
            # dig area, out of the truck's reach, and this test is cheaper than the tilt's
            move = self._truck_move(Pose(key[0], key[1], self.base.yaw))
            if move is None:
                continue
            yaw = self._exc_path(key, 0.0)[-1][3]
            if self.station(Pose(key[0], key[1], yaw))[1] > self.exc.max_tilt - self.margins.tilt:
                continue  # the referee's tilt rule
            self._drive_in_turn(key, *move)
            return True
        return False

    def reach_window(self, base: Pose) -> tuple[int, int, int, int] | None:
        """The grid's rows ``j0:j1`` and columns ``i0:i1`` within ``reach_max`` of ``base`` along
        each axis, or None where that window lies off the map."""
        e, hm = self.exc, self.terrain
        r, (x0, y0) = hm.resolution, hm.origin
        ny, nx = self.z.shape
        i0, i1 = max(int((base.x - e.reach_max - x0) / r), 0), min(int((base.x + e.reach_max - x0) / r) + 1, nx)
        j0, j1 = max(int((base.y - e.reach_max - y0) / r), 0), min(int((base.y + e.reach_max - y0) / r) + 1, ny)
        return None if i0 >= i1 or j0 >= j1 else (j0, j1, i0, i1)

    def material_bearing(self, base: Pose) -> float:
        """The bearing from ``base`` of the material it reaches (weighted by the depth above the floor)."""
        e = self.exc
        window = self.reach_window(base)
        if window is None:
            return base.yaw
        j0, j1, i0, i1 = window
        dx, dy = self.cx[j0:j1, i0:i1] - base.x, self.cy[j0:j1, i0:i1] - base.y
        d = np.hypot(dx, dy)
        w = np.where(self.in_area[j0:j1, i0:i1] & (d >= e.reach_min) & (d <= e.reach_max),
                     np.clip(self.z[j0:j1, i0:i1] - self.floor, 0.0, e.max_cut_depth * 2), 0.0)
        if w.sum() <= 0:
            return base.yaw
        return math.atan2(float((w * dy / np.maximum(d, 1e-9)).sum()), float((w * dx / np.maximum(d, 1e-9)).sum()))
