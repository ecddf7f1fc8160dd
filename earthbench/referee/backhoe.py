"""The backhoe's rules: digs (reach, depth, drag, dig area, floor, undermining, tilt,
duration) and dumps into the truck (reach, duration, the truck still)."""

from __future__ import annotations

import math

import numpy as np

from ..cut import cut_level, footprint, path_cells
from ..motion import ABS_TOL, dump_reach_excess, min_dig_time, min_dump_time
from ..plan import Dig, Dump
from ..world import ExcavatorSpec, Heightmap, Pose, Scenario
from .replay import DigRecord, Replay


def ground_under(scenario: Scenario, z: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Heights ``[k, 3]`` (x, y, z) of points every cell (≥ 0.1 m) under the rectangle
    ``corners[4, 2]``; points off the map stand on the open ground's level."""
    terrain: Heightmap = scenario.terrain
    h = max(terrain.resolution, 0.1)
    a, b, _, d = corners
    u, v = b - a, d - a
    nu, nv = max(int(math.ceil(np.hypot(*u) / h)), 1), max(int(math.ceil(np.hypot(*v) / h)), 1)
    fu, fv = np.meshgrid((np.arange(nu) + 0.5) / nu, (np.arange(nv) + 0.5) / nv)
    pts = a + fu.reshape(-1, 1) * u + fv.reshape(-1, 1) * v
    i = np.floor((pts[:, 0] - terrain.origin[0]) / terrain.resolution).astype(int)
    j = np.floor((pts[:, 1] - terrain.origin[1]) / terrain.resolution).astype(int)
    ny, nx = z.shape
    ok = (i >= 0) & (i < nx) & (j >= 0) & (j < ny)
    zz = np.full(len(pts), scenario.outside_level)
    zz[ok] = z[j[ok], i[ok]]
    return np.column_stack([pts, zz])


def track_level_and_tilt(scenario: Scenario, z: np.ndarray, spec: ExcavatorSpec, base: Pose) -> tuple[float, float]:
    """The lowest ground under the tracks, and the tilt (rad) of the plane fitted to it."""
    g = ground_under(scenario, z, spec.outline(base.x, base.y, base.yaw)[0])
    A = np.column_stack([g[:, 0] - base.x, g[:, 1] - base.y, np.ones(len(g))])
    (gx, gy, _), *_ = np.linalg.lstsq(A, g[:, 2], rcond=None)
    return float(g[:, 2].min()), math.atan(math.hypot(gx, gy))


def undermining_excess(
    terrain: Heightmap, z: np.ndarray, spec: ExcavatorSpec, base: Pose, track_level: float, jj: np.ndarray, ii: np.ndarray
) -> float:
    """How far (m) the cells ``(jj, ii)`` lie below the undermining line: ``track_level`` minus
    ``undermine_slope`` × each cell centre's horizontal distance from the tracks (≤ 0: safe)."""
    if jj.size == 0:
        return -math.inf
    x = terrain.origin[0] + (ii + 0.5) * terrain.resolution - base.x
    y = terrain.origin[1] + (jj + 0.5) * terrain.resolution - base.y
    c, s = math.cos(base.yaw), math.sin(base.yaw)
    along, across = np.abs(x * c + y * s), np.abs(-x * s + y * c)
    d = np.hypot(np.maximum(along - spec.track_length / 2, 0.0), np.maximum(across - spec.track_width / 2, 0.0))
    return float(np.max(track_level - spec.undermine_slope * d - z[jj, ii]))


def dig(r: Replay, n: int, a: Dig) -> None:
    spec = r.specs.get(a.machine)
    if a.machine != "excavator" or not isinstance(spec, ExcavatorSpec):
        r.flag(n, "wrong_machine", 1.0, f"{a.machine} cannot dig; only the excavator digs")
        return
    base = r.timelines[a.machine].pose(a.t_start)
    level_under, _ = _station(r, n, spec, base)
    if r.bucket > ABS_TOL:
        r.flag(n, "bucket_not_empty", r.bucket, f"the bucket still holds {r.bucket:.4f} m³")
    if a.depth > spec.max_cut_depth + ABS_TOL:
        r.flag(n, "cut_depth", a.depth - spec.max_cut_depth, f"depth {a.depth:.4f} m; limit {spec.max_cut_depth} m")
    if a.drag_length > spec.max_drag_length + ABS_TOL:
        r.flag(n, "drag_length", a.drag_length - spec.max_drag_length, f"drag {a.drag_length:.4f} m; limit {spec.max_drag_length} m")
    end = (a.contact[0] + math.cos(a.heading) * a.drag_length, a.contact[1] + math.sin(a.heading) * a.drag_length)
    for label, pt in (("contact", a.contact), ("drag end", end)):
        dist = math.hypot(pt[0] - base.x, pt[1] - base.y)
        if dist > spec.reach_max + ABS_TOL or dist < spec.reach_min - ABS_TOL:
            off = max(dist - spec.reach_max, spec.reach_min - dist)
            r.flag(n, "reach", off, f"{label} is {dist:.3f} m from the base; reach {spec.reach_min}–{spec.reach_max} m")
    fp = footprint(a.contact, a.heading, spec.bucket_width, a.drag_length)
    if not r.dig_area_tol.contains(fp):
        out = fp.difference(r.dig_area).area
        r.flag(n, "outside_dig_area", max(out, ABS_TOL), f"{out:.4f} m² of the bucket footprint lies outside the dig area")
    for ko in r.keep_outs:
        if fp.intersects(ko):
            r.flag(n, "keep_out", max(fp.intersection(ko).area, ABS_TOL), "the bucket footprint enters a keep-out zone")
    need = min_dig_time(base, r.turn, a.contact, spec)
    if a.t_end - a.t_start < need - ABS_TOL:
        r.flag(
            n, "duration", need - (a.t_end - a.t_start), f"dig lasts {a.t_end - a.t_start:.3f} s; the swing and stroke need {need:.3f} s"
        )
    level = cut_level(r.terrain, r.z, a.contact, a.depth)
    floor = r.sc.site.floor
    if floor is not None and level < floor - ABS_TOL:
        # only on the exact track is a cut below the floor the plan's own error; on the realistic
        # track (soil or a scan) the ground it meets is not the one its planner could know, and the
        # machine's grade control holds the floor (docs/DESIGN.md §5, "Rules where the planner's
        # model is not the world")
        if r.soil is None and r.sc.sensing is None:
            r.flag(n, "below_floor", floor - level, f"cut level {level:.4f} m is below the floor {floor} m")
        level = floor
    cells = path_cells(r.terrain, r.z.shape, a.contact, a.heading, spec.bucket_width, a.drag_length)
    jj, ii, _ = cells
    before = r.z[jj, ii]
    got, nominal = r.cut(a.contact, a.heading, spec.bucket_width, a.drag_length, level, spec.bucket_capacity, a.depth, cells)
    vol = got.volume
    # no cut reaches below the undermining line while its level is at or above the tracks' ground
    excess = -math.inf
    if level < level_under - ABS_TOL:
        cut = r.z[jj, ii] < before
        excess = undermining_excess(r.terrain, r.z, spec, base, level_under, jj[cut], ii[cut])
    if excess > ABS_TOL:
        r.flag(
            n,
            "undermining",
            excess,
            f"the cut leaves ground {excess:.3f} m below the line falling {spec.undermine_slope:g} m per m"
            f" from the tracks (ground under them {level_under:.3f} m)",
        )
    r.settle()
    r.bucket += vol
    r.removed += vol
    r.digs.append(DigRecord(n, vol, vol / spec.bucket_capacity, None if nominal is None else nominal.volume))
    r.turn = math.atan2(a.contact[1] - base.y, a.contact[0] - base.x) - base.yaw


def _station(r: Replay, n: int, spec: ExcavatorSpec, base: Pose) -> tuple[float, float]:
    """Track level and tilt where the excavator stands to work, judged once as it arrives."""
    if r.station is None or r.station[0] != base:
        level, tilt = track_level_and_tilt(r.sc, r.z, spec, base)
        r.station = (base, level, tilt)
        if tilt > spec.max_tilt + ABS_TOL:
            r.flag(
                n,
                "tilt",
                tilt - spec.max_tilt,
                f"the excavator stands on ground tilted {math.degrees(tilt):.1f}°; limit {math.degrees(spec.max_tilt):.1f}°",
            )
    return r.station[1], r.station[2]


def dump(r: Replay, n: int, a: Dump, spec: ExcavatorSpec) -> None:
    truck_spec = r.sc.machines.truck
    truck = r.timelines["truck"]
    if truck.moving_during(a.t_start, a.t_end):
        r.flag(n, "truck_moving", 1.0, "the truck moves while the bucket is emptied")
    base = r.timelines[a.machine].pose(a.t_start)
    _station(r, n, spec, base)
    tpos = truck.pose(a.t_start)
    off = dump_reach_excess(base, (tpos.x, tpos.y), spec, truck_spec)
    if off > ABS_TOL:
        dist = math.hypot(tpos.x - base.x, tpos.y - base.y)
        r.flag(n, "dump_reach", off, f"the truck is {dist:.3f} m from the base; its loading area is out of reach")
    need = min_dump_time(base, r.turn, (tpos.x, tpos.y), spec)
    if a.t_end - a.t_start < need - ABS_TOL:
        r.flag(n, "duration", need - (a.t_end - a.t_start), f"dump lasts {a.t_end - a.t_start:.3f} s; the swing and dump need {need:.3f} s")
    take = min(r.bucket, max(r.truck_capacity - r.loaded, 0.0))
    r.loaded += take
    r.bucket -= take
    r.dumps += 1
    r.load_curve.append((a.t_end, r.loaded))
    r.turn = math.atan2(tpos.y - base.y, tpos.x - base.x) - base.yaw
