"""Small motion primitives that planners share to write moves the referee accepts.

A machine is a unicycle: it turns in place or drives straight along its heading (forward or in
reverse). ``turn_drive_turn`` joins a start pose to a goal by the cheapest such sequence, at a
fraction ``margin`` of the limits so that floating-point noise never reads as a violation.
Excavator swing times are given here too, with the same definition the referee uses.
"""

from __future__ import annotations

import math

from .world import ExcavatorSpec, Pose

Sample = tuple[float, float, float, float]
MARGIN = 0.999


def wrap(angle: float) -> float:
    """Angle wrapped to [-π, π)."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def turn_drive_turn(
    start: Pose,
    goal: tuple[float, float],
    t0: float,
    speed: float,
    yaw_rate: float,
    final_yaw: float | None = None,
    *,
    allow_reverse: bool = True,
    margin: float = MARGIN,
) -> list[Sample]:
    """Samples ``(t, x, y, yaw)`` from ``start`` at ``t0`` to ``goal`` (and ``final_yaw``).

    Turns in place toward the goal (or away from it, to reverse, when that turn is shorter),
    drives straight, then turns to ``final_yaw`` if given. Samples with no change are dropped;
    a move of nothing returns just the start sample.
    """
    v, w = speed * margin, yaw_rate * margin
    samples: list[Sample] = [(t0, start.x, start.y, start.yaw)]
    t, yaw = t0, start.yaw
    dx, dy = goal[0] - start.x, goal[1] - start.y
    dist = math.hypot(dx, dy)
    if dist > 1e-9:
        bearing = math.atan2(dy, dx)
        fwd = wrap(bearing - yaw)
        rev = wrap(bearing + math.pi - yaw)
        delta = rev if allow_reverse and abs(rev) < abs(fwd) else fwd
        if abs(delta) > 1e-12:
            t += abs(delta) / w
            yaw += delta
            samples.append((t, start.x, start.y, yaw))
        t += dist / v
        samples.append((t, goal[0], goal[1], yaw))
    if final_yaw is not None:
        delta = wrap(final_yaw - yaw)
        if abs(delta) > 1e-12:
            t += abs(delta) / w
            yaw += delta
            samples.append((t, samples[-1][1], samples[-1][2], yaw))
    return samples


def travel_time(start: Pose, goal: tuple[float, float], speed: float, yaw_rate: float, final_yaw: float | None = None) -> float:
    """Duration of :func:`turn_drive_turn` for the same arguments."""
    path = turn_drive_turn(start, goal, 0.0, speed, yaw_rate, final_yaw)
    return path[-1][0]


def swing_time(base: Pose, turn: float, target: tuple[float, float], spec: ExcavatorSpec) -> float:
    """Seconds to swing the upper body (``turn`` relative to the base yaw) toward ``target``."""
    bearing = math.atan2(target[1] - base.y, target[0] - base.x)
    return abs(wrap(bearing - (base.yaw + turn))) / spec.swing_rate
