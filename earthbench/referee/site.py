"""The site's rules around a dig and the truck's ground (rules version 2, docs/referee.md):
no machine under the arm or the bucket while it digs, and the truck's ground traversable
where it drives and stands, and not lowered under it while it stands there.

The geometry is public (:mod:`earthbench.rules`: :func:`~earthbench.rules.arm_shadow`,
:func:`~earthbench.rules.overlap_area`, :func:`~earthbench.rules.truck_ground`,
:func:`~earthbench.rules.truck_cells`); this module only samples the machines' poses and flags.
"""

from __future__ import annotations

import math

import numpy as np

from ..motion import ABS_TOL, arcs, dense_poses
from ..rules import arm_shadow, body_reach, bucket_corners, overlap_area, truck_cells, truck_ground
from ..world import Pose, TruckSpec
from .state import Replay

#: What a dig's bucket footprint (and the excavator's arm) is checked against: each machine's body.
_WHO = {"truck": "the truck", "loader": "the loader", "excavator": "the excavator's tracks"}


def _poses_during(r: Replay, machine: str, t0: float, t1: float) -> np.ndarray:
    """Poses ``[k, 3]`` of ``machine`` from ``t0`` to ``t1``: where it stands, or if it moves,
    its samples there and times close enough that no body corner moves more than half a cell
    between two."""
    tl = r.timelines[machine]
    if not tl.moving_during(t0, t1):
        p = tl.pose(t0)
        return np.array([[p.x, p.y, p.yaw]])
    spec = r.specs[machine]
    fastest = spec.travel_speed + spec.yaw_rate * body_reach(spec)
    times = [t0, t1, *(t for t in tl.times if t0 < t < t1)]
    times.extend(np.linspace(t0, t1, int(math.ceil(fastest * (t1 - t0) / max(r.spacing, 0.025))) + 1))
    return tl.poses(np.unique(np.asarray(times, dtype=float)))


def _apart(poses: np.ndarray, a: tuple[float, float], b: tuple[float, float], room: float) -> bool:
    """Whether every pose's centre lies farther than ``room`` from the segment ``a``–``b``."""
    ax, ay = a
    dx, dy = b[0] - ax, b[1] - ay
    span = max(dx * dx + dy * dy, 1e-12)
    for x, y, _ in poses.tolist():  # one pose, or a few dozen along a move: plain floats beat numpy here
        f = min(max(((x - ax) * dx + (y - ay) * dy) / span, 0.0), 1.0)
        if math.hypot(x - ax - f * dx, y - ay - f * dy) <= room:
            return False
    return True


def near_dig(r: Replay, n: int, digger: str, contact: tuple[float, float], heading: float, width: float, length: float,
             base: Pose | None, t0: float, t1: float) -> None:
    """``dig_under_machine`` and ``arm_over_machine`` for a dig (or charge) by ``digger`` from
    ``t0`` to ``t1``: the bucket's footprint (``width`` × ``length`` from ``contact`` along
    ``heading``) touches no machine's body (the excavator's own tracks included), and the arm's
    shadow from ``base`` (None for a loader) touches no other machine's body. A machine under
    the bucket is flagged only under it. Machines whose centre stays farther from the bucket
    (or the shadow, which lies within its circumradius of the segment from the base to the
    bucket's centre) than that radius plus their body's reach are clear without intersecting."""
    mid = (contact[0] + math.cos(heading) * length / 2, contact[1] + math.sin(heading) * length / 2)
    radius = math.hypot(length / 2, width / 2)
    bucket = shadow = None
    for machine, what in _WHO.items():
        if machine not in r.timelines or (machine == digger and machine != "excavator"):
            continue
        spec = r.specs[machine]
        poses = _poses_during(r, machine, t0, t1)
        room = radius + body_reach(spec)
        if not _apart(poses, mid, mid, room):
            bucket = bucket_corners(contact, heading, width, length) if bucket is None else bucket
            under = overlap_area(bucket, spec, poses)
            k = int(np.argmax(under))
            if under[k] > ABS_TOL:
                r.flag(n, "dig_under_machine", under[k], f"{under[k]:.3f} m² of the bucket's footprint lies under {what}"
                       f" at ({poses[k, 0]:.2f}, {poses[k, 1]:.2f})")
                continue
        if base is None or machine == digger or _apart(poses, (base.x, base.y), mid, room):
            continue
        shadow = arm_shadow(base, contact, heading, width, length) if shadow is None else shadow
        over = overlap_area(shadow, spec, poses)
        k = int(np.argmax(over))
        if over[k] > ABS_TOL:
            r.flag(n, "arm_over_machine", over[k], f"{what} stands {over[k]:.3f} m² into the arm's ground shadow"
                   f" at ({poses[k, 0]:.2f}, {poses[k, 1]:.2f}) while it digs")


def truck_stands(r: Replay, t0: float, t1: float, contact: tuple[float, float], heading: float, width: float,
                 length: float) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
    """The cells the truck stands on at any time from ``t0`` to ``t1`` and their heights now
    (before the cut along ``contact``, ``heading``, ``width``, ``length``, for :func:`undercut`).
    Without soil a cut lowers only cells whose centre lies in its footprint, so a truck whose
    body stays farther than a cell's half-diagonal from it stands on none of them."""
    spec = r.specs["truck"]
    assert isinstance(spec, TruckSpec)
    poses = _poses_during(r, "truck", t0, t1)
    mid = (contact[0] + math.cos(heading) * length / 2, contact[1] + math.sin(heading) * length / 2)
    room = math.hypot(length / 2, width / 2) + body_reach(spec) + r.terrain.resolution
    if r.soil is None and _apart(poses, mid, mid, room):
        nothing = np.zeros(0, dtype=int)
        return (nothing, nothing), np.zeros(0)
    if len(poses) == 1:  # a parked truck: the same cells dig after dig
        key = ("truck_cells", *poses[0])
        if key not in r.memo:
            r.memo[key] = truck_cells(r.sc, spec, poses[0])
        jj, ii = r.memo[key]
    else:
        cells = [truck_cells(r.sc, spec, p) for p in poses]
        jj, ii = np.concatenate([c[0] for c in cells]), np.concatenate([c[1] for c in cells])
    return (jj, ii), r.z[jj, ii]


def undercut(r: Replay, n: int, stands: tuple[tuple[np.ndarray, np.ndarray], np.ndarray]) -> None:
    """``truck_undercut``: after a cut (and its slump), no cell the truck stood on is lower."""
    (jj, ii), before = stands
    if jj.size == 0:
        return
    drop = float(np.max(before - r.z[jj, ii]))
    if drop > ABS_TOL:
        r.flag(n, "truck_undercut", drop, f"the cut lowers the ground under the truck by {drop:.3f} m")


def truck_path(r: Replay, n: int, path: np.ndarray, arc: dict[str, np.ndarray] | None) -> None:
    """``truck_tilt`` and ``truck_step`` along a truck's move, at poses no body corner moves
    more than a cell (at least 0.1 m) between, on the ground as the move starts."""
    spec = r.specs["truck"]
    assert isinstance(spec, TruckSpec)
    if _level_enough(r, spec, path, arc):
        return
    dense = dense_poses(path, max(r.terrain.resolution, 0.1), body_reach(spec), arc=arc)
    poses = dense[:, 1:4]
    grade, cross, step = truck_ground(r.sc, r.z, spec, poses)
    tilt = np.maximum(grade - spec.max_grade, cross - spec.max_cross_slope)
    k = int(np.argmax(tilt))
    if tilt[k] > ABS_TOL:
        r.flag(n, "truck_tilt", tilt[k], f"the truck stands at ({poses[k, 0]:.2f}, {poses[k, 1]:.2f}) on a grade of"
               f" {100 * grade[k]:.0f} % along and {100 * cross[k]:.0f} % across; limits {100 * spec.max_grade:.0f} %"
               f" and {100 * spec.max_cross_slope:.0f} %")
    k = int(np.argmax(step))
    if step[k] > spec.max_step + ABS_TOL:
        r.flag(n, "truck_step", step[k] - spec.max_step, f"the ground under the truck at ({poses[k, 0]:.2f}, {poses[k, 1]:.2f})"
               f" departs {step[k]:.3f} m from its plane; step {spec.max_step} m")


def _level_enough(r: Replay, spec: TruckSpec, path: np.ndarray, arc: dict[str, np.ndarray] | None) -> bool:
    """Whether the ground within the body's reach of a move's samples (and of the arcs between,
    which stay within half their length of a sample) varies so little that no pose can break
    ``truck_tilt`` or ``truck_step``. If the heights under the body span ``h``, the fitted
    plane's grade along is at most ``h·√3 / length`` and across ``h·√3 / width`` (a slope
    is at most the heights' spread over twice the points' spread along it), and the ground
    departs from the plane by at most ``h (1 + √3)``; so ``h`` at most a third of
    ``max_step``, ``max_grade × length`` and ``max_cross_slope × width`` keeps both rules."""
    t = r.terrain
    p = np.asarray(path, dtype=float).reshape(-1, 4)
    lengths = arcs(p)["length"] if arc is None and len(p) > 1 else arc["length"] if arc is not None else np.zeros(0)
    reach = body_reach(spec) + float(np.max(lengths, initial=0.0)) / 2 + t.resolution
    xmin, xmax, ymin, ymax = t.extent
    x0, x1, y0, y1 = p[:, 1].min() - reach, p[:, 1].max() + reach, p[:, 2].min() - reach, p[:, 2].max() + reach
    i0, i1 = (max(int(math.floor((v - t.origin[0]) / t.resolution)), 0) for v in (x0, x1))
    j0, j1 = (max(int(math.floor((v - t.origin[1]) / t.resolution)), 0) for v in (y0, y1))
    window = r.z[j0:j1 + 1, i0:i1 + 1]
    lo, hi = (float(window.min()), float(window.max())) if window.size else (math.inf, -math.inf)
    if x0 < xmin or x1 > xmax or y0 < ymin or y1 > ymax or not window.size:  # open ground beyond the map
        lo, hi = min(lo, r.sc.outside_level), max(hi, r.sc.outside_level)
    return hi - lo <= min(spec.max_step, spec.max_grade * spec.length, spec.max_cross_slope * spec.width) / 3
