"""Where the machines and the bucket are during a plan: each machine's paths (:func:`machine_paths`,
:func:`pose_at`) and the bucket's path and rectangle as the referee cuts it (:func:`bucket_path`,
:func:`bucket_footprint`), for the viewer and the figures."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...cut import footprint
from ...plan import Charge, Dig, Move, Plan
from ...world import Scenario


def machine_paths(scenario: Scenario, plan: Plan) -> dict[str, list[np.ndarray]]:
    """Per machine, its moves (and a loader's charges) in time order, each an array of ``(t, x, y, yaw)`` rows.

    Kept apart, not joined: a move that starts away from where the machine stands is a jump,
    never an ordinary piece of path.
    """
    out: dict[str, list[np.ndarray]] = {mid: [] for mid in scenario.machines.ids}
    for a in sorted(plan.actions, key=lambda a: a.t_start):
        if a.machine not in out:
            continue
        if isinstance(a, Move):
            out[a.machine].append(np.array(a.path, dtype=float))
        elif isinstance(a, Charge):
            (x, y, yaw), (ex, ey, _) = a.entry, a.end
            out[a.machine].append(np.array([[a.t_start, x, y, yaw], [a.t_end, ex, ey, yaw]]))
    return out


def pose_at(start: tuple[float, float, float], segments: list[np.ndarray], t: float) -> tuple[float, float, float]:
    """Where a machine is at time ``t``: on the move running then (linear between samples), else where the last one ended."""
    p = start
    for seg in segments:
        if seg[0, 0] > t:
            break
        if seg[-1, 0] > t:
            return tuple(float(np.interp(t, seg[:, 0], seg[:, k])) for k in (1, 2, 3))  # type: ignore[return-value]
        p = (float(seg[-1, 1]), float(seg[-1, 2]), float(seg[-1, 3]))
    return p

def bucket_path(scenario: Scenario, a: Any) -> tuple[tuple[float, float], float, float, float] | None:
    """The bucket's path of a dig or a charge as the referee cuts it: start of the cutting edge,
    heading, width and length (``None`` for other actions, or without the machine)."""
    m = scenario.machines
    if isinstance(a, Dig) and m.excavator is not None:
        return a.contact, a.heading, m.excavator.bucket_width, a.drag_length
    if isinstance(a, Charge) and m.loader is not None:
        (x, y, yaw), spec = a.entry, m.loader
        return (x + spec.bucket_offset * math.cos(yaw), y + spec.bucket_offset * math.sin(yaw)), yaw, spec.bucket_width, a.penetration
    return None


def bucket_footprint(scenario: Scenario, a: Any) -> list[tuple[float, float]] | None:
    """The referee's bucket rectangle of a dig or a charge (``None`` for other actions, or without the machine)."""
    path = bucket_path(scenario, a)
    return None if path is None else list(footprint(*path).exterior.coords)
