"""The public rules: the predicates planners check their plans with, and the referee judges by.

A planner plans within the rules by calling these functions, exactly as it calls
:mod:`earthbench.cut` (the cut model) and :mod:`earthbench.motion` (the motion model); the
referee (:mod:`earthbench.referee`) calls the same functions, so a plan checked with them is
judged the same way. Nothing here judges a plan or records a violation: that is the
referee's job alone (docs/DESIGN.md §5).

- footprints: :func:`reach_of`, :func:`rectangles_touch`, :func:`bodies_touch`,
  :func:`off_map_excess`;
- the excavator's stand: :func:`ground_under`, :func:`track_level_and_tilt`,
  :func:`undermining_excess`;
- the wheel loader's step: :func:`loader_base_level`, :func:`cell_heights`,
  :func:`wheel_step_excess`, :func:`step_excess`;
- machines near a dig and the truck's ground (rules version 2): :func:`bucket_corners`,
  :func:`arm_shadow`, :func:`stroke_start`, :func:`overlap_area`, :func:`truck_ground`,
  :func:`truck_cells`.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import shapely
import shapely.geometry

from .motion import arcs, dense_poses, swing_time
from .world import ExcavatorSpec, Heightmap, LoaderSpec, Pose, Scenario, TruckSpec, rectangle

__all__ = [
    "STEP_FLOOR", "Spec", "arm_shadow", "bodies_touch", "body_reach", "bucket_corners", "cell_heights", "densify", "ground_under",
    "loader_base_level", "off_map_excess", "overlap_area", "reach_of", "rectangles_touch", "step_excess", "stroke_start",
    "track_level_and_tilt", "truck_cells", "truck_ground", "undermining_excess", "wheel_step_excess",
]

#: A machine's specification: anything with an ``outline`` and a ``body``.
Spec = ExcavatorSpec | TruckSpec | LoaderSpec


# -- footprints ----------------------------------------------------------------------------------

def reach_of(corners: np.ndarray) -> float:
    """Farthest footprint corner from the pose (corners of the footprint at the origin)."""
    return float(np.max(np.hypot(corners[..., 0], corners[..., 1])))


@functools.lru_cache(maxsize=16)
def body_reach(spec: Spec) -> float:
    """Farthest corner of the machine's body from its pose (:func:`reach_of` its body), once per spec."""
    return reach_of(spec.body(0.0, 0.0, 0.0))


def rectangles_touch(a: np.ndarray, b: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """Whether the rectangles ``a[k, 4, 2]`` and ``b[k, 4, 2]`` come closer than ``margin`` along
    one of their four edge normals on all of them (separating axes: with ``margin`` 0, whether
    they overlap or touch)."""
    apart = np.zeros(len(a), dtype=bool)
    for r in (a, b):
        for e in (1, 3):
            axis = r[:, e] - r[:, 0]  # the rectangle's two edge directions are its normals too
            axis = axis / np.hypot(axis[:, :1], axis[:, 1:])
            pa = np.einsum("kij,kj->ki", a, axis)
            pb = np.einsum("kij,kj->ki", b, axis)
            apart |= (pa.max(axis=1) + margin < pb.min(axis=1)) | (pb.max(axis=1) + margin < pa.min(axis=1))
    return ~apart


def bodies_touch(a: Spec, poses_a: np.ndarray, b: Spec, poses_b: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """Whether the bodies of machine ``a`` at ``poses_a[k, 3]`` (x, y, yaw) and ``b`` at
    ``poses_b[k, 3]`` (or one pose for all) touch: the footprint part of the clearance rule.
    The referee samples motion at half a cell, so a planner keeps a ``margin`` of that much."""
    pa = np.asarray(poses_a, dtype=float).reshape(-1, 3)
    pb = np.broadcast_to(np.asarray(poses_b, dtype=float).reshape(-1, 3), pa.shape)
    out = np.zeros(len(pa), dtype=bool)
    near = np.hypot(pa[:, 0] - pb[:, 0], pa[:, 1] - pb[:, 1]) < reach_of(a.body(0.0, 0.0, 0.0)) + reach_of(b.body(0.0, 0.0, 0.0)) + margin
    if near.any():
        out[near] = rectangles_touch(a.body(*pa[near].T), b.body(*pb[near].T), margin)
    return out


def off_map_excess(scenario: Scenario, spec: Spec, poses: np.ndarray) -> np.ndarray:
    """How far (m) the outline at each of ``poses[k, 3]`` reaches beyond the map (≤ 0: on it)."""
    p = np.asarray(poses, dtype=float).reshape(-1, 3)
    corners = spec.outline(p[:, 0], p[:, 1], p[:, 2])
    xmin, xmax, ymin, ymax = scenario.terrain.extent
    cx, cy = corners[..., 0], corners[..., 1]
    return np.maximum.reduce([xmin - cx, cx - xmax, ymin - cy, cy - ymax]).max(axis=1)


# -- the excavator's stand -----------------------------------------------------------------------

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


# -- the wheel loader's step ---------------------------------------------------------------------

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


# -- machines near the arm and the truck's ground (rules version 2) ----------------------------

def bucket_corners(contact: tuple[float, float], heading: float, width: float, length: float) -> np.ndarray:
    """Corners ``[4, 2]`` of the bucket's footprint: ``length`` from the contact along
    ``heading``, ``width`` across (:func:`earthbench.cut.footprint` as an array)."""
    return rectangle(np.array([contact[0]]), np.array([contact[1]]), np.array([heading]), 0.0, length, width)[0]


def arm_shadow(base: Pose, contact: tuple[float, float], heading: float, width: float, length: float) -> np.ndarray:
    """The arm's ground shadow during a stroke: corners ``[m, 2]`` (counter-clockwise) of the
    convex hull of the base centre and the bucket's footprint. The boom and stick run from the
    base to the bucket low over this ground while it digs, so no machine may stand under it."""
    pts = np.vstack([[base.x, base.y], bucket_corners(contact, heading, width, length)])
    hull = shapely.geometry.polygon.orient(shapely.MultiPoint(pts).convex_hull, 1.0)  # a bucket has width: a polygon
    return shapely.get_coordinates(hull.exterior)[:-1]


def overlap_area(polygon: np.ndarray, spec: Spec, poses: np.ndarray) -> np.ndarray:
    """Area (m²) the convex ``polygon[m, 2]`` shares with the body of ``spec`` at each of
    ``poses[k, 3]`` (x, y, yaw); 0 where they are apart. Poses farther from the polygon than
    the body's reach are not intersected."""
    p = np.asarray(poses, dtype=float).reshape(-1, 3)
    out = np.zeros(len(p))
    poly = shapely.Polygon(polygon)
    centre = np.asarray(polygon).mean(axis=0)
    radius = float(np.max(np.hypot(*(np.asarray(polygon) - centre).T)))
    near = np.hypot(p[:, 0] - centre[0], p[:, 1] - centre[1]) < radius + body_reach(spec)
    if near.any():
        corners = spec.body(*p[near].T)
        bodies = shapely.polygons(np.concatenate([corners, corners[:, :1]], axis=1))
        out[near] = shapely.area(shapely.intersection(bodies, poly))
    return out


def stroke_start(base: Pose, turn: float, contact: tuple[float, float], spec: ExcavatorSpec, t_start: float, t_end: float) -> float:
    """When a dig's stroke begins: after the swing to the contact's bearing at the swing rate
    (the referee's timing of a dig, :func:`earthbench.motion.min_dig_time`), at most at its end.
    Before it the bucket swings raised; from then to the end the arm is low over its shadow."""
    return min(t_start + swing_time(base, turn, contact, spec), t_end)


@functools.lru_cache(maxsize=16)
def _ground_fit(spec: TruckSpec, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points ``[m, 2]`` covering the truck's body in its own frame (along, across), the least-
    squares map from their heights to a plane's (grade along, grade across, level), and that
    plane's design matrix."""
    corners = spec.body(0.0, 0.0, 0.0)[0]
    a, b, _, d = corners
    nu = max(int(math.ceil(np.hypot(*(b - a)) / spacing)), 1)
    nv = max(int(math.ceil(np.hypot(*(d - a)) / spacing)), 1)
    fu, fv = np.meshgrid((np.arange(nu) + 0.5) / nu, (np.arange(nv) + 0.5) / nv)
    pts = a + fu.reshape(-1, 1) * (b - a) + fv.reshape(-1, 1) * (d - a)
    design = np.column_stack([pts, np.ones(len(pts))])
    return pts, np.linalg.pinv(design), design


def truck_cells(scenario: Scenario, spec: TruckSpec, pose: Pose | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of the map's cells the truck stands on at ``pose`` (the cells
    :func:`truck_ground` reads; off the map there are none)."""
    p = np.asarray(pose if isinstance(pose, np.ndarray) else (pose.x, pose.y, pose.yaw), dtype=float).reshape(1, 3)
    t = scenario.terrain
    pts = _placed(_ground_fit(spec, max(t.resolution, 0.1))[0], np.column_stack([np.zeros(1), p]))
    i = np.floor((pts[:, 0] - t.origin[0]) / t.resolution).astype(int)
    j = np.floor((pts[:, 1] - t.origin[1]) / t.resolution).astype(int)
    ny, nx = t.z.shape
    ok = (i >= 0) & (i < nx) & (j >= 0) & (j < ny)
    return j[ok], i[ok]


def truck_ground(scenario: Scenario, z: np.ndarray, spec: TruckSpec, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The truck's ground at each of ``poses[k, 3]``: the grade along its heading and across it
    (rise over run) of the plane fitted to the ground under its body, and how far (m) that
    ground departs from the plane (a bank, a hole, a cut's face under its wheels).

    Points every cell (≥ 0.1 m) cover the body; points off the map stand on the open ground's
    level. The plane is the least-squares fit, the same linear map of the heights at every pose.
    """
    p = np.asarray(poses, dtype=float).reshape(-1, 3)
    t = scenario.terrain
    pts, fit, design = _ground_fit(spec, max(t.resolution, 0.1))
    world = _placed(pts, np.column_stack([np.zeros(len(p)), p]))
    h = cell_heights(t, z, world).reshape(len(p), len(pts))
    h = np.where(np.isnan(h), scenario.outside_level, h)
    coef = h @ fit.T
    step = np.max(np.abs(h - coef @ design.T), axis=1)
    return np.abs(coef[:, 0]), np.abs(coef[:, 1]), step
