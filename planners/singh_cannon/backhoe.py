"""``singh-cannon-backhoe``: the multi-resolution bench-loading planner of Singh and Cannon.

Singh & Cannon, "Multi-resolution planning for earthmoving" (ICRA 1998), section 3.1: a coarse
planner tessellates the dig face into regions and a refined planner searches each region for
the locally best dig with a forward model. What we build, and the choices the paper leaves open:

Coarse planner (:meth:`Session.coarse_plan`)
    From the excavator's current pose, the *face* is the material above the floor (design grade)
    inside the dig area and the reach annulus. It is cut into

    - **lanes** (left to right): radial sectors of angular width ``lane_overlap · bucket_width /
      r_out``, where ``r_out`` is the farthest material in reach, so neighbouring strokes overlap
      slightly even at the outer edge and leave no ribs; "left" is counter-clockwise, as seen
      from the cab looking out at the face;
    - **bands** (top to bottom): horizontal layers below the highest material in reach, each
      ``capacity / (bucket_width · band_drag_fraction · max_drag)`` thick (0.8 m for the
      default machine: a full bucket in half the maximum drag), the last one ending at the floor.

    A region is a (band, lane) pair with the radial bounds of the lane's material above the band
    bottom; regions holding less than ``V_min`` are dropped. Regions are visited band by band
    (top first), lanes left to right, and the refined planner digs in the current region until
    it finds no feasible dig, then moves on. When no region is left, the excavator moves: the
    planner scores stations on a ``station_step`` grid by the material they reach (a
    convolution of the excess above the floor with the reach annulus; material around stations
    already exhausted counts ``depleted_weight``; counted up to max(1.5 × what is still needed,
    ``station_buckets`` buckets)) minus ``travel_value`` per second of travel, and drives
    (``earthbench.motion.turn_drive_turn``) to the best station, among those whose path keeps
    the clearance from the truck, from which the refined planner finds a feasible dig; a new
    coarse plan is made there. (When no station will do even at the lowest V_min, the stations
    in dump reach of the truck's line are tried before giving up: :meth:`Session.relocate_further`.)
    The truck is parked for the new station toward the coarse plan's material
    (``planners/truck_stands.py``: off the dig area, on ground within its limits, the
    cheapest stand in travel and swing, broadside so it can slide along the face), clear of the
    excavator by the clearance along its whole path (detouring round the excavator if
    necessary). Both drive at once only when a dense check (every 0.05 s) keeps them the
    clearance apart; otherwise the truck waits until the excavator has arrived. The excavator
    never drives while the truck is still on its way, and a dig whose arm's shadow the truck's
    way would cross waits for it to arrive.

Serving each dig (rules version 2; not in the paper)
    A dig is taken only if the truck can stay out of its arm's shadow: during the dig the truck
    slides along its heading to the stand whose dump ends soonest (least swing, least wait).
    When no dig of the current regions can be served from the truck's line, the truck is
    parked anew toward the first one before the region is given up.

Refined planner (:mod:`.backhoe_model`)
    ``n_d × n_alpha`` (20 × 10 = 200) candidates over the region's radial bounds and the approach
    angle; the forward model predicts the bucket's trajectory, swept volume, time and energy; the
    best candidate by ξ·ψ·ζ becomes a referee ``dig`` (contact on the radial line, heading toward
    the machine, depth h(α), drag length where the predicted bucket is full). The cut level of a
    region's digs may not go below the band bottom (nor the floor).

Without a design grade (``site.floor`` None) the lowest ground in the dig area serves as the
floor, so the planner never digs a pit below the surrounding site.

Closed loop (``closed_loop = true``, docs/DESIGN.md §6): the planner is reactive by design
(the paper plans each dig from the terrain as the excavator finds it), so each step makes a
new coarse plan from the observation — the terrain as now observed, the machines where they
stand, the load the truck reports — and returns the next dig with its dump (and any move
before it). The floor taken at the first step and the exhausted stations are remembered.

Execution model: the chosen dig is applied to the planner's copy of the grid with the referee's
own :func:`~earthbench.cut.apply_cut`, so the predicted volume of every dig is the one the
referee will measure. Each dig is followed by a dump into the truck. When nothing worth
``fill_min`` of a bucket remains anywhere, the planner relaxes V_min through ``relax_fills``
before giving up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry import Polygon

from earthbench.motion import turn_drive_turn, wrap
from earthbench.plan import Dig, Dump, Plan, Prediction
from earthbench.planner import closed_loop_setting
from earthbench.cut import cut_level, footprint, path_cells
from earthbench.motion import ABS_TOL, min_dig_time, min_dump_time
from earthbench.rules import stroke_start, track_level_and_tilt
from earthbench.world import ExcavatorSpec, Pose, Scenario

from ..backhoe_loop import BackhoeLoopPlanner
from ..stability import Stroke, cut_and_slump, margins, path_undermines
from ..truck_stands import TruckStands
from .backhoe_model import ForwardModel, RadialLine, SoilModel, candidate_grid, evaluate
from .stations import StationSearch

_EPS_T = 1e-6


IDLE_MOVES = 3
"""Stations tried in a row without a dig before V_min is relaxed: else one the truck cannot serve from leads to the next for ever."""


@dataclass(frozen=True)
class SinghCannonBackhoeConfig:
    n_d: int = 20
    """Candidate distances along the radial line per region."""
    n_alpha: int = 10
    """Candidate approach angles per region (n_d × n_alpha ≈ the paper's 200 starting poses)."""
    fill_min: float = 0.9
    """V_min as a fraction of the bucket capacity: ξ vetoes digs below it."""
    relax_fills: tuple[float, ...] = (0.6, 0.3)
    """V_min fractions tried, in order, when no station offers a dig of ``fill_min``."""
    lane_overlap: float = 0.9
    """Lane width at the outer edge of the face, as a fraction of the bucket width."""
    band_drag_fraction: float = 0.5
    """Band thickness = capacity / (bucket width · this · max drag length)."""
    energy_lo: float = 4_000.0
    energy_hi: float = 40_000.0
    """ψ(energy) cut-offs (J)."""
    time_span: float = 8.0
    """ζ(time) falls from 1 at the minimum stroke time to 0 this many seconds later."""
    station_step: float = 0.5
    """Spacing (m) of the candidate stations when the excavator must move."""
    stations_tried: int = 10
    """Best-scored stations checked with the refined planner before relaxing V_min."""
    station_buckets: float = 8.0
    """Material in reach counts in a station's score up to the larger of 1.5 × what is still
    needed and this many buckets."""
    travel_value: float = 0.035
    """m³ of reachable material worth one second of travel when choosing a station."""
    depleted_weight: float = 0.25
    """Weight, in station scores, of material in reach of a station already exhausted: the
    refined planner found no full bucket in it from there, so it counts for less elsewhere."""
    truck_distance: float = 5.0
    """Preferred centre distance (m) from the excavator to the truck when the truck must move."""
    max_digs: int = 1000
    closed_loop: bool = closed_loop_setting()
    """Replan every dig from the observed terrain and truck load."""
    scan_margin: float | None = None
    """Metres kept above the undermining line for the scan's error; None: derived from the
    observation (``planners/stability.py``: 0 on the exact track)."""


@dataclass(frozen=True)
class Region:
    """One coarse-plan region: a lane (radial line ``bearing``) within a band above ``level_min``."""

    band: int
    lane: int
    bearing: float
    level_min: float
    d_lo: float
    d_hi: float
    volume: float


@dataclass
class _Choice:
    region: Region
    line: RadialLine
    d: float
    alpha: float
    depth: float
    drag: float
    volume: float
    energy: float
    time: float
    quality: float
    swing: float
    stand: Pose | None = None
    """Where the truck stands for the dump (it slides there along its heading during the dig)."""
    start: float = 0.0
    """When the dig starts (later than the clock when it waits for the truck to pass)."""


class SinghCannonBackhoe(BackhoeLoopPlanner["Session", "tuple[float, np.ndarray]"]):
    """Singh & Cannon's coarse-to-fine bench-loading planner (section 3.1)."""

    name = "singh-cannon-backhoe"
    version = "1.7"
    Config = SinghCannonBackhoeConfig

    def plan(self, scenario: Scenario) -> Plan:
        return Session(scenario, self.config).run()

    def session(self, scenario: Scenario) -> Session:
        """A planning session at the scenario's initial state, to call the coarse and refined
        planners step by step (tests, benchmarks, figures)."""
        return Session(scenario, self.config)

    def _carry(self, session: Session) -> tuple[float, np.ndarray]:
        return session.floor, session.depleted

    def _one_dump(self, session: Session, carried: tuple[float, np.ndarray]) -> Plan:
        session.floor, session.depleted = carried
        session.truck_ready = session.t  # the truck waits from the observed time on
        return session.run(max_dumps=1)

    def model(self) -> ForwardModel:
        return forward_model(self.config)


def forward_model(cfg: SinghCannonBackhoeConfig) -> ForwardModel:
    return ForwardModel(
        soil=SoilModel(),
        n_d=cfg.n_d,
        n_alpha=cfg.n_alpha,
        fill_min=cfg.fill_min,
        energy_lo=cfg.energy_lo,
        energy_hi=cfg.energy_hi,
        time_span=cfg.time_span,
    )


class Session(StationSearch):
    """The state of one planning call: the planner's copy of the grid, poses, clock, actions."""

    def __init__(self, sc: Scenario, cfg: SinghCannonBackhoeConfig):
        self.sc, self.cfg = sc, cfg
        self.spec: ExcavatorSpec = sc.machines.excavator  # type: ignore[assignment]
        self.truck_spec = sc.machines.truck
        self.model = forward_model(cfg)
        self.terrain = sc.terrain
        self.z = np.array(sc.terrain.z, dtype=np.float64)
        self.area = Polygon(sc.site.dig_area)
        shapely.prepare(self.area)
        inner = self.area.buffer(-1e-3)
        self.area_inner = inner if not inner.is_empty else self.area
        shapely.prepare(self.area_inner)
        self.area_tol = self.area.buffer(ABS_TOL)
        self.keep_outs = [Polygon(k) for k in sc.site.keep_outs]
        self.margins = margins(sc, cfg.scan_margin)
        self.keep_outs_pad = [k.buffer(1e-3) for k in self.keep_outs]
        for k in self.keep_outs + self.keep_outs_pad:
            shapely.prepare(k)
        xs, ys = self.terrain.cell_centres()
        self.X, self.Y = np.meshgrid(xs, ys)
        self.in_area = shapely.contains_xy(self.area, self.X, self.Y)
        if sc.site.floor is not None:
            self.floor = float(sc.site.floor)
        else:
            self.floor = float(self.z[self.in_area].min()) if self.in_area.any() else float(self.z.min())
        self.base: Pose = sc.machines.excavator_pose  # type: ignore[assignment]
        self.truck: Pose = sc.machines.truck_pose
        self.turn = 0.0
        self.t = 0.0  # the excavator's clock
        self.truck_ready = 0.0
        self.loaded = 0.0
        self.actions: list = []
        self.log: list[dict] = []
        self.station = 0
        self.cap = self.spec.bucket_capacity
        self.v_min = cfg.fill_min * self.cap
        self.events: list[dict] = []
        self._lines: dict[tuple[float, float, float], RadialLine] = {}
        self.depleted = np.zeros(self.z.shape, dtype=bool)
        self.stands = TruckStands(sc, self.spec, self.z)
        self._line: tuple[tuple[Pose, Pose], tuple[np.ndarray, np.ndarray]] | None = None
        self.pending: np.ndarray | None = None  # the truck's move under way (samples), if any

    # -- coarse planner ---------------------------------------------------------------------------
    def coarse_plan(self, base: Pose, v_min: float) -> list[Region]:
        e, r = self.spec, self.terrain.resolution
        dx, dy = self.X - base.x, self.Y - base.y
        dist = np.hypot(dx, dy)
        excess = self.z - self.floor
        mat = self.in_area & (dist >= e.reach_min) & (dist <= e.reach_max) & (excess > 1e-3)
        if not mat.any():
            return []
        mx, my, mz, md = dx[mat], dy[mat], self.z[mat], dist[mat]
        w = excess[mat]
        centre = math.atan2(float((w * my / md).sum()), float((w * mx / md).sum()))
        rel = np.asarray(wrap(np.arctan2(my, mx) - centre))
        r_out = float(md.max())
        dth = self.cfg.lane_overlap * e.bucket_width / r_out
        lanes = []
        c = float(rel.max()) - dth / 2
        while c > float(rel.min()) - dth / 2:
            lanes.append(centre + c)
            c -= dth
        band_t = self.cap / (e.bucket_width * self.cfg.band_drag_fraction * e.max_drag_length)
        z_top = float(mz.max())
        n_bands = max(1, math.ceil((z_top - self.floor) / band_t - 1e-9))
        regions = []
        for band in range(n_bands):
            zb = max(self.floor, z_top - band_t * (band + 1))
            above = mz > zb + 1e-3
            for lane, theta in enumerate(lanes):
                ct, st = math.cos(theta), math.sin(theta)
                along = ct * mx + st * my
                sel = above & (np.abs(ct * my - st * mx) <= e.bucket_width / 2) & (along > 0)
                if not sel.any():
                    continue
                vol = float((mz[sel] - zb).sum()) * r * r
                if vol < v_min:
                    continue
                d_lo = max(float(along[sel].min()) + 0.1, e.reach_min + self.model.min_drag)
                d_hi = min(float(along[sel].max()) + 0.1, e.reach_max)
                if d_hi < d_lo:
                    continue
                regions.append(Region(band, lane, float(wrap(theta)), zb, d_lo, d_hi, vol))
        return regions

    # -- refined planner --------------------------------------------------------------------------
    def line(self, base: Pose, bearing: float) -> RadialLine:
        """The radial line's strip cells and workspace samples (independent of the heights: cached)."""
        key = (base.x, base.y, bearing)
        line = self._lines.get(key)
        if line is None:
            if len(self._lines) > 2000:
                self._lines.clear()
            line = self._lines[key] = RadialLine(self.terrain, self.spec, (base.x, base.y), bearing, self.area_inner, self.keep_outs_pad)
        return line

    def refine(self, region: Region, base: Pose, turn: float, v_min: float, line: RadialLine | None = None,
               serve: bool = False) -> _Choice | None:
        """The best dig of ``region`` from ``base`` by the paper's quality whose workspace the
        referee accepts; with ``serve``, also one the truck can serve out of the arm's shadow
        (:meth:`serve`)."""
        e = self.spec
        line = line or self.line(base, region.bearing)
        swing = abs(wrap(region.bearing - (base.yaw + turn))) / e.swing_rate
        dd, aa = candidate_grid(self.model, e, region.d_lo, region.d_hi)
        cand = evaluate(line, self.z, dd, aa, self.model, level_min=region.level_min, capacity=self.cap,
                        swing_time=swing, v_min=v_min)
        q = np.where(cand.feasible, cand.quality, 0.0)
        for _ in range(5):
            k = int(np.argmax(q))
            if q[k] <= 0:
                return None
            ch = _Choice(region, line, float(cand.d[k]), float(cand.alpha[k]), float(cand.depth[k]), float(cand.drag[k]),
                         float(cand.volume[k]), float(cand.energy[k]), float(cand.time[k]), float(q[k]), swing)
            if self.exact_ok(ch, base) and (not serve or self.serve(ch, base, turn)):
                return ch
            q[k] = 0.0
        return None

    def serve(self, ch: _Choice, base: Pose, turn: float) -> bool:
        """Find the stand the truck takes for ``ch``'s dump (:mod:`..truck_stands`): sliding
        along its heading during the dig, out of the arm's shadow, the dump done soonest. A dig
        whose shadow the truck's move still under way would cross waits for it to arrive."""
        e = self.spec
        contact, heading = self.dig_geometry(ch, base)
        duration = max(ch.time, min_dig_time(base, turn, contact, e)) + _EPS_T
        key = (self.truck, base)
        if self._line is None or self._line[0] != key:
            self._line = (key, self.stands.line(self.truck, base))
        for start in dict.fromkeys((self.t, max(self.t, self.truck_ready))):
            pending = None
            if self.pending is not None:  # where the truck still drives during the stroke
                stroke = stroke_start(base, turn, contact, e, start, start + duration)
                pending = self.stands.sweep_between(self.pending, stroke, start + duration)
            got = self.stands.best_for_dig(base, self.truck, self._line[1], contact, heading, ch.drag, start,
                                           start + duration, self.truck_ready, pending)
            if got is not None:
                ch.stand, ch.start = got[0], start
                return True
        return False

    def dig_geometry(self, ch: _Choice, base: Pose) -> tuple[tuple[float, float], float]:
        ux, uy = math.cos(ch.region.bearing), math.sin(ch.region.bearing)
        contact = (base.x + ux * ch.d, base.y + uy * ch.d)
        return contact, float(wrap(ch.region.bearing + math.pi))

    def exact_ok(self, ch: _Choice, base: Pose) -> bool:
        """The referee's own workspace checks on the chosen dig (sampling may miss a corner)."""
        e = self.spec
        contact, heading = self.dig_geometry(ch, base)
        fp = footprint(contact, heading, e.bucket_width, ch.drag)
        if not self.area_tol.contains(fp) or any(fp.intersects(k) for k in self.keep_outs):
            return False
        end = (contact[0] + math.cos(heading) * ch.drag, contact[1] + math.sin(heading) * ch.drag)
        for p in (contact, end):
            r = math.hypot(p[0] - base.x, p[1] - base.y)
            if r > e.reach_max - 1e-9 or r < e.reach_min + 1e-9:
                return False
        level = cut_level(self.terrain, self.z, contact, ch.depth)
        if level < self.floor + ABS_TOL:
            return False
        # the referee's undermining rule, on a trial cut made on the planner's grid and put back
        # (on the realistic track the whole drag: planners/stability.py)
        track_level = track_level_and_tilt(self.sc, self.z, e, base)[0]
        cells = path_cells(self.terrain, self.z.shape, contact, heading, e.bucket_width, ch.drag)
        stroke = Stroke(contact, heading, ch.drag, level, self.cap, cells, self.floor)
        return not path_undermines(self.sc, self.z, base, track_level, stroke, max(ABS_TOL, self.margins.undermining))

    def best_dig(self, regions: list[Region], start: int, base: Pose, turn: float, v_min: float,
                 serve: bool = False) -> tuple[int, _Choice | None]:
        """The first region from ``start`` on with a feasible dig (with ``serve``, one the truck
        can serve: :meth:`serve`), and that dig."""
        for k in range(start, len(regions)):
            ch = self.refine(regions[k], base, turn, v_min, serve=serve)
            if ch is not None:
                return k, ch
        return len(regions), None

    # -- execution ----------------------------------------------------------------------------------
    def do_dig(self, ch: _Choice) -> float:
        e = self.spec
        self.t = max(self.t, ch.start)
        contact, heading = self.dig_geometry(ch, self.base)
        if ch.stand is not None and math.hypot(ch.stand.x - self.truck.x, ch.stand.y - self.truck.y) > 1e-9:
            # the truck slides along its heading during the dig, clear of the arm's shadow
            self.add_truck_path(turn_drive_turn(self.truck, (ch.stand.x, ch.stand.y), max(self.t, self.truck_ready),
                                                self.truck_spec.travel_speed, self.truck_spec.yaw_rate))
        self.pending = None
        level = cut_level(self.terrain, self.z, contact, ch.depth)
        below = level < track_level_and_tilt(self.sc, self.z, e, self.base)[0] + self.margins.undermining
        vol = cut_and_slump(self.sc, self.z, Stroke(contact, heading, ch.drag, level, self.cap, (), self.floor), below)
        duration = max(ch.time, min_dig_time(self.base, self.turn, contact, e)) + _EPS_T
        self.actions.append(Dig("excavator", self.t, self.t + duration, contact, heading, ch.depth, ch.drag))
        self.log.append({
            "station": self.station, "band": ch.region.band, "lane": ch.region.lane,
            "bearing": ch.region.bearing, "d": ch.d, "alpha": ch.alpha, "depth": ch.depth,
            "drag": ch.drag, "level": level, "level_min": ch.region.level_min,
            "region_d": [ch.region.d_lo, ch.region.d_hi], "predicted_volume": ch.volume,
            "volume": vol, "energy": ch.energy, "time": ch.time, "quality": ch.quality,
            "base": [self.base.x, self.base.y],
        })
        self.t += duration
        self.turn = ch.region.bearing - self.base.yaw
        return vol

    def do_dump(self, vol: float) -> None:
        e = self.spec
        t0 = max(self.t, self.truck_ready)
        bearing = math.atan2(self.truck.y - self.base.y, self.truck.x - self.base.x)
        t1 = t0 + min_dump_time(self.base, self.turn, (self.truck.x, self.truck.y), e) + _EPS_T
        self.actions.append(Dump("excavator", t0, t1))
        self.t = t1
        self.turn = bearing - self.base.yaw
        self.loaded += min(vol, max(self.truck_spec.capacity - self.loaded, 0.0))

    def material_bearing(self, regions: list[Region], base: Pose) -> float:
        """The bearing of the coarse plan's material from ``base`` (its regions' volumes)."""
        if not regions:
            return base.yaw
        w = np.array([r.volume for r in regions])
        b = np.array([r.bearing for r in regions])
        return math.atan2(float((w * np.sin(b)).sum()), float((w * np.cos(b)).sum()))

    # -- the loop -----------------------------------------------------------------------------------
    def run(self, max_dumps: int | None = None) -> Plan:
        """Plan until the target is loaded (or ``max_dumps`` dumps: one closed-loop step)."""
        sc = self.sc
        start = self.loaded
        target = sc.task.target_volume
        fills = (self.cfg.fill_min,) + tuple(f for f in self.cfg.relax_fills if f < self.cfg.fill_min)
        level = 0
        self.v_min = fills[0] * self.cap
        self.regions = self.coarse_plan(self.base, self.v_min)
        self.ptr = 0
        status = "target reached"
        digs, parked, idle_moves, further, went_further = 0, False, 0, 0, False
        while self.loaded < target - 1e-9:
            if self.loaded >= self.truck_spec.capacity - 1e-9:
                status = "truck full"
                break
            if digs >= self.cfg.max_digs:
                status = "dig limit"
                break
            ptr = self.ptr
            if not self.truck_in_reach(self.base, (self.truck.x, self.truck.y)):
                # only when the start left it out of reach: brought toward the first dig, if any here
                _, probe = self.best_dig(self.regions, ptr, self.base, self.turn, self.v_min)
                found = None if probe is None else self.truck_route(self.base, self.material_bearing(self.regions, self.base))
                if probe is not None and found is None:
                    status = "truck cannot reach"
                    break
                if found is not None:
                    self.bring_truck(*found, self.t)
            self.ptr, ch = self.best_dig(self.regions, ptr, self.base, self.turn, self.v_min, serve=True)
            if ch is None and not parked:
                # a dig the truck cannot serve from where it stands: park it anew toward it
                _, probe = self.best_dig(self.regions, ptr, self.base, self.turn, self.v_min)
                found = None if probe is None else self.truck_route(self.base, probe.region.bearing, force=True)
                parked = True
                if found is not None and found[0]:
                    self.bring_truck(*found, self.t)
                    self.ptr = ptr
                    continue
            parked = False
            if ch is None:
                self.events.append({"event": "exhausted", "t": self.t, "station": self.station, "v_min": self.v_min})
                dist = np.hypot(self.X - self.base.x, self.Y - self.base.y)
                self.depleted |= (dist >= self.spec.reach_min) & (dist <= self.spec.reach_max)
                if idle_moves < IDLE_MOVES and self.relocate(self.v_min):
                    idle_moves += 1
                    continue
                level, idle_moves = level + 1, 0
                if (level >= len(fills) or went_further) and further < IDLE_MOVES \
                        and self.relocate_further(fills[0] * self.cap):
                    # 1.7: a station the truck can get to, where 1.6 gave up (and, from then on,
                    # before V_min is relaxed); V_min starts again
                    level, further, went_further = 0, further + 1, True
                    self.v_min = fills[0] * self.cap
                    continue
                if level >= len(fills):
                    status = "no feasible dig left"
                    break
                self.v_min = fills[level] * self.cap
                self.regions, self.ptr = self.coarse_plan(self.base, self.v_min), 0
                continue
            vol = self.do_dig(ch)
            digs, idle_moves, further = digs + 1, 0, 0
            self.do_dump(vol)
            if max_dumps is not None and digs >= max_dumps:
                status = "step done"
                break
        plan = Plan(
            tuple(self.actions),
            Prediction(volume=self.loaded - start, makespan=max((a.t_end for a in self.actions), default=0.0)),
            info={"planner": "singh-cannon-backhoe", "status": status, "digs": self.log, "events": self.events,
                  "stations": self.station},
        )
        return plan
