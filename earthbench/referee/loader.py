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

from ..cut import Cut, footprint, path_cells
from ..motion import ABS_TOL, RATE_TOL, arcs, loader_dump_excess, wrap
from ..plan import Charge, Dump, Move
from .. import compat, rules  # its names that lived here until 0.2 stay out of this module's namespace (see __getattr__)
from ..world import LoaderSpec
from .paths import swept
from .site import around_dig
from .state import Replay, Stroke, Violation


def act(r: Replay, n: int, a: Move | Dump | Charge, arc: dict[str, np.ndarray] | None) -> Stroke | None:
    """Check a loader's move (with its arcs from the shared rules) or dump, or a charge (the
    machine must be the loader); returns the charge's stroke for the loop to cut, or None."""
    spec = r.specs.get(a.machine)
    if isinstance(a, Charge):
        if not isinstance(spec, LoaderSpec):
            r.violations.append(Violation(n, "wrong_machine", 1.0, f"{a.machine} cannot charge; only a wheel loader charges"))
            return None
        return _charge(r, n, a, spec)
    assert isinstance(spec, LoaderSpec)
    if isinstance(a, Move):
        assert arc is not None
        _move(r, n, a, spec, arc)
    else:
        _dump(r, n, a, spec)
    return None


def _step(r: Replay, n: int, machine: str, spec: LoaderSpec, path: np.ndarray, arc: dict[str, np.ndarray] | None = None) -> None:
    base = rules.loader_base_level(r.sc)
    excess, x, y = rules.wheel_step_excess(r.terrain, r.z if r.firm is None else r.firm, spec, path, base, arc)
    if excess > ABS_TOL:
        r.violations.append(Violation(n, "step", float(excess),
            f"{machine}'s wheels cross a cell {spec.max_step + excess:.3f} m above the base level {base:g} m"
            f" at ({x:.2f}, {y:.2f}); traversable step {spec.max_step} m"))


def _move(r: Replay, n: int, a: Move, spec: LoaderSpec, arc: dict[str, np.ndarray]) -> None:
    p = np.array(a.path, dtype=float)
    k = int(np.argmin(arc["radius"]))
    radius = arc["radius"][k]
    if radius < spec.min_turning_radius * (1 - RATE_TOL) - ABS_TOL:
        what = "turns in place" if arc["chord"][k] <= ABS_TOL else f"turns on a {radius:.3f} m radius"
        r.violations.append(Violation(n, "turning_radius", float(spec.min_turning_radius - radius),
            f"{a.machine} {what} between samples {k} and {k + 1}; minimum {spec.min_turning_radius} m"))
    _step(r, n, a.machine, spec, p, arc)


def _charge(r: Replay, n: int, a: Charge, spec: LoaderSpec) -> Stroke:
    here = r.pose[a.machine]
    x, y, yaw = a.entry
    gap, turn = math.hypot(x - here.x, y - here.y), abs(wrap(yaw - here.yaw))
    if gap > ABS_TOL or turn > ABS_TOL:
        r.violations.append(Violation(n, "entry_pose", float(max(gap, turn)),
            f"{a.machine} is at ({here.x:.3f}, {here.y:.3f}, yaw {here.yaw:.3f})"
            f" but the charge enters at ({x:.3f}, {y:.3f}, yaw {yaw:.3f})"))
    if r.bucket > ABS_TOL:
        r.violations.append(Violation(n, "bucket_not_empty", float(r.bucket), f"the bucket still holds {r.bucket:.4f} m³"))
    dur = a.t_end - a.t_start
    speed = a.penetration / dur if dur > 0 else math.inf
    if speed > spec.penetration_speed * (1 + RATE_TOL):
        r.violations.append(Violation(n, "penetration_speed", float(speed - spec.penetration_speed),
            f"the charge drives {a.penetration:.3f} m in {dur:.3f} s ({speed:.4f} m/s); limit {spec.penetration_speed} m/s"))
    if dur < spec.min_charge_time - ABS_TOL:
        r.violations.append(Violation(n, "duration", float(spec.min_charge_time - dur),
            f"charge lasts {dur:.3f} s; the loader needs at least {spec.min_charge_time} s"))
    edge = (x + spec.bucket_offset * math.cos(yaw), y + spec.bucket_offset * math.sin(yaw))
    fp = footprint(edge, yaw, spec.bucket_width, a.penetration)
    if not r.dig_area_tol.contains(fp):
        out = fp.difference(r.dig_area).area
        r.violations.append(Violation(n, "outside_dig_area", float(max(out, ABS_TOL)),
            f"{out:.4f} m² of the bucket's path lies outside the dig area"))
    path, arc = r.memo[("charge", n)] = _charge_path(a)
    swept(r, n, a.machine, path, arc)  # the outline reaches to the cutting edge: keep-out zones, map edge
    stands = around_dig(r, n, a.machine, edge, yaw, spec.bucket_width, a.penetration, None, a.t_start, a.t_end)
    level = r.sc.site.floor if r.sc.site.floor is not None else rules.loader_base_level(r.sc)
    cells = path_cells(r.terrain, r.z.shape, edge, yaw, spec.bucket_width, a.penetration)  # the edge's path (charge_along's)
    return Stroke(a.machine, edge, yaw, spec.bucket_width, a.penetration, level, spec.bucket_capacity, None, cells,
                  r.z[cells[0], cells[1]], None, stands)


def _charge_path(a: Charge) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The loader's two samples over a charge, from its entry to its end (the heading held),
    and their arc (kept in the replay's memo until the rules after the cut)."""
    x, y, yaw = a.entry
    ex, ey, _ = a.end
    path = np.array([[a.t_start, x, y, yaw], [max(a.t_end, a.t_start + ABS_TOL), ex, ey, yaw]])
    return path, arcs(path)


def after_cut(r: Replay, n: int, a: Charge, stroke: Stroke, got: Cut, nominal: Cut | None) -> None:
    """``overfill`` (judged on the public cut model: where the plan could know the bucket fills)
    and the wheels' ``step`` along the charge, on the ground as the cut left it."""
    full_at = got.full_at if nominal is None else nominal.full_at
    if full_at is not None:
        _overfill(r, n, a.penetration, stroke.level, full_at, stroke.cells)
    spec = r.specs[a.machine]
    assert isinstance(spec, LoaderSpec)
    path, arc = r.memo.pop(("charge", n))
    _step(r, n, a.machine, spec, path, arc)


def _overfill(r: Replay, n: int, penetration: float, level: float, full_at: float,
              cells: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
    """The bucket filled ``full_at`` along the edge's path (``cells``): the edge may go at most
    one cell further; the material it would push through beyond that is the violation."""
    jj, ii, along = cells
    beyond = along > full_at + r.terrain.resolution + ABS_TOL
    left = float(np.maximum(r.z[jj[beyond], ii[beyond]] - level, 0.0).sum() * r.terrain.cell_area)
    if left > ABS_TOL:
        r.violations.append(Violation(n, "overfill", float(left),
            f"the bucket is full {full_at:.2f} m along the charge, but the edge drives on {penetration - full_at:.2f} m"
            f" through {left:.3f} m³ it cannot take"))


def _dump(r: Replay, n: int, a: Dump, spec: LoaderSpec) -> None:
    truck_spec = r.sc.machines.truck
    tpos = r.timelines["truck"].pose(a.t_start)
    pose = r.timelines[a.machine].pose(a.t_start)
    gap, off = loader_dump_excess(pose, (tpos.x, tpos.y), spec, truck_spec)
    if gap > ABS_TOL:
        r.violations.append(Violation(n, "dump_reach", float(gap),
            f"the bucket edge is {gap + spec.dump_reach:.3f} m from the truck's loading circle; dump reach {spec.dump_reach} m"))
    if off > ABS_TOL:
        r.violations.append(Violation(n, "dump_reach", float(off),
            f"the truck lies {math.degrees(off + math.pi / 4):.1f}° off the loader's heading; at most 45°"))
    if a.t_end - a.t_start < spec.min_dump_time - ABS_TOL:
        r.violations.append(Violation(n, "duration", float(spec.min_dump_time - (a.t_end - a.t_start)),
            f"dump lasts {a.t_end - a.t_start:.3f} s; the loader needs {spec.min_dump_time} s"))


__getattr__ = compat.forward(__name__)  # the rules' predicates that lived here (earthbench.compat)
