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

import math

import numpy as np

from ..cut import footprint, path_cells
from ..lazy import moved_getattr
from ..motion import ABS_TOL, RATE_TOL, arcs, loader_dump_excess, wrap
from ..plan import Charge, Dump, Move
from ..world import LoaderSpec, Pose
from ..rules import loader_base_level as _loader_base_level
from ..rules import wheel_step_excess as _wheel_step_excess
from .site import near_dig, truck_stands, undercut
from .state import DigRecord, Replay


# -- rules ---------------------------------------------------------------------------------------

def step(r: Replay, n: int, machine: str, spec: LoaderSpec, path: np.ndarray, arc: dict[str, np.ndarray] | None = None) -> None:
    base = _loader_base_level(r.sc)
    excess, x, y = _wheel_step_excess(r.terrain, r.ground, spec, path, base, arc)
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
    near_dig(r, n, a.machine, edge, yaw, spec.bucket_width, a.penetration, None, a.t_start, a.t_end)
    stands = truck_stands(r, a.t_start, a.t_end, edge, yaw, spec.bucket_width, a.penetration)
    level = r.sc.site.floor if r.sc.site.floor is not None else _loader_base_level(r.sc)
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
    undercut(r, n, stands)
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
    tpos = r.truck_for_dump(n, a.t_start, a.t_end)
    pose = r.timelines[a.machine].pose(a.t_start)
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
    r.empty_bucket(a.t_end)


# moved to earthbench.rules (0.2): the old names keep working for a release, with a warning
__getattr__ = moved_getattr(__name__, dict.fromkeys(
    ("STEP_FLOOR", "cell_heights", "densify", "loader_base_level", "step_excess", "wheel_step_excess"), "earthbench.rules"))
