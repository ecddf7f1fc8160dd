"""The site's rules around a dig (rules version 2, docs/referee.md): no machine under the arm or
the bucket while it digs, and the cells the truck stands on meanwhile, which the cut must not
lower (``truck_undercut``, checked by :mod:`earthbench.referee.ground` once the cut has settled).

The geometry is public (:mod:`earthbench.rules`: :func:`~earthbench.rules.arm_shadow`,
:func:`~earthbench.rules.overlap_area`, :func:`~earthbench.rules.truck_ground`,
:func:`~earthbench.rules.truck_cells`); this module only samples the machines' poses and flags.
"""

from __future__ import annotations

import math

import numpy as np

from ..motion import ABS_TOL
from ..rules import arm_shadow, body_reach, bucket_corners, overlap_area, truck_cells
from ..world import Pose, TruckSpec
from .state import Replay, Violation

#: The truck's cells and their heights before a cut (what ``truck_undercut`` compares with after it).
Stands = tuple[tuple[np.ndarray, np.ndarray], np.ndarray]

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


def around_dig(r: Replay, n: int, digger: str, contact: tuple[float, float], heading: float, width: float, length: float,
               base: Pose | None, t0: float, t1: float) -> Stands:
    """Both checks before a dig's (or charge's) cut: :func:`near_dig`, then :func:`truck_stands`."""
    near_dig(r, n, digger, contact, heading, width, length, base, t0, t1)
    return truck_stands(r, t0, t1, contact, heading, width, length)


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
                r.violations.append(Violation(n, "dig_under_machine", float(under[k]),
                    f"{under[k]:.3f} m² of the bucket's footprint lies under {what}"
                    f" at ({poses[k, 0]:.2f}, {poses[k, 1]:.2f})"))
                continue
        if base is None or machine == digger or _apart(poses, (base.x, base.y), mid, room):
            continue
        shadow = arm_shadow(base, contact, heading, width, length) if shadow is None else shadow
        over = overlap_area(shadow, spec, poses)
        k = int(np.argmax(over))
        if over[k] > ABS_TOL:
            r.violations.append(Violation(n, "arm_over_machine", float(over[k]),
                f"{what} stands {over[k]:.3f} m² into the arm's ground shadow"
                f" at ({poses[k, 0]:.2f}, {poses[k, 1]:.2f}) while it digs"))


def truck_stands(r: Replay, t0: float, t1: float, contact: tuple[float, float], heading: float, width: float,
                 length: float) -> Stands:
    """The cells the truck stands on at any time from ``t0`` to ``t1`` and their heights now
    (before the cut along ``contact``, ``heading``, ``width``, ``length``, for ``truck_undercut``).
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
