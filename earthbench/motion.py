"""The motion model the referee judges by, and the motion helpers planners share with it.

**Between two move samples** ``(t0, p0, ψ0)`` and ``(t1, p1, ψ1)`` a machine drives the
constant-curvature arc from ``p0`` to ``p1`` that turns its heading by ``Δψ = wrap(ψ1 − ψ0)``
(a straight line when ``Δψ = 0``, a turn in place when ``p0 = p1``; at ``|Δψ| = π`` the arc
that starts forward). Its length is ``L = c · (Δψ/2) / sin(Δψ/2)`` for the chord ``c``, its
radius ``L / |Δψ|``, and the machine moves along it at constant speed ``L / (t1 − t0)`` and yaw
rate ``|Δψ| / (t1 − t0)``. The arc meets the samples' headings only if the chord lies along
the mean heading ``ψ0 + Δψ/2`` (forward or reverse); the referee's ``heading`` rule bounds
that lateral offset by the spec's ``chord_tolerance``. :func:`dense_poses` samples this curve
as finely as a caller needs; every referee rule that looks at a path uses it.

``turn_drive_turn`` joins a start pose to a goal by turn in place, straight, turn (each piece
an arc of this model), at a fraction ``margin`` of the limits so that floating-point noise
never reads as a violation. The minimum durations and reaches of digs and dumps are defined
here once, for the referee and planners alike.
"""

from __future__ import annotations

import bisect
import math

import numpy as np

from .plan import Move
from .world import ExcavatorSpec, LoaderSpec, Pose, TruckSpec

Sample = tuple[float, float, float, float]
MARGIN = 0.999

#: The referee's one tolerance on durations, distances, depths and volumes (s, m, m³): exact
#: arithmetic by a planner is never punished, while nothing material is rounded in its favour.
ABS_TOL = 1e-6
#: Relative tolerance on speeds and rates.
RATE_TOL = 1e-3
#: A loader dumps only into a truck whose centre lies within this angle of its heading.
LOADER_DUMP_HALF_ANGLE = math.pi / 4


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


def swing_time(base: Pose, turn: float, target: tuple[float, float], spec: ExcavatorSpec) -> float:
    """Seconds to swing the upper body (``turn`` relative to the base yaw) toward ``target``."""
    bearing = math.atan2(target[1] - base.y, target[0] - base.x)
    return abs(wrap(bearing - (base.yaw + turn))) / spec.swing_rate


def min_dig_time(base: Pose, turn: float, contact: tuple[float, float], spec: ExcavatorSpec) -> float:
    """Shortest valid dig: the swing to the contact's bearing plus the minimum stroke time."""
    return swing_time(base, turn, contact, spec) + spec.min_stroke_time


def min_dump_time(base: Pose, turn: float, truck: tuple[float, float], spec: ExcavatorSpec) -> float:
    """Shortest valid excavator dump: the swing to the truck's centre plus the minimum dump time."""
    return swing_time(base, turn, truck, spec) + spec.min_dump_time


def dump_reach_excess(base: Pose, truck: tuple[float, float], spec: ExcavatorSpec, truck_spec: TruckSpec) -> float:
    """How far (m) the truck's loading circle lies outside the reach annulus (≤ 0: in reach)."""
    d = math.hypot(truck[0] - base.x, truck[1] - base.y)
    r = truck_spec.loading_radius
    return max(d - r - spec.reach_max, spec.reach_min - d - r)


def loader_dump_excess(pose: Pose, truck: tuple[float, float], spec: LoaderSpec, truck_spec: TruckSpec) -> tuple[float, float]:
    """For a loader dump: how far (m) the cutting edge lies beyond ``dump_reach`` of the truck's
    loading circle, and how far (rad) the truck's centre lies beyond 45° of the heading
    (each ≤ 0: allowed)."""
    ex, ey = pose.x + spec.bucket_offset * math.cos(pose.yaw), pose.y + spec.bucket_offset * math.sin(pose.yaw)
    gap = math.hypot(truck[0] - ex, truck[1] - ey) - truck_spec.loading_radius
    off = abs(wrap(math.atan2(truck[1] - pose.y, truck[0] - pose.x) - pose.yaw))
    return gap - spec.dump_reach, off - LOADER_DUMP_HALF_ANGLE


# -- the motion model between samples -----------------------------------------------------------

def arcs(path: np.ndarray) -> dict[str, np.ndarray]:
    """The arc of the motion model between each two samples of ``path[k, 4]`` (t, x, y, yaw).

    Returns arrays of length ``k − 1``: ``dt``, ``chord``, ``dyaw`` (the heading change),
    ``length`` (arc length), ``radius`` (``inf`` for a straight, 0 for a turn in place),
    ``lateral`` (the chord's offset from the mean heading: 0 when the arc fits both headings)
    and ``theta0`` (direction of travel at the start of the arc).
    """
    p = np.asarray(path, dtype=float).reshape(-1, 4)
    d = p[1:] - p[:-1]
    dt, dx, dy = d[:, 0], d[:, 1], d[:, 2]
    chord = np.hypot(dx, dy)
    dyaw = (d[:, 3] + math.pi) % (2 * math.pi) - math.pi
    direction = np.arctan2(dy, dx)
    # at |Δψ| = π both turning senses fit: take the one whose arc starts forward
    half_turn = np.abs(np.abs(dyaw) - math.pi) < 1e-9
    fwd = np.cos(direction - (p[:-1, 3] + dyaw / 2)) >= 0
    dyaw = np.where(half_turn & ~fwd, -dyaw, dyaw)
    half = np.abs(dyaw) / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        stretch = np.where(half > 1e-12, half / np.sin(half), 1.0)
        length = chord * stretch
        radius = np.where(half > 1e-12, length / (2 * half), np.inf)
    mid = p[:-1, 3] + dyaw / 2
    lateral = np.abs(dx * np.sin(mid) - dy * np.cos(mid))
    return {"dt": dt, "chord": chord, "dyaw": dyaw, "length": length, "radius": radius, "lateral": lateral, "theta0": direction - dyaw / 2}


def sample_yaws(path: np.ndarray, arc: dict[str, np.ndarray]) -> np.ndarray:
    """The heading at each sample of ``path[k, 4]``, unwrapped along the path (the arcs' turns
    added up) but snapped to the sample's own yaw plus whole turns: summing thousands of turns
    must not leave a machine at rest a rounding error off the heading its plan wrote."""
    p = np.asarray(path, dtype=float).reshape(-1, 4)
    summed = p[0, 3] + np.concatenate([[0.0], np.cumsum(arc["dyaw"])])
    return p[:, 3] + np.round((summed - p[:, 3]) / (2 * math.pi)) * (2 * math.pi)


def _on_arc(p0: np.ndarray, theta0: np.ndarray, dyaw: np.ndarray, length: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions at fraction ``f`` along arcs from ``p0[k, 2]`` (vectorised over k)."""
    small = np.abs(dyaw) < 1e-9
    safe = np.where(small, 1.0, dyaw)
    th = theta0 + f * dyaw
    ax = np.where(small, length * f * np.cos(theta0 + f * dyaw / 2), length / safe * (np.sin(th) - np.sin(theta0)))
    ay = np.where(small, length * f * np.sin(theta0 + f * dyaw / 2), length / safe * (np.cos(theta0) - np.cos(th)))
    return p0[:, 0] + ax, p0[:, 1] + ay


def dense_poses(
    path: np.ndarray, spacing: float, reach: float = 0.0, only: np.ndarray | None = None, arc: dict[str, np.ndarray] | None = None
) -> np.ndarray:
    """Poses ``[m, 4]`` (t, x, y, yaw) along the motion model's curve through ``path[k, 4]``.

    Consecutive poses are at most ``spacing`` apart along the curve, and a point ``reach``
    metres from the pose (a footprint's corner) moves at most ``spacing`` between them; every
    sample of ``path`` is among the poses. Yaw is continuous (unwrapped). With ``only`` (one
    flag per arc) the arcs not flagged contribute just their first sample. ``arc`` is
    ``arcs(path)`` when the caller already has it.
    """
    p = np.asarray(path, dtype=float).reshape(-1, 4)
    if len(p) < 2:
        return p.copy()
    a = arcs(p) if arc is None else arc
    n = np.maximum(np.ceil(np.maximum(a["length"], np.abs(a["dyaw"]) * reach) / spacing).astype(int), 1)
    if only is not None:
        n = np.where(only, n, 1)
    seg = np.repeat(np.arange(len(n)), n)
    f = (np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)) / n[seg]
    yaw0 = sample_yaws(p, a)
    x, y = _on_arc(p[seg, 1:3], a["theta0"][seg], a["dyaw"][seg], a["length"][seg], f)
    out = np.stack([p[seg, 0] + f * a["dt"][seg], x, y, yaw0[seg] + f * a["dyaw"][seg]], axis=1)
    last = np.array([[p[-1, 0], p[-1, 1], p[-1, 2], yaw0[-1]]])
    return np.vstack([out, last])


def poses_at(path: np.ndarray, times: np.ndarray, arc: dict[str, np.ndarray] | None = None) -> np.ndarray:
    """Poses ``[m, 3]`` (x, y, yaw) at ``times`` on the motion model's curve through ``path``;
    before the first sample the machine is at the first, after the last exactly at the last
    (not at the arc's end, which rounding can leave 1e-15 m off: the referee judges a station
    where the plan put it). ``arc`` is ``arcs(path)`` when the caller already has it."""
    p = np.asarray(path, dtype=float).reshape(-1, 4)
    times = np.asarray(times, dtype=float)
    if len(p) < 2:
        return np.repeat(p[:1, 1:4], len(times), axis=0)
    a = arcs(p) if arc is None else arc
    yaw0 = sample_yaws(p, a)
    k = np.clip(np.searchsorted(p[:, 0], times, side="right") - 1, 0, len(p) - 2)
    f = np.clip((times - p[k, 0]) / np.where(a["dt"][k] > 0, a["dt"][k], 1.0), 0.0, 1.0)
    x, y = _on_arc(p[k, 1:3], a["theta0"][k], a["dyaw"][k], a["length"][k], f)
    out = np.stack([x, y, yaw0[k] + f * a["dyaw"][k]], axis=1)
    out[times >= p[-1, 0]] = (p[-1, 1], p[-1, 2], yaw0[-1])
    return out


class Timeline:
    """A machine's samples over time (its start, then every move and charge), on the motion model:
    where it is at any time, how fast its body moves, whether it moves in a span (the referee's
    clock for every rule that looks at two machines at once, docs/DESIGN.md §5)."""

    def __init__(self, start: Pose, moves: list[Move]):
        samples = [(0.0, start.x, start.y, start.yaw)]
        for m in sorted(moves, key=lambda m: m.t_start):
            samples.extend(m.path)
        self.path = np.array(samples, dtype=float)
        self.arc = arcs(self.path) if len(self.path) > 1 else None
        self.times = self.path[:, 0].tolist()
        self.yaw0 = sample_yaws(self.path, self.arc).tolist() if self.arc is not None else []
        self.moves = [(m.t_start, m.t_end) for m in moves]
        self._last: tuple[float, Pose] | None = None  # the last answer of :meth:`pose`: rules ask for one time in turn

    def poses(self, times: np.ndarray) -> np.ndarray:
        return poses_at(self.path, times, self.arc)

    def rates(self, times: np.ndarray, reach: float) -> np.ndarray:
        """Speed of the centre plus yaw rate × ``reach`` (a body corner) at ``times``."""
        if self.arc is None:
            return np.zeros(len(times))
        k = np.clip(np.searchsorted(self.path[:, 0], times, side="right") - 1, 0, len(self.path) - 2)
        dt = self.arc["dt"][k]
        with np.errstate(divide="ignore", invalid="ignore"):
            v = np.where(dt > 0, (self.arc["length"][k] + np.abs(self.arc["dyaw"][k]) * reach) / dt, 0.0)
        inside = (times >= self.path[0, 0]) & (times <= self.path[-1, 0])
        return np.where(inside, v, 0.0)

    def pose(self, t: float) -> Pose:
        """The pose at ``t`` (:func:`poses_at` for one time, in plain floats)."""
        if self._last is not None and self._last[0] == t:
            return self._last[1]
        pose = self._pose(t)
        self._last = (t, pose)
        return pose

    def _pose(self, t: float) -> Pose:
        p, a = self.path, self.arc
        if a is None or t <= p[0, 0]:
            return Pose(float(p[0, 1]), float(p[0, 2]), float(p[0, 3]))
        if t >= self.times[-1]:
            return Pose(float(p[-1, 1]), float(p[-1, 2]), self.yaw0[-1])
        k = min(bisect.bisect_right(self.times, t) - 1, len(p) - 2)
        dt = float(a["dt"][k])
        f = min(max((t - p[k, 0]) / dt, 0.0), 1.0) if dt > 0 else 1.0
        dyaw, th0, length = float(a["dyaw"][k]), float(a["theta0"][k]), float(a["length"][k])
        if abs(dyaw) < 1e-9:
            x = p[k, 1] + length * f * math.cos(th0 + f * dyaw / 2)
            y = p[k, 2] + length * f * math.sin(th0 + f * dyaw / 2)
        else:
            x = p[k, 1] + length / dyaw * (math.sin(th0 + f * dyaw) - math.sin(th0))
            y = p[k, 2] + length / dyaw * (math.cos(th0) - math.cos(th0 + f * dyaw))
        return Pose(float(x), float(y), float(self.yaw0[k] + f * dyaw))

    def moving_during(self, t0: float, t1: float) -> bool:
        return any(a < t1 - ABS_TOL and b > t0 + ABS_TOL for a, b in self.moves)
