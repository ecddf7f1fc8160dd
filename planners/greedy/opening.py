"""Where the greedy backhoe starts digging: stay, or first drive to a station whose material lies
toward ground where the truck can stand, so that the target's buckets swing little (issue 49).

From a base beside a dig area, with the truck off it on the same side, every dump swings from the
soil's bearing to the truck's; from a base on the far side of the soil, the truck stands beyond
it and a dump costs next to no swing (docs/metrics.md, "What the geometry forces"). Whether the
drive there pays depends on the target: the estimate weighs the time until the first dump can
start (the excavator's drive and one stroke, or the truck's drive, whichever is longer) against
the swing the target's buckets need — for ``n`` buckets, ``n`` times the angle either side of the
truck's bearing within which the material holds them (a dig swings to the contact and back).
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from shapely.geometry import Point

from earthbench.world import Pose

#: Directions (per turn) and distances (m) of the truck stands looked at around each station.
_DIRECTIONS, _DISTANCES = 24, (5.2, 6.2, 6.9)
#: Cells of the grid (one in so many each way) sampled for the material's bearings, and the
#: width (rad) of the bins they are summed in.
_SUBSAMPLE, _BIN = 4, math.radians(2.0)
#: Stations looked at: those whose reach holds the target this many times over, within this
#: radius (m) of the excavator, every one of the grid within the near radius and every other one beyond.
_HOLDS, _RADIUS, _NEAR = 1.5, 14.0, 3.0
#: Buckets the target needs at least before a drive to a better station is considered.
_BUCKETS = 8
#: Seconds the estimate must gain before the excavator drives off; stations tried for the truck's
#: way there (best first), and stands offered at each.
_GAIN, _TRIED, _STANDS = 1.0, 4, 24
#: How far (m) either way, and in what steps, a stand's line along its heading is looked at.
_SLIDE, _SLIDE_STEP = 6.0, 0.25


def _wrap(a: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-π, π)."""
    return (a + math.pi) % (2 * math.pi) - math.pi


class Opening:
    """The opening of a :class:`~earthbench_planners.greedy.backhoe.GreedySession` session, which holds
    the state it reads and changes."""

    def opening(self, visited: set[tuple[float, float]]) -> bool:
        """Drive to the station of least estimated time to the target, if it is not here; True if moved."""
        e = self.exc
        need = min(self.sc.task.target_volume, self.truck_spec.capacity) - self.loaded
        n = math.ceil(need / e.bucket_capacity - 1e-9)
        if n < _BUCKETS:
            return False  # a few buckets: the drive would not pay; ``relocate`` decides where to go
        if self.sc.soil is not None:
            return False  # a scan (the realistic track) shows ground far from where it was taken too roughly to pick a station on the soil
        bases = self._opening_stations(need)
        found: list[tuple[float, int, list[Pose]]] = []
        here = math.inf
        for k, (x, y) in enumerate(bases):  # here first: a station that cannot beat it is not looked at closely
            est = self._opening_estimate(Pose(float(x), float(y), self.base.yaw), need, n, moved=k > 0, beat=here - _GAIN)
            if k == 0:
                here = math.inf if est is None else est[0]
            elif est is not None:
                found.append((est[0], k, est[1]))
        for _, k, spots in sorted(found, key=lambda f: f[0])[:_TRIED]:
            key = (round(float(bases[k, 0]), 3), round(float(bases[k, 1]), 3))
            move = self._opening_move(Pose(key[0], key[1], self.base.yaw), spots, need, n)
            if move is not None:
                visited.add(key)
                self._drive_in_turn(key, *move)
                return True
        return False

    def _opening_move(self, base: Pose, spots: list[Pose], need: float, n: int) -> tuple[str, Pose] | None:
        """The machines' moves for a station at ``base`` (:meth:`_truck_move`) with the stand of
        least estimated time to the target (:meth:`_sliding_order`) among the first few, the
        order the machines drive in counted (one may have to wait for the other)."""
        t_exc, cands = self._sliding_order(base, spots, need, n)
        stroke = self.exc.min_stroke_time
        best: dict[bool, tuple[float, tuple[str, Pose]]] = {}  # the best with a stand as offered, and turned
        for swing, t_truck, spot, turned in cands[:_STANDS]:
            if turned in best and max(t_exc + stroke, t_truck) + swing >= best[turned][0]:
                continue  # cannot beat the best found, whichever machine drives first
            move = self._truck_move(base, spots=[spot])
            if move is None:
                continue
            start = {"both": max(t_exc + stroke, t_truck), "excavator": t_exc + max(stroke, t_truck)}.get(move[0], t_truck + t_exc + stroke)
            if turned not in best or start + swing < best[turned][0]:
                best[turned] = (start + swing, move)
        if True in best and (False not in best or best[True][0] < best[False][0] - _GAIN):
            return best[True][1]  # turned along the edge only when that gains clearly
        return best[False][1] if False in best else None

    def _opening_stations(self, need: float) -> np.ndarray:
        """Here first, then the stations of the relocation grid within ``_RADIUS`` (every other one
        beyond ``_NEAR``) whose reach holds the target ``_HOLDS`` times over, nearest first."""
        s = self.cfg.station_step
        gx, gy = self.station_grid()
        grid = np.stack([gx.ravel(), gy.ravel()], axis=1)
        vol = self.station_volumes(grid)
        dist = np.hypot(grid[:, 0] - self.base.x, grid[:, 1] - self.base.y)
        every_other = (np.round((gx - gx[0, 0]) / s).astype(int) % 2 == 0) & (np.round((gy - gy[0, 0]) / s).astype(int) % 2 == 0)
        keep = (vol >= _HOLDS * need) & (dist > 1e-6) & (dist <= _RADIUS) & ((dist <= _NEAR) | every_other.ravel())
        order = np.flatnonzero(keep)[np.argsort(dist[keep], kind="stable")]
        return np.vstack([[self.base.x, self.base.y], grid[order]])

    def _opening_estimate(self, base: Pose, need: float, n: int, moved: bool,
                          beat: float = math.inf) -> tuple[float, list[Pose]] | None:
        """(estimated time to the first dump plus the target's swing at the best truck stand
        around ``base``, the stands on ground the truck may stand on, broadside to their bearing
        so it can slide along the face, best first); None when the tracks may not stand there,
        no stand serves it, or none comes under ``beat``."""
        e = self.exc
        t_exc = 0.0
        if moved:
            path = self._exc_path((base.x, base.y), 0.0)
            base, t_exc = Pose(base.x, base.y, path[-1][3]), path[-1][0]
            if any(shapely.contains_xy(ko, base.x, base.y) for ko in self.keep_outs):
                return None
        theta, w = self._material_bearings(base)
        if w.sum() < need:
            return None
        ang = np.arange(_DIRECTIONS) * (2 * math.pi / _DIRECTIONS)
        A, D = (a.ravel() for a in np.meshgrid(ang, np.array(_DISTANCES)))
        x, y = base.x + D * np.cos(A), base.y + D * np.sin(A)
        ok = self.stands.in_reach(base, np.column_stack([x, y]), 0.3)
        A, x, y = A[ok], x[ok], y[ok]
        time, yaw = self.stands.drive_times(self.truck, x, y, A + math.pi / 2)
        # the angle either side of each stand's bearing within which the material holds the
        # target: window sums of the material's bearings binned by _BIN (a circular prefix sum)
        bins = int(round(2 * math.pi / _BIN))
        hist = np.bincount((np.mod(theta, 2 * math.pi) / _BIN).astype(int) % bins, weights=w, minlength=bins)
        cum = np.concatenate([[0.0], np.cumsum(np.tile(hist, 3))])
        centre = (np.mod(A, 2 * math.pi) / _BIN).astype(int) % bins + bins
        half = np.arange(bins // 2)
        held = cum[centre[:, None] + half + 1] - cum[centre[:, None] - half] >= need
        spread = np.where(held.any(axis=1), (held.argmax(axis=1) + 0.5) * _BIN, math.pi)
        # the first cycle swings from where the upper body faces on arrival to the truck's bearing at least
        first = np.abs(_wrap(A - base.yaw - self.turn))
        est = np.maximum(t_exc + e.min_stroke_time, time) + (n * spread + first) / e.swing_rate
        rank = np.argsort(est, kind="stable")
        rank = rank[est[rank] < beat]
        if not len(rank) or (moved and self.station(base)[1] > e.max_tilt - self.margins.tilt):
            return None
        rank = rank[:_STANDS]
        good = rank[self.stands.ground_ok(np.column_stack([x[rank], y[rank], yaw[rank]]))]
        if not len(good):
            return None
        return float(est[good[0]]), [Pose(float(x[i]), float(y[i]), float(yaw[i])) for i in good]

    def _sliding_order(self, base: Pose, spots: list[Pose], need: float, n: int) -> tuple[float, list[tuple[float, float, Pose, bool]]]:
        """``spots`` (stands for a station at ``base``) and each turned along the dig area's nearest
        edge, least estimated time to the target first: the first dump, as the opening estimates
        it, and the target's swing beyond the bearings the truck covers sliding along its heading
        (it follows the face during digs, ``truck_stands.TruckStands.line``), so a stand whose
        line runs along the edge the soil lies behind beats one broadside to the soil's bearing
        that the edge stops after a step."""
        e = self.exc
        path = self._exc_path((base.x, base.y), 0.0)
        arrive, t_exc = path[-1][3] + self.turn, path[-1][0]
        theta, w = self._material_bearings(base)
        edge = self.dig_area.exterior
        cands = []
        for sp in spots:
            d = edge.project(Point(sp.x, sp.y))
            a, b = edge.interpolate(d - 0.05), edge.interpolate(d + 0.05)
            cands += [sp, Pose(sp.x, sp.y, math.atan2(b.y - a.y, b.x - a.x))]
        poses = np.array([[c.x, c.y, c.yaw] for c in cands])
        time, yaw = self.stands.drive_times(self.truck, poses[:, 0], poses[:, 1], poses[:, 2])
        offsets = np.arange(-_SLIDE, _SLIDE + 1e-9, _SLIDE_STEP)
        mid = len(offsets) // 2
        costs = []
        for x, y, yw in zip(poses[:, 0], poses[:, 1], yaw):
            line = np.column_stack([x + offsets * math.cos(yw), y + offsets * math.sin(yw), np.full(len(offsets), yw)])
            good = self.stands.in_reach(base, line[:, :2])
            good[good] = self.stands.ground_ok(line[good])
            if not good[mid]:
                costs.append(math.inf)
                continue
            run = np.zeros(len(offsets), bool)
            for side in (slice(mid, None), slice(mid, None, -1)):
                run[side] = np.cumprod(good[side]).astype(bool)
            centre = math.atan2(y - base.y, x - base.x)
            rel = _wrap(np.arctan2(line[run, 1] - base.y, line[run, 0] - base.x) - centre)
            delta = _wrap(theta - centre)
            beyond = np.maximum.reduce([rel.min() - delta, delta - rel.max(), np.zeros(len(delta))])
            order = np.argsort(beyond)
            held = np.searchsorted(np.cumsum(w[order]), need)
            swing = n * float(beyond[order[min(held, len(order) - 1)]]) if len(order) else n * math.pi
            first = abs(float(_wrap(np.array(centre - arrive))))
            costs.append((swing + first) / e.swing_rate)
        total = np.maximum(t_exc + e.min_stroke_time, time) + np.array(costs)
        return t_exc, [(costs[i], float(time[i]), Pose(float(poses[i, 0]), float(poses[i, 1]), float(yaw[i])), i % 2 == 1)
                       for i in np.argsort(total, kind="stable") if math.isfinite(total[i])]

    def _material_bearings(self, base: Pose) -> tuple[np.ndarray, np.ndarray]:
        """Bearings from ``base`` and volumes (m³, above the floor, a cut depth deep at most) of
        the material its strokes reach (two cuts deep at most), on a grid of every ``_SUBSAMPLE``-th cell."""
        e = self.exc
        window = self.reach_window(base)
        if window is None:
            return np.zeros(0), np.zeros(0)
        j0, j1, i0, i1 = window
        sl = (slice(j0, j1, _SUBSAMPLE), slice(i0, i1, _SUBSAMPLE))
        dx, dy = self.cx[sl] - base.x, self.cy[sl] - base.y
        d = np.hypot(dx, dy)
        depth = np.clip(self.z[sl] - self.floor, 0.0, 2 * e.max_cut_depth)
        inside = self.in_area[sl] & (d >= e.reach_min + e.max_drag_length) & (d <= e.reach_max - e.bucket_width / 2) & (depth > 0.02)
        return np.arctan2(dy[inside], dx[inside]), depth[inside] * (self.terrain.resolution * _SUBSAMPLE) ** 2
