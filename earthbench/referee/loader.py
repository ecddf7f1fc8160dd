"""The wheel loader's rules: charges (entry pose, penetration speed, dig area, keep-out zones,
the bucket filling, the wheels' step), dumps (reach, angle, duration) and moves (turning
radius, the wheels' step), plus the step helpers planners share.

The traversable step reads "higher" as **height above the base level**: the floor, or without
one the initial ground under the loader's start. Every cell under the wheels' rectangle
(``LoaderSpec.wheels``) anywhere along a move's arcs, or along a charge after its cut, must lie
within ``max_step`` of it; off the map the open ground is level (a closed map's edge is the
``off_map`` rule's business).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ..cut import footprint, path_cells
from ..motion import ABS_TOL, RATE_TOL, arcs, dense_poses, loader_dump_excess, wrap
from ..plan import Charge, Dump, Move
from ..world import Heightmap, LoaderSpec, Pose, Scenario
from .replay import DigRecord, Replay, reach_of


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


def _rectangle_points(corners: np.ndarray, spacing: float, interior: bool) -> np.ndarray:
    """Points ``[k, 2]`` on the edges of the rectangle ``corners[4, 2]`` (and inside it, when
    ``interior``) no farther than ``spacing`` apart."""
    a, b, _, d = corners
    u, v = b - a, d - a
    nu = max(int(math.ceil(np.hypot(*u) / spacing)), 1)
    nv = max(int(math.ceil(np.hypot(*v) / spacing)), 1)
    fu, fv = np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1)
    if interior:
        gu, gv = np.meshgrid(fu, fv)
        fu, fv = gu.ravel(), gv.ravel()
    else:
        fu = np.concatenate([fu, fu, np.zeros(nv + 1), np.ones(nv + 1)])
        fv = np.concatenate([np.zeros(nu + 1), np.ones(nu + 1), fv, fv])
    return a + fu[:, None] * u + fv[:, None] * v


#: :func:`wheel_step_excess` reports any excess below this (m) as this value: poses whose
#: neighbourhood holds no cell higher than that are not looked at cell by cell.
STEP_FLOOR = -0.01


@functools.lru_cache(maxsize=16)
def _wheel_points(spec: LoaderSpec, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The wheels' rectangle at the origin, points on its edges and points covering it."""
    wheels0 = spec.wheels(0.0, 0.0, 0.0)[0]
    return wheels0, _rectangle_points(wheels0, spacing, interior=False), _rectangle_points(wheels0, spacing, interior=True)


def _placed(points: np.ndarray, poses: np.ndarray) -> np.ndarray:
    c, s = np.cos(poses[:, 3])[:, None], np.sin(poses[:, 3])[:, None]
    x = poses[:, 1:2] + points[None, :, 0] * c - points[None, :, 1] * s
    y = poses[:, 2:3] + points[None, :, 0] * s + points[None, :, 1] * c
    return np.column_stack([x.ravel(), y.ravel()])


def wheel_step_excess(
    terrain: Heightmap, z: np.ndarray, spec: LoaderSpec, path: np.ndarray, base: float, arc: dict[str, np.ndarray] | None = None
) -> tuple[float, float, float]:
    """Largest height above ``base + max_step`` of the cells under the wheels along ``path[k, 4]``
    on the motion model's arcs (≤ 0: traversable; at least :data:`STEP_FLOOR`), and where (x, y).

    The union of the wheels' rectangle over a motion is its first position plus what its
    edges sweep; so the whole first rectangle and then its edges at poses no more than a third
    of a cell apart (in the rectangle's every corner) are looked up, missing no cell. Arcs
    along which the rectangle's centre stays farther than its half-diagonal (and two cells)
    from every cell above ``base + max_step + STEP_FLOOR`` are skipped (a distance transform
    of those cells bounds the distance along the whole arc from its two ends). ``arc`` is
    ``arcs(path)`` when the caller already has it.
    """
    path = np.asarray(path, dtype=float).reshape(-1, 4)
    h = terrain.resolution / 3
    wheels0, edge, cover = _wheel_points(spec, h)
    first = _placed(cover, path[:1])
    high = z > base + spec.max_step + STEP_FLOOR
    if not high.any():
        return STEP_FLOOR, float(path[0, 1]), float(path[0, 2])
    centre = wheels0.mean(axis=0)
    reach = reach_of(wheels0 - centre)
    r = terrain.resolution
    ny, nx = z.shape
    a = (arcs(path) if arc is None else arc) if len(path) > 1 else None
    travel = a["length"] + np.abs(a["dyaw"]) * float(np.hypot(*centre)) if a is not None else np.zeros(0)
    pad = int(math.ceil((reach + (travel.max() if travel.size else 0.0)) / r)) + 3
    cyaw, syaw = np.cos(path[:, 3]), np.sin(path[:, 3])
    i = np.floor((path[:, 1] + centre[0] * cyaw - centre[1] * syaw - terrain.origin[0]) / r).astype(int)
    j = np.floor((path[:, 2] + centre[0] * syaw + centre[1] * cyaw - terrain.origin[1]) / r).astype(int)
    i0, i1 = max(i.min() - pad, 0), min(i.max() + pad + 1, nx)
    j0, j1 = max(j.min() - pad, 0), min(j.max() + pad + 1, ny)
    if i0 >= i1 or j0 >= j1 or not high[j0:j1, i0:i1].any():
        return STEP_FLOOR, float(path[0, 1]), float(path[0, 2])
    from scipy.ndimage import distance_transform_edt  # only where a path nears high ground

    dist = distance_transform_edt(~high[j0:j1, i0:i1]) * r
    inside = (i >= i0) & (i < i1) & (j >= j0) & (j < j1)
    d = np.where(inside, dist[np.clip(j - j0, 0, j1 - j0 - 1), np.clip(i - i0, 0, i1 - i0 - 1)], 0.0)
    pts = [first]
    if a is not None:
        near = (d[:-1] + d[1:] - travel) / 2 <= reach + 2 * r
        if near.any():
            dense = dense_poses(path, h, reach_of(wheels0), only=near, arc=a)
            pts.append(_placed(edge, dense))
    pts_all = np.vstack(pts)
    hgt = cell_heights(terrain, z, pts_all) - base - spec.max_step
    hgt = np.where(np.isnan(hgt), -np.inf, hgt)
    k = int(np.argmax(hgt))
    return max(float(hgt[k]), STEP_FLOOR), float(pts_all[k, 0]), float(pts_all[k, 1])


def step_excess(terrain: Heightmap, z: np.ndarray, xy: np.ndarray, base: float, max_step: float) -> tuple[float, int]:
    """Largest height above ``base + max_step`` of the cells the polyline ``xy`` crosses, and the
    index of its densified point (≤ 0 means traversable): a point's step, for planners' quick
    pre-checks; the referee judges the wheels with :func:`wheel_step_excess`."""
    pts = densify(xy, terrain.resolution / 2)
    h = cell_heights(terrain, z, pts) - base - max_step
    h = np.where(np.isnan(h), -np.inf, h)
    k = int(np.argmax(h))
    return float(h[k]), k


# -- rules ---------------------------------------------------------------------------------------

def step(r: Replay, n: int, machine: str, spec: LoaderSpec, path: np.ndarray, arc: dict[str, np.ndarray] | None = None) -> None:
    base = loader_base_level(r.sc)
    excess, x, y = wheel_step_excess(r.terrain, r.ground, spec, path, base, arc)
    if excess > ABS_TOL:
        r.flag(
            n,
            "step",
            excess,
            f"{machine}'s wheels cross a cell {spec.max_step + excess:.3f} m above the base level {base:g} m"
            f" at ({x:.2f}, {y:.2f}); traversable step {spec.max_step} m",
        )


def move(r: Replay, n: int, a: Move, spec: LoaderSpec, arc: dict[str, np.ndarray]) -> None:
    p = np.array(a.path, dtype=float)
    k = int(np.argmin(arc["radius"]))
    radius = arc["radius"][k]
    if radius < spec.min_turning_radius * (1 - RATE_TOL) - ABS_TOL:
        what = "turns in place" if arc["chord"][k] <= ABS_TOL else f"turns on a {radius:.3f} m radius"
        r.flag(
            n,
            "turning_radius",
            spec.min_turning_radius - radius,
            f"{a.machine} {what} between samples {k} and {k + 1}; minimum {spec.min_turning_radius} m",
        )
    step(r, n, a.machine, spec, p, arc)


def charge(r: Replay, n: int, a: Charge) -> None:
    spec = r.specs.get(a.machine)
    if not isinstance(spec, LoaderSpec):
        r.flag(n, "wrong_machine", 1.0, f"{a.machine} cannot charge; only a wheel loader charges")
        return
    here = r.pose[a.machine]
    x, y, yaw = a.entry
    gap, turn = math.hypot(x - here.x, y - here.y), abs(wrap(yaw - here.yaw))
    if gap > ABS_TOL or turn > ABS_TOL:
        r.flag(
            n,
            "entry_pose",
            max(gap, turn),
            f"{a.machine} is at ({here.x:.3f}, {here.y:.3f}, yaw {here.yaw:.3f})"
            f" but the charge enters at ({x:.3f}, {y:.3f}, yaw {yaw:.3f})",
        )
    if r.bucket > ABS_TOL:
        r.flag(n, "bucket_not_empty", r.bucket, f"the bucket still holds {r.bucket:.4f} m³")
    dur = a.t_end - a.t_start
    speed = a.penetration / dur if dur > 0 else math.inf
    if speed > spec.penetration_speed * (1 + RATE_TOL):
        r.flag(
            n,
            "penetration_speed",
            speed - spec.penetration_speed,
            f"the charge drives {a.penetration:.3f} m in {dur:.3f} s ({speed:.4f} m/s); limit {spec.penetration_speed} m/s",
        )
    if dur < spec.min_charge_time - ABS_TOL:
        r.flag(n, "duration", spec.min_charge_time - dur, f"charge lasts {dur:.3f} s; the loader needs at least {spec.min_charge_time} s")
    edge = (x + spec.bucket_offset * math.cos(yaw), y + spec.bucket_offset * math.sin(yaw))
    fp = footprint(edge, yaw, spec.bucket_width, a.penetration)
    if not r.dig_area_tol.contains(fp):
        out = fp.difference(r.dig_area).area
        r.flag(n, "outside_dig_area", max(out, ABS_TOL), f"{out:.4f} m² of the bucket's path lies outside the dig area")
    ex, ey, _ = a.end
    path = np.array([[a.t_start, x, y, yaw], [max(a.t_end, a.t_start + ABS_TOL), ex, ey, yaw]])
    charge_arc = arcs(path)
    r.swept(n, a.machine, path, charge_arc)  # the outline reaches to the cutting edge: keep-out zones, map edge
    level = r.sc.site.floor if r.sc.site.floor is not None else loader_base_level(r.sc)
    cells = path_cells(r.terrain, r.z.shape, edge, yaw, spec.bucket_width, a.penetration)  # the edge's path (charge_along's)
    cut, nominal = r.cut(edge, yaw, spec.bucket_width, a.penetration, level, spec.bucket_capacity, None, cells)
    # overfill is judged on the public cut model: where the plan could know the bucket fills
    full_at = cut.full_at if nominal is None else nominal.full_at
    if full_at is not None:
        _overfill(r, n, a.penetration, level, full_at, cells)
    r.bucket += cut.volume
    r.removed += cut.volume
    r.digs.append(DigRecord(n, cut.volume, cut.volume / spec.bucket_capacity, None if nominal is None else nominal.volume))
    step(r, n, a.machine, spec, path, charge_arc)
    r.settle()  # the face slumps as the bucket withdraws: into the channel it cut, ahead of the wheels
    r.travel[a.machine] += a.penetration
    r.pose[a.machine] = Pose(ex, ey, yaw)


def _overfill(r: Replay, n: int, penetration: float, level: float, full_at: float,
              cells: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
    """The bucket filled ``full_at`` along the edge's path (``cells``): the edge may go at most
    one cell further; the material it would push through beyond that is the violation."""
    jj, ii, along = cells
    beyond = along > full_at + r.terrain.resolution + ABS_TOL
    left = float(np.maximum(r.z[jj[beyond], ii[beyond]] - level, 0.0).sum() * r.terrain.cell_area)
    if left > ABS_TOL:
        r.flag(
            n,
            "overfill",
            left,
            f"the bucket is full {full_at:.2f} m along the charge, but the edge drives on {penetration - full_at:.2f} m"
            f" through {left:.3f} m³ it cannot take",
        )


def dump(r: Replay, n: int, a: Dump, spec: LoaderSpec) -> None:
    truck_spec = r.sc.machines.truck
    truck = r.timelines["truck"]
    if truck.moving_during(a.t_start, a.t_end):
        r.flag(n, "truck_moving", 1.0, "the truck moves while the bucket is emptied")
    pose = r.timelines[a.machine].pose(a.t_start)
    tpos = truck.pose(a.t_start)
    gap, off = loader_dump_excess(pose, (tpos.x, tpos.y), spec, truck_spec)
    if gap > ABS_TOL:
        r.flag(
            n,
            "dump_reach",
            gap,
            f"the bucket edge is {gap + spec.dump_reach:.3f} m from the truck's loading circle; dump reach {spec.dump_reach} m",
        )
    if off > ABS_TOL:
        r.flag(n, "dump_reach", off, f"the truck lies {math.degrees(off + math.pi / 4):.1f}° off the loader's heading; at most 45°")
    if a.t_end - a.t_start < spec.min_dump_time - ABS_TOL:
        r.flag(
            n,
            "duration",
            spec.min_dump_time - (a.t_end - a.t_start),
            f"dump lasts {a.t_end - a.t_start:.3f} s; the loader needs {spec.min_dump_time} s",
        )
    take = min(r.bucket, max(r.truck_capacity - r.loaded, 0.0))
    r.loaded += take
    r.bucket -= take
    r.dumps += 1
    r.load_curve.append((a.t_end, r.loaded))
