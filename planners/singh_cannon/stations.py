"""Where the backhoe of :mod:`.backhoe` moves when nothing in reach is worth a dig: the coarse
planner's candidate stations and their search (Singh and Cannon's relocation; 1.7's further search
where 1.6 gave up)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import shapely
from shapely.geometry import Point

from earthbench.motion import turn_drive_turn, wrap
from earthbench.plan import Move
from earthbench.rules import track_level_and_tilt
from earthbench.world import Pose

from ..truck_stands import SPAN
from .truck import TruckMoves

if TYPE_CHECKING:
    from .backhoe import Region

FURTHER_STATIONS = 40
"""Stations tried in the last search, where 1.6 gave up (1.7: :meth:`StationSearch.relocate_further`)."""


def _convolve_full(blocks: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """The full 2-D convolution of ``blocks`` with a 0/1 ``kernel``: one shifted add per kernel
    cell. The arrays are small (station-sized blocks, a ~15 × 15 kernel), so this takes well
    under a millisecond, where importing scipy.signal for it cost ~0.7 s of every case."""
    (ny, nx), (ky, kx) = blocks.shape, kernel.shape
    out = np.zeros((ny + ky - 1, nx + kx - 1))
    for a, b in zip(*np.nonzero(kernel)):
        out[a:a + ny, b:b + nx] += blocks
    return out


class StationSearch(TruckMoves):
    """The station search of a :class:`~earthbench_planners.singh_cannon.backhoe.Session`, which
    holds the state it reads and changes."""

    # -- relocation ---------------------------------------------------------------------------------
    def stations(self) -> tuple[np.ndarray, np.ndarray]:
        """Candidate stations on a ``station_step`` grid covering the map and a reach around it,
        with the material each reaches: block sums of the excess above the floor convolved
        with the reach annulus, shrunk by a drag's margin at both ends."""
        e, r = self.spec, self.terrain.resolution
        f = max(1, int(round(self.cfg.station_step / r)))
        step = f * r
        excess = np.where(self.in_area, np.clip(self.z - self.floor, 0.0, None), 0.0) * r * r
        excess = np.where(self.depleted, self.cfg.depleted_weight * excess, excess)
        ny, nx = excess.shape
        ny2, nx2 = (ny + f - 1) // f, (nx + f - 1) // f
        pad = np.zeros((ny2 * f, nx2 * f))
        pad[:ny, :nx] = excess
        blocks = pad.reshape(ny2, f, nx2, f).sum(axis=(1, 3))
        k = int(math.ceil(e.reach_max / step))
        off = np.arange(-k, k + 1) * step
        dist = np.hypot(off[None, :], off[:, None])
        kernel = ((dist >= e.reach_min + 0.3) & (dist <= e.reach_max - 0.2)).astype(float)
        reach = np.clip(_convolve_full(blocks, kernel), 0.0, None)
        x0, y0 = self.terrain.origin
        gx = x0 + (np.arange(nx2 + 2 * k) - k + 0.5) * step
        gy = y0 + (np.arange(ny2 + 2 * k) - k + 0.5) * step
        GX, GY = np.meshgrid(gx, gy)
        return np.stack([GX.ravel(), GY.ravel()], axis=1), reach.ravel()

    def ranked(self, v_min: float) -> tuple[np.ndarray, list[int]]:
        """The candidate stations (:meth:`stations`) and the indices of those worth trying, best first."""
        e = self.spec
        st, reach = self.stations()
        need = max(1.5 * (self.sc.task.target_volume - self.loaded), self.cfg.station_buckets * self.cap)
        dx, dy = st[:, 0] - self.base.x, st[:, 1] - self.base.y
        dist = np.hypot(dx, dy)
        bearing = np.arctan2(dy, dx)
        turn = np.minimum(np.abs(wrap(bearing - self.base.yaw)), np.abs(wrap(bearing + math.pi - self.base.yaw)))
        travel = dist / e.travel_speed + turn / e.yaw_rate
        tdist = np.hypot(st[:, 0] - self.truck.x, st[:, 1] - self.truck.y)
        truck_extra = np.where(
            tdist - self.truck_spec.loading_radius > e.reach_max - 0.05,
            np.abs(tdist - self.cfg.truck_distance) / self.truck_spec.travel_speed + 15.0,
            0.0,
        )
        inside = shapely.contains_xy(self.area, st[:, 0], st[:, 1])
        score = np.minimum(reach, need) - self.cfg.travel_value * (travel + truck_extra + 10.0 * inside)
        ok = (reach >= v_min) & (dist > 0.3) & (tdist >= e.clearance + 0.2)
        return st, [k for k in np.argsort(-score) if ok[k]]

    def relocate(self, v_min: float) -> bool:
        st, order = self.ranked(v_min)
        return self.first_station(st, order, v_min, self.cfg.stations_tried)

    def relocate_further(self, v_min: float) -> bool:
        """A last station search (1.7), where 1.6 gave up: no station of the best
        ``stations_tried`` would do, even with V_min relaxed to the last of ``relax_fills``. On a
        large site those stations are often all out of the truck's way: it stands off the dig
        area and drives only straight lines, so it cannot get round the site's corner to a stand
        serving them (or they are too tilted for the tracks). Here only the stations within dump
        reach of the truck's own line are tried (where it can slide to along its heading,
        :data:`..truck_stands.SPAN` either way), best score first, at most
        ``FURTHER_STATIONS``; the first with a feasible dig and a truck route is taken. Once it
        has moved the excavator, it is tried before V_min is relaxed as well. A plan that never
        ended "no feasible dig left" is 1.6's, action for action."""
        t = self.truck
        st, order = self.ranked(v_min)
        if not order:
            return False
        cand = st[order]
        ux, uy = math.cos(t.yaw), math.sin(t.yaw)
        s = np.clip((cand[:, 0] - t.x) * ux + (cand[:, 1] - t.y) * uy, -SPAN, SPAN)
        gap = np.hypot(cand[:, 0] - (t.x + s * ux), cand[:, 1] - (t.y + s * uy))
        near = gap - self.truck_spec.loading_radius <= self.spec.reach_max - 0.05
        return self.first_station(st, list(np.asarray(order)[near]), v_min, FURTHER_STATIONS, further=True)

    def first_station(self, st: np.ndarray, order: list[int], v_min: float, limit: int, further: bool = False) -> bool:
        """Move to the first of ``st[order]`` (at most ``limit`` tried: those off keep-outs whose
        way keeps clear of the truck) that is level enough for the tracks and has a feasible dig
        and a truck route; False when none does."""
        e = self.spec
        tried = 0
        here = (self.base.x, self.base.y)
        for k in order:
            if tried >= limit:
                break
            goal = (float(st[k, 0]), float(st[k, 1]))
            if any(ko.buffer(0.5).contains(Point(goal)) for ko in self.keep_outs):
                continue
            if not self.clear(here, goal, (self.truck.x, self.truck.y)):
                continue
            tried += 1
            path = turn_drive_turn(self.base, goal, 0.0, e.travel_speed, e.yaw_rate)
            pose = Pose(path[-1][1], path[-1][2], path[-1][3])
            if track_level_and_tilt(self.sc, self.z, e, pose)[1] > e.max_tilt - self.margins.tilt:
                continue  # the referee's tilt rule
            regions = self.coarse_plan(pose, v_min)
            idx, ch = self.best_dig(regions, 0, pose, self.turn, v_min)
            if ch is None:
                continue
            found = self.truck_route(pose, self.material_bearing(regions, pose), force=True)
            if found is None:
                continue
            self.move_to(goal, found, regions, idx, further=tried if further else None)
            return True
        return False

    def move_to(self, goal: tuple[float, float], found: tuple[list[tuple[float, float]], float | None],
                regions: list[Region], idx: int, further: int | None = None) -> None:
        """Drive the excavator to the station ``goal`` and the truck by ``found``'s route."""
        e = self.spec
        route, yaw = found
        # the truck drives at the same time when the two stay the clearance apart throughout,
        # else once the excavator has arrived (its route keeps clear of the new station)
        t0 = max(self.t, self.truck_ready)
        epath = turn_drive_turn(self.base, goal, t0, e.travel_speed, e.yaw_rate)
        tpath = self.truck_path(route, t0, yaw) if route else []
        if tpath and not self.apart(epath, tpath):
            tpath = self.truck_path(route, epath[-1][0], yaw)
        if len(epath) > 1:
            self.actions.append(Move("excavator", tuple(epath)))
            self.base = Pose(epath[-1][1], epath[-1][2], epath[-1][3])  # ``turn`` is relative
        event = {"event": "move", "t": t0, "to": list(goal), "regions": len(regions)}
        if further is not None:
            event["further"] = further
        self.events.append(event)
        self.t = epath[-1][0]
        self.station += 1
        self.add_truck_path(tpath)
        self.regions, self.ptr = regions, idx
