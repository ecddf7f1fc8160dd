"""From an NLP solution to plan actions the referee accepts.

The NLP's trajectories are a model; the referee judges the plan on the real heightmap with
its flat cut. The conversion therefore replays every decision on an exact copy of what the
referee will do (``earthbench.cut.apply_cut``/``cut_level`` on our own copy of the grid,
``earthbench.motion.swing_time`` for durations) and re-checks every rule before it emits an
action:

- Moves: the base and truck paths are the NLP's controls, clipped to 99.9 % of the limits and
  re-integrated with the same mid-step heading rule (so each pair of samples is an exact
  unicycle chord: no lateral slip, speed and yaw rate within the limits), starting exactly where
  the machine is, then retimed to drive each chord as fast as the limits allow
  (:func:`fastest_steps`; the NLP's move steps also carry its arm motion, which the dig's own
  swing time pays for). Moves whose displacement is below 1 µm are dropped.
- Collisions: the excavator–truck centre distance is checked in continuous time (both paths
  are piecewise linear between samples) before a move is accepted.
- Digs: a phase with ``η ≥ eta_on`` becomes a dig at the NLP's contact and drag heading, at
  the full cut depth (less where the floor is closer); the referee's capacity cap then fills the
  bucket. The dig is skipped if its contact or drag end leaves the reach annulus of the real
  base pose, its footprint leaves the dig area, the truck is out of dump reach, or the cut
  would take less than ``min_dig_volume`` — unless a contact shifted by at most ``repair``
  metres along/across the drag passes these checks (the best such is used and counted as
  ``contact_repaired``: the fitted surface smooths earlier cuts, so the NLP sometimes aims at a
  hole it cannot see). The last dig's depth is bisected so that the loaded
  volume meets the target instead of overshooting it. In the as-planned mode
  (:meth:`Converter.dig_as_planned`) the NLP's digs are executed as they are: its contact,
  heading and modelled depth, the full drag, no repair and no trimming.
- Durations: a dig lasts the swing to its bearing plus the minimum stroke time, a dump the
  swing to the truck plus the minimum dump time (plus 1 µs each, never less).
- Site rules the NLP does not model (rules version 2): a dig whose arm's shadow
  (:func:`earthbench.rules.arm_shadow`) comes within :data:`SHADOW_GAP` of the truck's body is
  rejected like one out of reach (and repaired if it can be); a phase-0 truck move whose way
  leaves the truck's grade, cross-slope or step limits (:func:`earthbench.rules.truck_ground`)
  is replaced by a drive to a stand of ``planners/truck_stands.py`` (:meth:`Converter.park_truck`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely
from shapely.geometry import Polygon

from earthbench.motion import arcs, dense_poses, min_dig_time, min_dump_time, poses_at, turn_drive_turn
from earthbench.plan import Dig, Dump, Move
from earthbench.rules import arm_shadow, bodies_touch, reach_of, track_level_and_tilt, undermining_excess
from earthbench.cut import apply_cut, cut_level, footprint, path_cells
from earthbench.world import Heightmap, Pose, Scenario
from earthbench.soil import slump

from ..stability import envelope, face_blur, margins
from ..truck_stands import TruckStands
from .judge import AT_THE_STAND, StandJudge

EPS_T = 1e-6
#: How far (m) the truck's body keeps from a dig's arm shadow (the referee's samples and a cell).
SHADOW_GAP = 0.05
#: Buckets whose swing a truck stand chosen by the converter is priced for (an area's digs).
PARK_BUCKETS = 5.0
#: How far (rad) under the referee's tilt limit a stand must be for the converter to work from it.
TILT_MARGIN = 0.01


class ConversionError(RuntimeError):
    """A solution could not be turned into valid actions (reported with the solve's status)."""


@dataclass
class SimState:
    """The world as the referee will see it after the actions emitted so far."""

    scenario: Scenario
    z: np.ndarray
    t: float
    exc: Pose
    turn: float
    truck: Pose
    loaded: float = 0.0
    actions: list[Any] = field(default_factory=list)
    digs: int = 0
    dig_area: Any = None
    truck_ready: float = 0.0  # when the truck's last move ends (a dump waits for it)
    judge: StandJudge = AT_THE_STAND  # how a stand's tilt is judged

    @classmethod
    def start(cls, scenario: Scenario) -> SimState:
        m = scenario.machines
        area = Polygon(scenario.site.dig_area)
        shapely.prepare(area)
        return cls(scenario, np.array(scenario.terrain.z, dtype=float), 0.0, m.excavator_pose, 0.0, m.truck_pose,
                   dig_area=area)

    @property
    def s0(self) -> np.ndarray:
        return np.array([self.exc.x, self.exc.y, self.exc.yaw, self.turn, 0.3, -1.5,
                         self.truck.x, self.truck.y, self.truck.yaw])


def integrate(start: Pose, v: np.ndarray, w: np.ndarray, dts: np.ndarray, vmax: float, wmax: float) -> np.ndarray:
    """Nodes (len+1, 3) of the mid-step unicycle from ``start`` under clipped ``v``, ``ω``."""
    v = np.clip(v, -vmax * 0.999, vmax * 0.999)
    w = np.clip(w, -wmax * 0.999, wmax * 0.999)
    out = np.zeros((len(dts) + 1, 3))
    out[0] = (start.x, start.y, start.yaw)
    for k, dt in enumerate(dts):
        x, y, yaw = out[k]
        mid = yaw + 0.5 * w[k] * dt
        out[k + 1] = (x + v[k] * dt * math.cos(mid), y + v[k] * dt * math.sin(mid), yaw + w[k] * dt)
    return out


def fastest_steps(nodes: np.ndarray, dts: np.ndarray, vmax: float, wmax: float, margin: float = 0.999) -> np.ndarray:
    """Step durations that drive the same nodes as fast as the limits allow.

    The NLP's step durations also pay for joint motion it models inside the move steps, which
    the plan's dig and dump durations pay for again (``swing_time``). A node pair is a unicycle
    arc (the referee's motion model, :func:`earthbench.motion.arcs`), so any duration keeps it
    slip-free; the shortest one puts the arc's speed or its yaw rate at ``margin`` × the limit.
    Never longer than the NLP's own ``dts``, except where those drive the chord (the NLP's
    model) at the limit and so the longer arc above it."""
    length = arcs(np.column_stack([np.arange(len(nodes), dtype=float), nodes[:, :3]]))["length"]
    turn = np.abs(np.diff(nodes[:, 2]))
    fastest = np.maximum(length / (vmax * margin), turn / (wmax * margin))
    return np.maximum(np.minimum(dts, np.maximum(fastest, 1e-4)), fastest)


def _samples(nodes: np.ndarray, times: np.ndarray) -> list[tuple[float, float, float, float]]:
    return [(float(t), float(x), float(y), float(yaw)) for t, (x, y, yaw) in zip(times, nodes)]


Path = list[tuple[float, float, float, float]]


def _track(p: Path | Pose) -> np.ndarray | None:
    return None if isinstance(p, Pose) else np.asarray(p, dtype=float).reshape(-1, 4)


def min_distance(a: Path | Pose, b: Path | Pose, step: float = 0.025) -> float:
    """Least centre distance of two machines moving along the motion model's arcs through their
    samples (or standing still at a pose), over the time both paths share, sampled so that
    neither moves more than ``step`` between two times (:func:`earthbench.motion.dense_poses`)."""
    return _sampled(a, b, step, 0.0, 0.0)[0]


def _sampled(a: Path | Pose, b: Path | Pose, step: float, reach_a: float,
             reach_b: float) -> tuple[float, np.ndarray, np.ndarray]:
    """(least centre distance, poses of a, poses of b) at common times along both paths."""
    A, B = _track(a), _track(b)
    if A is None and B is None:
        pa = np.array([[a.x, a.y, a.yaw]])
        pb = np.array([[b.x, b.y, b.yaw]])
    else:
        t0 = max(A[0, 0] if A is not None else -math.inf, B[0, 0] if B is not None else -math.inf)
        t1 = min(A[-1, 0] if A is not None else math.inf, B[-1, 0] if B is not None else math.inf)
        if t1 < t0:
            return math.inf, np.zeros((0, 3)), np.zeros((0, 3))
        ts = [np.array([t0, t1])]
        ts += [dense_poses(P, step, r)[:, 0] for P, r in ((A, reach_a), (B, reach_b)) if P is not None]
        times = np.unique(np.concatenate(ts))
        times = times[(times >= t0) & (times <= t1)]

        def poses(P: np.ndarray | None, p: Path | Pose) -> np.ndarray:
            return np.tile([p.x, p.y, p.yaw], (len(times), 1)) if P is None else poses_at(P, times)

        pa, pb = poses(A, a), poses(B, b)
    return float(np.min(np.hypot(pa[:, 0] - pb[:, 0], pa[:, 1] - pb[:, 1]))), pa, pb


class ScanStands(TruckStands):
    """The truck's stands on a scan, whose faces may lie ``radius`` cells from where it shows them
    (:func:`planners.stability.face_blur`): the ground under the truck keeps its limits on the
    grid and on its envelope over that radius, the lowest and the highest heights near each cell
    (so a bank or a cut's wall the truck's wheels could meet within the radius is seen)."""

    def __init__(self, sc: Scenario, spec: Any, z: np.ndarray, radius: float):
        super().__init__(sc, spec, z)
        self.radius = radius
        self._bounds: tuple[TruckStands, TruckStands] | None = None

    def ground_kept(self, poses: np.ndarray) -> np.ndarray:
        p = np.asarray(poses, dtype=float).reshape(-1, 3)
        ok = super().ground_kept(p)
        if not ok.any():
            return ok
        if self._bounds is None:  # once per grid, when first needed
            lo, hi = envelope(self.z, self.radius)
            self._bounds = (TruckStands(self.sc, self.spec, lo), TruckStands(self.sc, self.spec, hi))
        for bound in self._bounds:
            ok[ok] = bound.ground_kept(p[ok])
        return ok


class Converter:
    """Emits the actions of solved phases into a :class:`SimState`."""

    def __init__(self, scenario: Scenario, *, eta_on: float, min_dig_volume: float, depth: float, repair: float = 0.5,
                 clearance_margin: float = 0.01, retime: bool = True, follow_face: bool = False, keep_soil: bool = False):
        self.retime = retime  # moves as fast as the limits allow (fastest_steps), else at the NLP's pace
        self.follow_face = follow_face  # the truck slides along its heading during a dig (:meth:`follow`)
        self._line: tuple[tuple[Pose, Pose], tuple[np.ndarray, np.ndarray]] | None = None
        # the scan's undermining margin and the soil's slump on the realistic track (stl-tamp 0.11.0)
        self.keep_soil, self.under_margin = keep_soil, margins(scenario).undermining if keep_soil else 0.0
        self.blur = face_blur(scenario) if keep_soil else 0.0  # the scan's misplaced faces (stl-tamp 0.12.0)
        self.sc = scenario
        self.exc_spec = scenario.machines.excavator
        self.truck_spec = scenario.machines.truck
        self.eta_on, self.min_dig_volume, self.depth, self.repair = eta_on, min_dig_volume, depth, repair
        self.clearance = self.exc_spec.clearance + clearance_margin
        self.floor = scenario.site.floor
        self.skips: dict[str, int] = {}
        self._station: tuple[Pose, float, float] | None = None

    def station(self, st: SimState) -> tuple[float, float]:
        """The ground level under the tracks and their tilt where the excavator now stands,
        judged as it arrives, exactly as the referee judges a station (its first dig there)."""
        if self._station is None or self._station[0] != st.exc:
            level, tilt = track_level_and_tilt(self.sc, st.z, self.exc_spec, st.exc)
            self._station = (st.exc, level, st.judge.tilt(self.sc, st.z, self.exc_spec, st.exc, at_pose=tilt))
        return self._station[1], self._station[2]

    def undermines(self, st: SimState, contact: tuple[float, float], heading: float, depth: float, drag: float) -> bool:
        """Whether this dig breaks the referee's undermining rule (a trial cut on the footprint's
        window), with the scan's margin on the realistic track (``planners/stability.py``, as
        greedy keeps it; 0 on exact ground)."""
        track_level = self.station(st)[0]
        terrain, z = self._window(st, contact, heading, drag)
        level = cut_level(terrain, z, contact, depth)
        if level >= track_level + self.under_margin:
            return False  # nothing is cut below the tracks' ground
        es = self.exc_spec
        jj, ii, _ = path_cells(terrain, z.shape, contact, heading, es.bucket_width, drag)
        before = z[jj, ii].copy()
        apply_cut(terrain, z, contact, heading, es.bucket_width, drag, level, es.bucket_capacity)
        cut = z[jj, ii] < before
        return undermining_excess(terrain, z, es, st.exc, track_level, jj[cut], ii[cut]) > -max(1e-4, self.under_margin)

    def clear(self, exc: Path | Pose, truck: Path | Pose) -> bool:
        """Whether the excavator and the truck keep the referee's clearance rule along both paths:
        centres at least the clearance apart and footprints apart by half a cell (the referee's
        sampling step, :func:`earthbench.rules.bodies_touch`), on the arcs it drives."""
        es, ts = self.exc_spec, self.truck_spec
        step = max(self.sc.terrain.resolution / 2, 0.025)
        d, pe, pt = _sampled(exc, truck, step, reach_of(es.body(0.0, 0.0, 0.0)), reach_of(ts.body(0.0, 0.0, 0.0)))
        return d >= self.clearance and not (len(pe) and bodies_touch(es, pe, ts, pt, margin=step).any())

    def _skip(self, why: str) -> float:
        self.skips[why] = self.skips.get(why, 0) + 1
        return 0.0

    # -- moves ------------------------------------------------------------------------------------
    def move_excavator(self, st: SimState, v: np.ndarray, w: np.ndarray, dts: np.ndarray) -> bool:
        if len(dts) == 0:
            return True
        es = self.exc_spec
        nodes = integrate(st.exc, v, w, dts, es.travel_speed, es.yaw_rate)
        if np.max(np.hypot(nodes[:, 0] - nodes[0, 0], nodes[:, 1] - nodes[0, 1])) < 1e-6 and abs(nodes[-1, 2] - nodes[0, 2]) < 1e-6:
            return True
        if self.retime:
            dts = fastest_steps(nodes, np.asarray(dts, float), es.travel_speed, es.yaw_rate)
        times = st.t + np.concatenate([[0.0], np.cumsum(dts)])
        path = _samples(nodes, times)
        if not self.clear(path, st.truck):
            self._skip("move_blocked")
            return False
        st.actions.append(Move("excavator", tuple(path)))
        st.t = float(times[-1])
        st.exc = Pose(*nodes[-1])
        return True

    def move_both(self, st: SimState, ve: np.ndarray, we: np.ndarray, vt: np.ndarray, wt: np.ndarray, dts: np.ndarray) -> str:
        """Phase 0: both machines move at once; falls back to one after the other. Returns how."""
        es = self.exc_spec
        ts = self.truck_spec
        ne = integrate(st.exc, ve, we, dts, es.travel_speed, es.yaw_rate)
        nt = integrate(st.truck, vt, wt, dts, ts.travel_speed, ts.yaw_rate)
        e_moves = np.max(np.hypot(ne[:, 0] - ne[0, 0], ne[:, 1] - ne[0, 1])) > 1e-6 or abs(ne[-1, 2] - ne[0, 2]) > 1e-6
        t_moves = np.max(np.hypot(nt[:, 0] - nt[0, 0], nt[:, 1] - nt[0, 1])) > 1e-6 or abs(nt[-1, 2] - nt[0, 2]) > 1e-6
        if t_moves and not self.stands(st).path_ok(_samples(nt, st.t + np.concatenate([[0.0], np.cumsum(dts)]))):
            # the truck's way crosses ground beyond its limits (rules version 2): the excavator
            # moves alone, then the truck drives to a stand of its own in dump reach
            self._skip("truck_ground")
            t0, n = st.t, len(st.actions)
            if not self.move_excavator(st, ve, we, dts):
                return self._blocked()
            moved = st.actions[n].path if len(st.actions) > n else None  # type: ignore[union-attr]
            return "excavator" if self.park_truck(st, Pose(*nt[-1]), t0, moved) else "truck_kept"
        if not t_moves:  # the NLP's own durations: move_excavator integrates them again, then retimes
            return "excavator" if self.move_excavator(st, ve, we, dts) else self._blocked()
        if self.retime:  # the slower machine sets each shared step's duration
            step = np.asarray(dts, float)
            dts = np.maximum(fastest_steps(ne, step, es.travel_speed, es.yaw_rate),
                             fastest_steps(nt, step, ts.travel_speed, ts.yaw_rate))
        times = st.t + np.concatenate([[0.0], np.cumsum(dts)])
        pe, pt = _samples(ne, times), _samples(nt, times)
        if not e_moves:
            if not self.clear(st.exc, pt):
                return self._blocked()
            st.actions.append(Move("truck", tuple(pt)))
            st.truck = Pose(*nt[-1])
            st.t = max(st.t, float(times[-1]))  # the excavator waits for the truck before dumping
            return "truck"
        if self.clear(pe, pt):
            st.actions.append(Move("excavator", tuple(pe)))
            st.actions.append(Move("truck", tuple(pt)))
            st.exc, st.truck = Pose(*ne[-1]), Pose(*nt[-1])
            st.t = float(times[-1])
            return "together"
        # one after the other: the truck first (it usually leaves the excavator's way), then the excavator
        for first in ("truck", "excavator"):
            if first == "truck":
                if not self.clear(st.exc, pt):
                    continue
                end_truck = Pose(*nt[-1])
                pe2 = _samples(ne, times + (times[-1] - times[0]))
                if not self.clear(pe2, end_truck):
                    continue
                st.actions.append(Move("truck", tuple(pt)))
                st.actions.append(Move("excavator", tuple(pe2)))
                st.exc, st.truck = Pose(*ne[-1]), end_truck
                st.t = float(pe2[-1][0])
                return "truck-first"
            end_exc = Pose(*ne[-1])
            if not self.clear(pe, st.truck):
                continue
            pt2 = _samples(nt, times + (times[-1] - times[0]))
            if not self.clear(end_exc, pt2):
                continue
            st.actions.append(Move("excavator", tuple(pe)))
            st.actions.append(Move("truck", tuple(pt2)))
            st.exc, st.truck = end_exc, Pose(*nt[-1])
            st.t = float(pt2[-1][0])
            return "excavator-first"
        return self._blocked()

    def stands(self, st: SimState) -> TruckStands:
        """The truck's stands on the grid as it now is (``planners/truck_stands.py``); on a scanned
        site their ground also keeps the truck's limits on the scan's envelope (:class:`ScanStands`)."""
        if self.blur > 0:
            return ScanStands(self.sc, self.exc_spec, st.z, self.blur / self.sc.terrain.resolution)
        return TruckStands(self.sc, self.exc_spec, st.z)

    def park_truck(self, st: SimState, wanted: Pose, t0: float, exc_path: Any = None) -> bool:
        """Drive the truck to a stand serving the excavator where it now stands, near the
        bearing of ``wanted`` (the NLP's stand) and cheap in travel, on ground within its limits
        all the way (``planners/truck_stands.py``): from ``t0`` alongside the excavator's move
        ``exc_path`` when the two keep the clearance, else after it. False (the truck stays)
        when it is in dump reach already or no stand works."""
        d = math.hypot(st.truck.x - st.exc.x, st.truck.y - st.exc.y)
        r = self.truck_spec.loading_radius
        if d - r <= self.exc_spec.reach_max - 1e-3 and d + r >= self.exc_spec.reach_min + 1e-3:
            return False
        stands = self.stands(st)
        bearing = math.atan2(wanted.y - st.exc.y, wanted.x - st.exc.x)
        ts = self.truck_spec
        for tried, stand in enumerate(stands.parking(st.exc, st.truck, bearing, PARK_BUCKETS)):
            if tried >= 40:
                break
            for start in ((t0, st.t) if exc_path is not None else (st.t,)):
                path = turn_drive_turn(st.truck, (stand.x, stand.y), start, ts.travel_speed, ts.yaw_rate, final_yaw=stand.yaw)
                if not stands.path_ok(path):
                    break
                # clear of the excavator where it ends up, and (setting off together) of its way,
                # the truck standing at its end once there (clear() compares shared times only)
                ok = self.clear(st.exc, path)
                if ok and start < st.t:
                    ok = self.clear(exc_path, path) and self.clear(exc_path, Pose(*path[-1][1:]))
                if ok:
                    st.actions.append(Move("truck", tuple(path)))
                    st.truck, st.t = Pose(*path[-1][1:]), max(st.t, float(path[-1][0]))
                    return True
        return False

    def follow(self, st: SimState, contact: tuple[float, float], heading: float, drag: float, dig_t: float) -> None:
        """The truck follows the dig face: during the dig it slides along its heading to the
        stand of ``planners/truck_stands.py`` whose dump after the dig ends soonest (less swing
        against the truck's drive), clear of this dig's arm shadow, off the dig area, on kept
        ground and in dump reach; it stays where it is when that is best or nothing is clear."""
        key = (st.truck, st.exc)
        if self._line is None or self._line[0] != key:
            self._line = (key, self.stands(st).line(st.truck, st.exc))
        stands = self._line[1]
        best = self.stands(st).best_for_dig(st.exc, st.truck, stands, contact, heading, drag, st.t, st.t + dig_t,
                                            free_at=st.truck_ready)
        if best is None or math.hypot(best[0].x - st.truck.x, best[0].y - st.truck.y) < 1e-6:
            return
        ts = self.truck_spec
        path = turn_drive_turn(st.truck, (best[0].x, best[0].y), max(st.t, st.truck_ready), ts.travel_speed, ts.yaw_rate)
        if not self.clear(st.exc, path):
            return
        st.actions.append(Move("truck", tuple(path)))
        st.truck, st.truck_ready = Pose(*path[-1][1:]), float(path[-1][0])
        self._skip("truck_followed")

    def _blocked(self) -> str:
        self._skip("move_blocked")
        return "blocked"

    # -- digs ---------------------------------------------------------------------------------------
    def dig_ok(self, st: SimState, contact: tuple[float, float], heading: float) -> str | None:
        """Why a dig here is impossible for the referee (None: it is possible)."""
        es = self.exc_spec
        end = (contact[0] + math.cos(heading) * es.max_drag_length, contact[1] + math.sin(heading) * es.max_drag_length)
        for pt in (contact, end):
            r = math.hypot(pt[0] - st.exc.x, pt[1] - st.exc.y)
            if r > es.reach_max - 1e-4 or r < es.reach_min + 1e-4:
                return "reach"
        fp = footprint(contact, heading, es.bucket_width, es.max_drag_length)
        if not st.dig_area.contains(fp):
            return "outside_dig_area"
        if fp.intersection(Polygon(es.body(st.exc.x, st.exc.y, st.exc.yaw)[0])).area > 0.0:
            return "under_machine"  # a drag across the arm's bearing near reach_min (the 20-t class's tracks)
        for ko in self.sc.site.keep_outs:
            if fp.intersects(Polygon(ko)):
                return "keep_out"
        d = math.hypot(st.truck.x - st.exc.x, st.truck.y - st.exc.y)
        r = self.truck_spec.loading_radius
        if d - r > es.reach_max - 1e-4 or d + r < es.reach_min + 1e-4:
            return "dump_reach"
        shadow = Polygon(arm_shadow(st.exc, contact, heading, es.bucket_width, es.max_drag_length))
        if shadow.distance(Polygon(self.truck_spec.body(st.truck.x, st.truck.y, st.truck.yaw)[0])) <= SHADOW_GAP:
            return "arm_over_machine"  # rules version 2: no truck under the arm (nor the bucket)
        if self.station(st)[1] > es.max_tilt - TILT_MARGIN:
            return "tilt"
        return None

    def cut_volume(self, st: SimState, contact: tuple[float, float], heading: float, depth: float,
                   drag: float | None = None) -> float:
        """What the referee's cut would take here, on a copy of the grid around the footprint
        only (the same cells at the same place: a whole-grid copy per trial cut made the
        conversion grow with the map's area)."""
        es = self.exc_spec
        drag = es.max_drag_length if drag is None else drag
        terrain, z = self._window(st, contact, heading, drag)
        level = cut_level(terrain, z, contact, depth)
        return apply_cut(terrain, z, contact, heading, es.bucket_width, drag, level, es.bucket_capacity)

    def _window(self, st: SimState, contact: tuple[float, float], heading: float, drag: float,
                pad: float = 0.0) -> tuple[Heightmap, np.ndarray]:
        t = self.sc.terrain
        r, (x0, y0) = t.resolution, t.origin
        ny, nx = st.z.shape
        ex, ey = contact[0] + math.cos(heading) * drag, contact[1] + math.sin(heading) * drag
        pad = pad + self.exc_spec.bucket_width + 3 * r
        i0 = max(int(math.floor((min(contact[0], ex) - pad - x0) / r)), 0)
        i1 = min(int(math.ceil((max(contact[0], ex) + pad - x0) / r)) + 1, nx)
        j0 = max(int(math.floor((min(contact[1], ey) - pad - y0) / r)), 0)
        j1 = min(int(math.ceil((max(contact[1], ey) + pad - y0) / r)) + 1, ny)
        if i1 - i0 < 2 or j1 - j0 < 2:
            return t, st.z.copy()
        sub = st.z[j0:j1, i0:i1].copy()
        return Heightmap((x0 + i0 * r, y0 + j0 * r), r, sub), sub

    def max_depth(self, st: SimState, contact: tuple[float, float]) -> float:
        d = min(self.depth, self.exc_spec.max_cut_depth)
        if self.floor is not None:
            zc = self.sc.terrain.height_at(contact[0], contact[1], st.z)
            d = min(d, zc - self.floor - 1e-7)
        return d

    def best_contact(self, st: SimState, contact: tuple[float, float], heading: float) -> tuple[tuple[float, float], float, float] | None:
        """The NLP's contact, or — when the real grid says it is impossible or nearly empty (the
        fitted surface smooths earlier cuts) — the best of a few shifted contacts within
        ``repair`` metres along and across the drag. Returns (contact, depth, volume) or None."""
        ux, uy = math.cos(heading), math.sin(heading)
        cands = [(0.0, 0.0)]
        if self.repair > 0:
            steps = (-self.repair, -self.repair / 2, 0.0, self.repair / 2, self.repair)
            cands += sorted(((a, c) for a in steps for c in steps if (a, c) != (0.0, 0.0)), key=lambda ac: math.hypot(*ac))
        best = None
        cap = self.exc_spec.bucket_capacity
        for k, (a, c) in enumerate(cands):
            pt = (contact[0] + a * ux - c * uy, contact[1] + a * uy + c * ux)
            why = self.dig_ok(st, pt, heading)
            if why is not None:
                if k == 0:
                    self._skip(f"nlp_contact_{why}")
                continue
            depth = self.max_depth(st, pt)
            if depth <= 1e-3:
                continue
            vol = self.cut_volume(st, pt, heading, depth)
            if best is None or vol > best[2] + 1e-9:
                best = (pt, depth, vol)
            if k == 0 and vol >= self.min_dig_volume:
                return best  # the NLP's own contact works: keep it
            if best[2] >= cap - 1e-9:
                break
        if best is not None and best[2] >= self.min_dig_volume:
            self._skip("contact_repaired")
            return best
        return None

    def _bisect(self, st: SimState, contact: tuple[float, float], heading: float, depth: float, remaining: float) -> tuple[float, float]:
        lo, hi = 0.0, depth
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            if self.cut_volume(st, contact, heading, mid) >= remaining:
                hi = mid
            else:
                lo = mid
        hi = max(hi, 1e-3)  # where the ground rises along the drag even a skim overshoots
        return hi, self.cut_volume(st, contact, heading, hi)

    def _bisect_drag(self, st: SimState, contact: tuple[float, float], heading: float, depth: float,
                     remaining: float) -> float:
        """The shortest drag whose cut takes at least ``remaining`` (a shorter drag only takes less,
        and it stays on the full drag's segment, so reach and footprint stay valid)."""
        lo, hi = 0.0, self.exc_spec.max_drag_length
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            if self.cut_volume(st, contact, heading, depth, mid) >= remaining:
                hi = mid
            else:
                lo = mid
        return hi

    def exact_last_cut(self, st: SimState, contact: tuple[float, float], heading: float, depth: float,
                       remaining: float) -> tuple[tuple[float, float], float]:
        """Contact and depth whose cut is closest to ``remaining`` (not below it when possible):
        the NLP's contact first, then the repair neighbourhood when a skim there overshoots."""
        d, v = self._bisect(st, contact, heading, depth, remaining)
        best = (abs(v - remaining), contact, d)
        if v <= remaining * 1.002 or self.repair <= 0:
            return contact, d
        ux, uy = math.cos(heading), math.sin(heading)
        steps = (-self.repair, -self.repair / 2, 0.0, self.repair / 2, self.repair)
        for a in steps:
            for c in steps:
                pt = (contact[0] + a * ux - c * uy, contact[1] + a * uy + c * ux)
                if self.dig_ok(st, pt, heading) is not None:
                    continue
                dmax = self.max_depth(st, pt)
                if dmax <= 1e-3 or self.cut_volume(st, pt, heading, dmax) < remaining:
                    continue
                d2, v2 = self._bisect(st, pt, heading, dmax, remaining)
                if abs(v2 - remaining) < best[0]:
                    best = (abs(v2 - remaining), pt, d2)
                if best[0] <= remaining * 0.002:
                    return best[1], best[2]
        return best[1], best[2]

    def dig_and_dump(self, st: SimState, contact: tuple[float, float], heading: float, remaining: float) -> float:
        """Dig at ``contact`` (or its repair) and dump into the truck; returns the loaded volume (0: skipped)."""
        found = self.best_contact(st, contact, heading)
        if found is None:
            return self._skip("no_material")
        contact, depth, vol = found
        drag = self.exc_spec.max_drag_length
        if vol > remaining:  # the last bucket: bisect the depth to meet the target, then the drag
            contact, depth = self.exact_last_cut(st, contact, heading, depth, remaining)
            if self.cut_volume(st, contact, heading, depth) > remaining * 1.002:  # even a skim overshoots
                drag = self._bisect_drag(st, contact, heading, depth, remaining)
        return self._dig_and_dump(st, contact, heading, depth, drag)

    def dig_as_planned(self, st: SimState, contact: tuple[float, float], heading: float, depth: float) -> float:
        """The NLP's own dig (contact, heading, depth, full drag) as it is: no contact repair, no
        last-bucket trimming. A dig the referee would reject (reach, footprint, dump reach) is
        skipped and counted (``as_planned_<why>``) rather than emitted into an invalid plan."""
        why = self.dig_ok(st, contact, heading)
        if why is not None:
            return self._skip(f"as_planned_{why}")
        depth = min(depth, self.max_depth(st, contact))
        if depth <= 1e-6:
            return self._skip("as_planned_no_depth")
        return self._dig_and_dump(st, contact, heading, depth, self.exc_spec.max_drag_length)

    def _dig_and_dump(self, st: SimState, contact: tuple[float, float], heading: float, depth: float,
                      drag: float) -> float:
        es = self.exc_spec
        if self.undermines(st, contact, heading, depth, drag):
            return self._skip("undermining")
        dig_t = min_dig_time(st.exc, st.turn, contact, es) + EPS_T
        if self.follow_face:
            self.follow(st, contact, heading, drag, dig_t)
        z_level = cut_level(self.sc.terrain, st.z, contact, depth)
        soil = self.sc.soil if self.keep_soil else None  # the faces the cut leaves slump, as the referee's soil does
        if soil is not None:
            run = (2 * es.max_cut_depth + drag) / math.tan(math.radians(soil.repose_deg))
            t, z0 = self._window(st, contact, heading, drag, pad=run)
            (x0, y0), r = t.origin, t.resolution
            i0, j0 = int(round((x0 - self.sc.terrain.origin[0]) / r)), int(round((y0 - self.sc.terrain.origin[1]) / r))
            box = (j0, j0 + z0.shape[0], i0, i0 + z0.shape[1])
        got = apply_cut(self.sc.terrain, st.z, contact, heading, es.bucket_width, drag, z_level, es.bucket_capacity)
        if soil is not None:
            slump(st.z, self.sc.terrain.resolution, soil.repose_deg, z0, box)
        st.actions.append(Dig("excavator", st.t, st.t + dig_t, (float(contact[0]), float(contact[1])), float(heading),
                              float(depth), float(drag)))
        st.t = max(st.t + dig_t, st.truck_ready)  # the dump waits for the truck
        st.turn = math.atan2(contact[1] - st.exc.y, contact[0] - st.exc.x) - st.exc.yaw
        dump_t = min_dump_time(st.exc, st.turn, (st.truck.x, st.truck.y), es) + EPS_T
        st.actions.append(Dump("excavator", st.t, st.t + dump_t))
        st.t += dump_t
        st.turn = math.atan2(st.truck.y - st.exc.y, st.truck.x - st.exc.x) - st.exc.yaw
        take = min(got, max(self.truck_spec.capacity - st.loaded, 0.0))
        st.loaded += take
        st.digs += 1
        return take
