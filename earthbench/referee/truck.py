"""The truck's rules (rules version 2, docs/referee.md): its ground traversable where it drives
(``truck_tilt``, ``truck_step``) and standing still while a bucket is emptied into it
(``truck_moving``). The geometry is public (:func:`~earthbench.rules.truck_ground`)."""

from __future__ import annotations

import math

import numpy as np

from ..motion import ABS_TOL, arcs, dense_poses
from ..plan import Dump
from ..rules import body_reach, truck_ground
from ..world import TruckSpec
from .state import Replay, Violation


def still(r: Replay, n: int, a: Dump) -> None:
    """A truck that moves while the bucket is emptied into it breaks ``truck_moving`` (both machines' dump rule)."""
    if r.timelines["truck"].moving_during(a.t_start, a.t_end):
        r.violations.append(Violation(n, "truck_moving", 1.0, "the truck moves while the bucket is emptied"))


def path(r: Replay, n: int, path: np.ndarray, arc: dict[str, np.ndarray] | None) -> None:
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
        r.violations.append(Violation(n, "truck_tilt", float(tilt[k]),
            f"the truck stands at ({poses[k, 0]:.2f}, {poses[k, 1]:.2f}) on a grade of"
            f" {100 * grade[k]:.0f} % along and {100 * cross[k]:.0f} % across; limits {100 * spec.max_grade:.0f} %"
            f" and {100 * spec.max_cross_slope:.0f} %"))
    k = int(np.argmax(step))
    if step[k] > spec.max_step + ABS_TOL:
        r.violations.append(Violation(n, "truck_step", float(step[k] - spec.max_step),
            f"the ground under the truck at ({poses[k, 0]:.2f}, {poses[k, 1]:.2f})"
            f" departs {step[k]:.3f} m from its plane; step {spec.max_step} m"))


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
