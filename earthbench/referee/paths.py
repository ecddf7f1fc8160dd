"""The rules every machine shares along its path (docs/referee.md): a move starts where the
machine is, keeps to its speed and yaw rate, follows an arc of the motion model along its
samples' headings, and its footprint stays on the map and out of keep-out zones.

Motion between two samples is the arc of :mod:`earthbench.motion`; every rule here samples it
with :func:`~earthbench.motion.dense_poses` at half a cell (and so that no footprint corner
moves more than that between two poses), so a plan cannot pass by being sampled sparsely.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

from ..motion import ABS_TOL, RATE_TOL, arcs, dense_poses, wrap
from ..plan import Move
from ..rules import off_map_excess, reach_of
from .state import SLIP_LENGTH, Replay, Violation


def _polygons(corners: np.ndarray) -> np.ndarray:
    return shapely.polygons(np.concatenate([corners, corners[:, :1]], axis=1))

def move(r: Replay, n: int, a: Move) -> dict[str, np.ndarray]:
    """Check one move against the rules every machine shares; returns its arcs (the loop moves the machine)."""
    spec = r.specs[a.machine]
    p = np.array(a.path, dtype=float)
    here = r.pose[a.machine]
    t, x, y, yaw = p[0]
    gap = math.hypot(x - here.x, y - here.y)
    turn = abs(wrap(yaw - here.yaw))
    if gap > ABS_TOL or turn > ABS_TOL:
        r.violations.append(Violation(n, "discontinuous", float(max(gap, turn)),
            f"{a.machine} is at ({here.x:.3f}, {here.y:.3f}, yaw {here.yaw:.3f})"
            f" but the move starts at ({x:.3f}, {y:.3f}, yaw {yaw:.3f})"))
    arc = arcs(p)
    limits = (("speed", arc["length"] / arc["dt"], spec.travel_speed, "m/s", "at {:.4f} m/s along the arc"),
              ("yaw_rate", np.abs(arc["dyaw"]) / arc["dt"], spec.yaw_rate, "rad/s", "turns at {:.4f} rad/s"))
    for rule, rates, limit, unit, doing in limits:
        k = int(np.argmax(rates))
        if rates[k] > limit * (1 + RATE_TOL):
            r.violations.append(Violation(n, rule, float(rates[k] - limit),
                f"{a.machine} {doing.format(rates[k])} between samples {k} and {k + 1}; limit {limit} {unit}"))
    # the slack shrinks with the chord (no sliding sideways in short steps), down to the referee's
    # absolute tolerance: a rounding error's worth of sideways is no move at all
    slack = spec.chord_tolerance * np.minimum(1.0, arc["chord"] / SLIP_LENGTH) + ABS_TOL
    k = int(np.argmax(arc["lateral"] - slack))
    if arc["lateral"][k] > slack[k]:
        r.violations.append(Violation(n, "heading", float(arc["lateral"][k]),
            f"no arc along the headings joins samples {k} and {k + 1}: {a.machine} slides {arc['lateral'][k]:.3f}"
            f" m sideways over a {arc['chord'][k]:.3f} m chord; tolerance {slack[k]:.4f} m"))
    swept(r, n, a.machine, p, arc)
    return arc


def swept(r: Replay, n: int, machine: str, path: np.ndarray, arc: dict[str, np.ndarray] | None = None) -> None:
    """Keep-out zones and the map's edge for the machine's outline along ``path``."""
    if not r.keep_outs and r.sc.outside_open:
        return
    spec = r.specs[machine]
    reach = reach_of(spec.outline(0.0, 0.0, 0.0))
    only = None
    if len(path) > 1:  # arcs whose outline stays clear of the map's edge and every zone
        a = arcs(path) if arc is None else arc
        travel = a["length"] + np.abs(a["dyaw"]) * reach
        room = np.full(len(path), np.inf)
        if not r.sc.outside_open:
            xmin, xmax, ymin, ymax = r.terrain.extent
            room = np.minimum.reduce([path[:, 1] - xmin, xmax - path[:, 1], path[:, 2] - ymin, ymax - path[:, 2]])
        for ko in r.keep_outs:
            room = np.minimum(room, shapely.distance(ko, shapely.points(path[:, 1:3])))
        only = (room[:-1] + room[1:] - travel) / 2 <= reach + ABS_TOL
    dense = dense_poses(path, r.spacing, reach, only=only, arc=None if len(path) < 2 else a)
    if not r.sc.outside_open:
        out = off_map_excess(r.sc, spec, dense[:, 1:4])
        k = int(np.argmax(out))
        if out[k] > ABS_TOL:
            r.violations.append(Violation(n, "off_map", float(out[k]), f"{machine}'s footprint leaves the map by {out[k]:.3f} m"
                f" at ({dense[k, 1]:.2f}, {dense[k, 2]:.2f}), t={dense[k, 0]:.2f} s"))
    if r.keep_outs:
        polys = _polygons(spec.outline(dense[:, 1], dense[:, 2], dense[:, 3]))
        for ko in r.keep_outs:
            hit = shapely.intersects(polys, ko)
            if hit.any():
                k = int(np.argmax(hit))
                depth = float(shapely.area(shapely.intersection(polys[hit], ko)).max())
                r.violations.append(Violation(n, "keep_out", float(max(depth, ABS_TOL)),
                    f"{machine}'s footprint enters a keep-out zone at ({dense[k, 1]:.2f}, {dense[k, 2]:.2f}), t={dense[k, 0]:.2f} s"))

