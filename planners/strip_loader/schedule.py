"""When each machine does what along a strip (:func:`timed`): the loader's approach, its charges,
back-offs and dumps, the truck's route to its first stand and its moves along its line, with the
loader kept clear of the truck (the clearance and the bodies, sampled as finely as the referee's
collision rule needs) while the truck comes."""

from __future__ import annotations

import math

import numpy as np

from earthbench.motion import dense_poses, poses_at
from earthbench.plan import Charge, Dump, Move
from earthbench.rules import bodies_touch, off_map_excess, reach_of, wheel_step_excess
from earthbench.world import Pose

from ..loader_cycle import MARGIN, RADIUS_MARGIN, ChargeResult, CycleBuilder, Route, Sample
from .strip import Layout, Strip, approach_route, truck_routes


def timed(b: CycleBuilder, lay: Layout) -> Strip | None:
    """The fastest of a few schedules that keep the loader clear of the truck, over the truck's
    routes: the loader charges at once and, while the truck comes, waits in the strip or backs
    out of it to wait beside it and drives back to dump as the truck stands (an excursion); or
    it drives part of its way and waits there until the truck has passed. None if none keeps
    clear."""
    approach = approach_route(b, lay.entry, (*lay.stands[-1], 0.0))
    if approach is None:
        return None
    outs = [None, *_excursions(b, lay)]
    firsts = truck_routes(b, lay.stands[0], lay.truck_yaw, b.t)
    best = _fastest_clear(b, lay, firsts, outs, [approach])
    # only if that fails: first step aside, out of the way of a truck that sweeps the loader's pose
    return best if best is not None else _fastest_clear(b, lay, firsts, [], _stepped_aside(b, lay))


def _fastest_clear(b: CycleBuilder, lay: Layout, firsts: list[list[Sample]], outs: list, ways: list[Route],
                   checks: int = 40) -> Strip | None:
    """The fastest clear schedule over the truck's routes ``firsts``: the first of ``ways`` at
    once with each of ``outs`` (excursions, None: none), and every way with a wait at a few of
    its samples until the truck has (about) reached its first stand; the ``checks`` fastest of
    them per truck route are checked."""
    best: Strip | None = None
    for first in firsts:
        tries = [_schedule(b, ways[0], lay, first, out) for out in outs]
        for way in ways:
            late = max(first[-1][0] - float(way.t[-1]), 0.0)  # it arrives as the truck reaches its first stand
            for wait in sorted({0, 1, *range(0, len(way.t), 3), len(way.t) - 1}):
                for delay in (late, late + 1.0, late + 2.5):
                    t = way.t + np.where(np.arange(len(way.t)) > wait, delay, 0.0)
                    tries.append(_schedule(b, Route(t, way.p, way.length), lay, first, None))
        for strip in sorted(tries, key=lambda st: st.t_end)[:checks]:  # the fastest few: the rest fail alike
            if best is not None and strip.t_end >= best.t_end:
                break
            if _clear(b, strip):
                best = strip
                break
    return best


def _stepped_aside(b: CycleBuilder, lay: Layout) -> list[Route]:
    """Approaches that first drive straight ahead or back from the loader's pose (out of the way
    of a truck that will sweep it), to wait there (the schedule's waits) and go on to the strip."""
    spec, p = b.spec, b.pose
    v = spec.travel_speed * MARGIN
    out = []
    for step in (2.0, -2.0, 3.5):
        to = Pose(p.x + step * math.cos(p.yaw), p.y + step * math.sin(p.yaw), p.yaw)
        n = max(int(math.ceil(abs(step) / 0.25)), 1)
        poses = np.column_stack([np.linspace(p.x, to.x, n + 1), np.linspace(p.y, to.y, n + 1), np.full(n + 1, p.yaw)])
        path = np.column_stack([b.t + np.arange(n + 1) * abs(step) / n / v, poses])
        dense = dense_poses(path, b.sc.terrain.resolution / 2, reach_of(spec.outline(0.0, 0.0, 0.0)))[:, 1:4]
        if np.max(off_map_excess(b.sc, spec, dense)) > -0.05 or wheel_step_excess(b.sc.terrain, b.firm, spec, path, b.step_base)[0] > -1e-3:
            continue
        rest = approach_route(b, lay.entry, (*lay.stands[-1], 0.0), to, float(path[-1, 0]))
        if rest is None:
            continue
        out.append(Route(np.concatenate([path[:, 0], rest.t[1:]]), np.vstack([poses, rest.p[1:]]), abs(step) + rest.length))
    return out


def _excursions(b: CycleBuilder, lay: Layout) -> list[np.ndarray]:
    """Ways out of the strip after the first charge (poses k × 3): back along the strip to its
    entry, then a reverse arc at the turning radius either way; the loader drives the same way
    back, forward. Only those on the map and on traversable ground after the first charge."""
    spec, ch = b.spec, lay.charges[0]
    ex, ey, yaw = ch.end
    sx, sy = lay.entry[0], lay.entry[1]
    n = max(int(math.ceil(math.hypot(ex - sx, ey - sy) / 0.25)), 1)
    straight = np.column_stack([np.linspace(ex, sx, n + 1), np.linspace(ey, sy, n + 1), np.full(n + 1, yaw)])
    radius = spec.min_turning_radius * RADIUS_MARGIN
    out = []
    for length in (3.0, 1.5, 4.5):
        for sign in (1.0, -1.0):
            kappa = sign / radius
            s = -np.linspace(0.0, length, max(int(math.ceil(length / 0.2)), 2) + 1)[1:]  # reverse
            th = yaw + kappa * s
            arc = np.column_stack([sx + (np.sin(th) - math.sin(yaw)) / kappa, sy - (np.cos(th) - math.cos(yaw)) / kappa, th])
            poses = np.vstack([straight, arc])
            path = np.column_stack([np.arange(len(poses), dtype=float), poses])
            dense = dense_poses(path, b.sc.terrain.resolution / 2, reach_of(spec.outline(0.0, 0.0, 0.0)))[:, 1:4]
            if np.max(off_map_excess(b.sc, spec, dense)) > -0.05:
                continue
            if wheel_step_excess(b.sc.terrain, ch.firm, spec, path, b.step_base)[0] > -1e-3:
                continue
            out.append(poses)
    return out


def _timed_poses(poses: np.ndarray, t0: float, b: CycleBuilder) -> list[Sample]:
    """Samples along ``poses`` from ``t0`` at the loader's speed and yaw rate (× the margin)."""
    d = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    turn = np.abs(np.diff(poses[:, 2]))
    dt = np.maximum(d / (b.spec.travel_speed * MARGIN), turn / (b.spec.yaw_rate * MARGIN))
    t = t0 + np.concatenate([[0.0], np.cumsum(dt)])
    return [(float(a), float(x), float(y), float(w)) for a, (x, y, w) in zip(t, poses)]


def _path(b: CycleBuilder, actions: list, machine: str) -> np.ndarray:
    """The samples (t, x, y, yaw) of one machine's moves and charges, from its pose at the plan's start."""
    p = b.pose if machine == "loader" else b.sc.machines.truck_pose
    rows = [(b.t, p.x, p.y, p.yaw)]
    for a in actions:
        if isinstance(a, Move):
            rows += [tuple(r) for r in a.path]
        elif isinstance(a, Charge):
            rows += [(a.t_start, *a.entry), (a.t_end, *a.end)]
    return np.array(rows, dtype=float)


def _clear(b: CycleBuilder, strip: Strip, step: float = 0.05) -> bool:
    """Whether the loader and the truck keep the clearance and their bodies apart all along
    (the collision rule's geometry, :func:`earthbench.rules.bodies_touch`, sampled finely)."""
    la, ta = _path(b, strip.loader, "loader"), _path(b, strip.truck, "truck")
    times = np.union1d(np.arange(b.t, strip.t_end + step, step), np.concatenate([la[:, 0], ta[:, 0]]))
    pa, pb = poses_at(la, times), poses_at(ta, times)
    if np.min(np.hypot(pa[:, 0] - pb[:, 0], pa[:, 1] - pb[:, 1])) < b.spec.clearance + 0.05:
        return False
    return not bodies_touch(b.spec, pa, b.sc.machines.truck, pb, 0.1).any()


def _schedule(b: CycleBuilder, approach: Route, lay: Layout, first: list[Sample], out: np.ndarray | None) -> Strip:
    """The actions of both machines with their times: the loader's approach, then per charge its
    back-off, the charge and the dump once the truck stands (after the first charge, with
    ``out``, an excursion out of the strip and back timed to end as the truck stands); the
    truck's route to the first stand and on along its line as each dump ends."""
    spec, tspec = b.spec, b.sc.machines.truck
    loader: list = []
    if len(approach.t) > 1:
        loader.append(Move("loader", tuple(approach.samples)))
    t = float(approach.t[-1])
    entry = (lay.entry[0], lay.entry[1], float(approach.p[-1, 2]))
    truck: list = [Move("truck", tuple(first))] if len(first) > 1 else []
    ready, tyaw = first[-1][0], first[-1][3]
    here = (first[-1][1], first[-1][2])
    v = spec.travel_speed * MARGIN
    for k, (ch, start, stand) in enumerate(zip(lay.charges, lay.starts, lay.stands)):
        if k > 0:
            t = _back_off(loader, lay.charges[k - 1], start, t, v)
        yaw_c = entry[2] if k == 0 else start[2]
        dur = max(spec.min_charge_time, ch.penetration / (spec.penetration_speed * MARGIN)) + 1e-6
        loader.append(Charge("loader", t, t + dur, (start[0], start[1], yaw_c), ch.penetration))
        t += dur
        if k == 0 and out is not None:
            t = _excursion(b, loader, out, t, ready)
        if k > 0:  # the truck moves on along its line as the last dump ends
            d = math.hypot(stand[0] - here[0], stand[1] - here[1])
            if d > 1e-6:
                arrive = ready + d / (tspec.travel_speed * MARGIN)
                truck.append(Move("truck", ((ready, here[0], here[1], tyaw), (arrive, stand[0], stand[1], tyaw))))
                ready, here = arrive, stand
        t = max(t, ready + 1e-6)
        loader.append(Dump("loader", t, t + spec.min_dump_time + 1e-6))
        t += spec.min_dump_time + 1e-6
        ready = max(ready, t)
    return Strip(loader, truck, lay.loaded, t, list(lay.charges))


def _back_off(loader: list, prev: ChargeResult, start: tuple[float, float, float], t: float, v: float) -> float:
    """The straight reverse from the last charge's end to the next one's start; the time after."""
    end = prev.end
    d = math.hypot(end[0] - start[0], end[1] - start[1])
    if d > 1e-9:
        loader.append(Move("loader", ((t, end[0], end[1], end[2]), (t + d / v, start[0], start[1], start[2]))))
        t += d / v
    return t


def _excursion(b: CycleBuilder, loader: list, out: np.ndarray, t: float, ready: float) -> float:
    """Out along ``out`` at once, and back so as to stand again at the charge's end as the truck
    stands (``ready``), if there is time for both; the time after."""
    go = _timed_poses(out, t, b)
    took = go[-1][0] - t
    if ready - t < 2 * took:
        return t
    back = _timed_poses(out[::-1], ready - took, b)
    loader.append(Move("loader", tuple(go)))
    loader.append(Move("loader", tuple(back)))
    return back[-1][0]
