"""Clearance between machines (the ``collision`` rule): the excavator's or the loader's distance
to the truck and their footprints, checked along both swept paths at once, after the replay,
over the whole of both timelines (docs/referee.md)."""

from __future__ import annotations

import numpy as np

from ..motion import ABS_TOL
from ..plan import Charge, Move
from ..rules import bodies_touch, reach_of
from ..world import TruckSpec
from .state import Replay, Violation


def collisions(r: Replay) -> None:
    for machine in ("excavator", "loader"):
        if machine in r.timelines:
            _collision(r, machine)

def _collision(r: Replay, machine: str) -> None:
    """Centre distance and footprint contact along both swept paths at once.

    Between two consecutive sample times of either machine each one drives a piece of one
    arc at constant speed and yaw rate, so the distance between them cannot dip below
    ``(d0 + d1 − S) / 2`` for the distances ``d0, d1`` at the ends and ``S`` the sum of
    what both centres (and body corners, by the turn) travel. Intervals whose bound stays
    above the clearance and the bodies' reach are clear; the others are sampled so that
    neither machine moves more than half a cell (at least 2.5 cm) between two times.
    """
    me, truck = r.timelines[machine], r.timelines["truck"]
    spec, tspec = r.specs[machine], r.specs["truck"]
    assert not isinstance(spec, TruckSpec)  # the excavator or the loader, each with its clearance to the truck
    reach_a, reach_b = reach_of(spec.body(0.0, 0.0, 0.0)), reach_of(tspec.body(0.0, 0.0, 0.0))
    step = max(r.spacing, 0.025)
    times = np.unique(np.concatenate([me.path[:, 0], truck.path[:, 0]]))
    pa, pb = me.poses(times), truck.poses(times)
    d = np.hypot(pa[:, 0] - pb[:, 0], pa[:, 1] - pb[:, 1])
    if len(times) > 1:
        mid = (times[:-1] + times[1:]) / 2
        dt = np.diff(times)
        S = (me.rates(mid, reach_a) + truck.rates(mid, reach_b)) * dt
        near = (d[:-1] + d[1:] - S) / 2 <= max(spec.clearance, reach_a + reach_b) + ABS_TOL
        if near.any():
            n = np.maximum(np.ceil(S[near] / step).astype(int), 1)
            at = np.repeat(np.nonzero(near)[0], n)
            f = (np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n, n)
            extra = times[at] + f * dt[at]
            times = np.concatenate([times, extra])
            pa, pb = np.vstack([pa, me.poses(extra)]), np.vstack([pb, truck.poses(extra)])
            d = np.hypot(pa[:, 0] - pb[:, 0], pa[:, 1] - pb[:, 1])
    clearance = spec.clearance
    bad = d < clearance - ABS_TOL
    k = int(np.argmin(d))
    if bad.any():
        r.violations.append(Violation(_active(r, times[k]), "collision", float(clearance - d[k]),
            f"{machine} and truck {d[k]:.3f} m apart at t={times[k]:.3f} s; clearance {clearance} m"))
        return
    touch = bodies_touch(spec, pa, tspec, pb)
    if touch.any():
        t = times[int(np.argmax(touch))]
        r.violations.append(Violation(_active(r, t), "collision", 1.0,
            f"{machine}'s and the truck's footprints touch at t={t:.3f} s"))

def _active(r: Replay, t: float) -> int | None:
    who = [
        n for n, a in enumerate(r.plan.actions) if isinstance(a, (Move, Charge)) and a.t_start - ABS_TOL <= t <= a.t_end + ABS_TOL
    ]
    return who[0] if who else None

