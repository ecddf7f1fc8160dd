"""A strip along the pile: the loader scrapes a straight strip with its bucket's floor-side edge
at the pile's zero contour, dumping where each charge ends into a truck that stands beside the
strip on the open floor and moves on along a line during the next charge.

Candidate strips start at points of the zero contour and run along its tangent, either way
(:func:`candidates`); the first charge must leave the wheels on traversable ground (where the pile
ends across the strip: a wall's end), the truck must find a stand for every dump on one line
beside the strip (within the dump reach and 45° of the loader's heading, clear of the loader's
body, on ground within its grade and step limits), and the charges must load what is asked
(:func:`layout`). The truck drives there once (:func:`truck_routes`); the loader's way to the
strip is the cycles' route search (:func:`approach_route`); :mod:`.schedule` times both.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from earthbench.cut import cut_along
from earthbench.motion import dense_poses, loader_dump_excess, turn_drive_turn
from earthbench.rules import body_reach, off_map_excess, rectangles_touch, truck_ground, wheel_step_excess
from earthbench.world import Pose

from ..greedy.loader import nearest_candidates
from ..loader_cycle import (MARGIN, ChargeResult, CycleBuilder, Route, Sample, charge_model, entry_for, pile_side, search_dubins,
                            search_routes, simulate_charge)


@dataclass(frozen=True)
class StripSettings:
    """The strip's geometry (m): the bucket's floor-side edge ``outside`` the contour, the back-off
    before each further charge (the row where a bucket filled is left partly cut), the truck's
    lines beside the strip (``gaps``: its centre from the strip's line is the half widths of the
    loader's body and the truck's plus a gap) and its stands ahead of the loader's pose (the
    bucket's offset plus ``shares`` of the dump's reach from the truck's centre, its loading
    radius and dump reach), contour points tried ``spacing`` apart, and how many of
    the most promising strips are timed."""

    outside: float = 0.05
    back_off: float = 0.2
    gaps: tuple[float, ...] = (0.2, 0.15, 0.25, 0.1, 0.3)
    shares: tuple[float, ...] = (0.37, 0.35, 0.4, 0.325, 0.425, 0.3, 0.45)
    spacing: float = 0.3
    timed: int = 6


@dataclass
class Strip:
    """A planned strip: the loader's actions, the truck's, the expected load and when it ends."""

    loader: list
    truck: list
    loaded: float
    t_end: float
    charges: list[ChargeResult]


@dataclass
class Layout:
    """A strip before its timing: the entry, the charges (from ``starts``), the truck's stands on
    its line (heading ``truck_yaw`` or back), the expected load, and an optimistic end time to rank
    strips by (the truck's fastest route, unchecked)."""

    entry: tuple[float, float, float]
    charges: list[ChargeResult]
    starts: list[tuple[float, float, float]]
    stands: list[tuple[float, float]]
    truck_yaw: float
    loaded: float
    estimate: float


def candidates(b: CycleBuilder, s: StripSettings) -> list[tuple[float, float, float]]:
    """Distinct first-charge entry poses of strips along the contour, nearest the truck first."""
    out: list[tuple[float, float, float]] = []
    truck = b.sc.machines.truck_pose
    for line in b.contours():
        step = max(int(round(max(s.spacing, b.spec.bucket_width / 6) / b.cfg.contour_spacing)), 1)  # a bigger bucket, sparser points
        M, n = nearest_candidates(line, b.spec.bucket_width)
        M, n = M[::step], n[::step]
        if not len(M):
            continue
        inward = n * pile_side(b.sc.terrain, b.z, M, n, b.base)[:, None]
        for k in range(len(M)):
            for sign in (1.0, -1.0):
                u = sign * np.array([-inward[k, 1], inward[k, 0]])  # along the contour
                centre = M[k] + (b.spec.bucket_width / 2 + s.outside) * inward[k]
                entry = entry_for(b.sc.terrain, b.z, b.spec, centre, u, b.base)
                if entry is not None:
                    out.append(entry)
    out.sort(key=lambda e: math.hypot(e[0] - truck.x, e[1] - truck.y))
    distinct: list[tuple[float, float, float]] = []
    for e in out:
        if all(math.hypot(e[0] - d[0], e[1] - d[1]) > 0.25 or abs(math.remainder(e[2] - d[2], 2 * math.pi)) > 0.1 for d in distinct):
            distinct.append(e)
    return distinct


def _stand(b: CycleBuilder, z: np.ndarray, pose: tuple[float, float, float], side: float, lateral: float,
           aheads: tuple[float, ...], yaw: float) -> tuple[float, float] | None:
    """The truck's centre beside the loader at ``pose`` (on ``side`` of its heading, ``lateral``
    from its line), the first of ``aheads`` that keeps the dump's reach and angle, the clearance,
    the bodies apart, the map and the truck's ground; None if none does."""
    x, y, yaw_l = pose
    u, left = (math.cos(yaw_l), math.sin(yaw_l)), (-math.sin(yaw_l), math.cos(yaw_l))
    spec, tspec = b.spec, b.sc.machines.truck
    for a in aheads:
        tx, ty = x + a * u[0] + side * lateral * left[0], y + a * u[1] + side * lateral * left[1]
        gap, off = loader_dump_excess(Pose(x, y, yaw_l), (tx, ty), spec, tspec)
        if gap > -0.01 or off > -0.005 or math.hypot(tx - x, ty - y) < spec.clearance + 0.05:
            continue
        if rectangles_touch(spec.body(x, y, yaw_l), tspec.body(tx, ty, yaw), 0.05).any():
            continue
        if off_map_excess(b.sc, tspec, np.array([[tx, ty, yaw]]))[0] > -0.02:
            continue
        grade, cross, step = truck_ground(b.sc, z, tspec, np.array([[tx, ty, yaw]]))
        if grade[0] > 0.9 * tspec.max_grade or cross[0] > 0.9 * tspec.max_cross_slope or step[0] > tspec.max_step - 0.03:
            continue
        return tx, ty
    return None


def _arc_routes(start: Pose, goal: tuple[float, float], final: float, t0: float, v: float, w: float, radius: float) -> list[list]:
    """Straight, one arc at ``radius`` and straight (either may be driven in reverse) from
    ``start`` to ``goal`` heading ``final``: the two lengths solve a 2 × 2 system per arc. The
    straights go at ``v``, the arc at ``v`` or slower, as the yaw rate ``w`` allows."""
    out = []
    v_arc = min(v, w * radius)
    delta = math.remainder(final - start.yaw, 2 * math.pi)
    u0, uf = (math.cos(start.yaw), math.sin(start.yaw)), (math.cos(final), math.sin(final))
    det = u0[0] * uf[1] - u0[1] * uf[0]
    if abs(det) < 1e-6:
        return out
    for kappa in (1.0 / radius, -1.0 / radius):
        ell = delta / kappa
        dx = (math.sin(start.yaw + delta) - math.sin(start.yaw)) / kappa
        dy = (math.cos(start.yaw) - math.cos(start.yaw + delta)) / kappa
        rx, ry = goal[0] - start.x - dx, goal[1] - start.y - dy
        l1 = (rx * uf[1] - ry * uf[0]) / det
        l2 = (u0[0] * ry - u0[1] * rx) / det
        x1, y1 = start.x + l1 * u0[0], start.y + l1 * u0[1]
        t1 = t0 + abs(l1) / v
        t2 = t1 + abs(ell) / v_arc
        pts = [(t0, start.x, start.y, start.yaw)]
        if abs(l1) > 1e-6:
            pts.append((t1, x1, y1, start.yaw))
        n = max(int(math.ceil(abs(delta) / 0.5)), 1)  # arcs of under 0.5 rad: short chords
        for k in range(1, n + 1):
            f = k / n
            th = start.yaw + f * delta
            pts.append((t1 + f * (t2 - t1), x1 + (math.sin(th) - math.sin(start.yaw)) / kappa,
                        y1 + (math.cos(start.yaw) - math.cos(th)) / kappa, th))
        if abs(l2) > 1e-6:
            pts.append((t2 + abs(l2) / v, goal[0], goal[1], final))
        else:
            pts[-1] = (pts[-1][0], goal[0], goal[1], final)
        out.append(pts)
    return out


def truck_routes(b: CycleBuilder, stand: tuple[float, float], yaw: float, t0: float, slack: float = 1.5,
                 check: bool = True, most: int = 4) -> list[list[Sample]]:
    """The truck's routes from its pose to ``stand`` heading along the strip either way (turn in
    place, straight and turn; or a turn in place of up to 90°, then straight, one arc, straight at
    radii from its speed over its yaw rate down to 2 m), the fastest first, at most ``most`` within ``slack`` seconds of it (their
    paths differ: one may keep clear of the loader where another does not). With ``check``, only
    those that stay on the map and on ground within the truck's grade and step limits."""
    tspec, start = b.sc.machines.truck, b.sc.machines.truck_pose
    if math.hypot(stand[0] - start.x, stand[1] - start.y) < 1e-6 and abs(math.remainder(yaw - start.yaw, math.pi)) < 1e-9:
        return [[(t0, start.x, start.y, start.yaw)]]
    v, w = tspec.travel_speed * MARGIN, tspec.yaw_rate * MARGIN
    routes = []
    for final in (yaw, yaw + math.pi):
        routes.append(turn_drive_turn(start, stand, t0, tspec.travel_speed, tspec.yaw_rate, final, margin=MARGIN))
        for turn in np.radians(np.arange(-90.0, 91.0, 5.0)):  # a turn in place first: a slow truck turns while it waits
            turned = Pose(start.x, start.y, start.yaw + float(turn))
            head = [(t0, start.x, start.y, start.yaw)] if abs(turn) > 1e-9 else []
            for radius in (v / w * 1.01, 6.0, 4.5, 3.0, 2.0):
                routes += [head + r for r in _arc_routes(turned, stand, final, t0 + abs(float(turn)) / w, v, w, radius)]
    routes.sort(key=lambda r: r[-1][0])
    if not check:
        return routes[:1]
    kept: list[list[Sample]] = []
    for route in routes:
        if len(kept) >= most or (kept and route[-1][0] > kept[0][-1][0] + slack):
            break
        poses = dense_poses(np.array(route, dtype=float), 0.2, body_reach(tspec))[:, 1:4]
        if off_map_excess(b.sc, tspec, poses).max() > -0.1:
            continue
        grade, cross, step = truck_ground(b.sc, b.z, tspec, poses)
        if grade.max() <= 0.9 * tspec.max_grade and cross.max() <= 0.9 * tspec.max_cross_slope and step.max() <= tspec.max_step - 0.03:
            kept.append(route)
    return kept


def approach_route(b: CycleBuilder, entry: tuple[float, float, float], away: tuple[float, float, float],
                   start: Pose | None = None, t0: float | None = None) -> Route | None:
    """The loader's fastest route from ``start`` (where it stands) at ``t0`` to the strip's entry
    (as the cycles' return leg)."""
    start = b.pose if start is None else start
    t0 = b.t if t0 is None else t0
    if math.hypot(entry[0] - start.x, entry[1] - start.y) < 1e-6 and abs(math.remainder(entry[2] - start.yaw, 2 * math.pi)) < 1e-9:
        return Route(np.array([t0]), np.array([[start.x, start.y, start.yaw]]), 0.0)
    ray = np.array([[entry[0], entry[1], -math.cos(entry[2]), -math.sin(entry[2])]])
    # the searches keep clear of a truck standing still; this one drives off (the schedule keeps
    # the loader clear of it, :mod:`.schedule`), so they see it parked at the strip's end
    sc = dataclasses.replace(b.sc, machines=dataclasses.replace(b.sc.machines, truck_pose=Pose(*away)))
    routes = [search_routes(sc, b.firm, start, t0, ray, 0.0, 12.0, 0.0, 0.0, b.opts, b.step_base),
              search_dubins(sc, b.firm, start, t0, entry, b.opts, b.step_base)]
    found = [r for r in routes if r is not None]
    return min(found, key=lambda r: r.duration) if found else None


def layout(b: CycleBuilder, entry: tuple[float, float, float], s: StripSettings) -> Layout | None:
    """The strip from ``entry``: charges along it until the target is expected, each with a truck
    stand on one line beside it (the first of ``s.gaps`` that has a stand for every dump).
    None if a charge fails before the target or no line has every stand."""
    side = _truck_side(b, entry)
    if side is None:
        return None
    charges, starts = _charges(b, entry, s)
    if not charges:
        return None
    spec = b.spec
    tspec = b.sc.machines.truck
    reach = tspec.loading_radius + spec.dump_reach
    aheads = tuple(spec.bucket_offset + reach * f for f in s.shares)
    for gap in s.gaps:
        lateral = spec.wheel_width / 2 + tspec.width / 2 + gap
        stands = []
        for ch in charges:
            stand = _stand(b, ch.z, ch.end, side, lateral, aheads, entry[2])
            if stand is None:
                break
            stands.append(stand)
        if len(stands) < len(charges):
            continue
        fastest = truck_routes(b, stands[0], entry[2], b.t, check=False)
        v = spec.travel_speed * MARGIN
        work = sum(max(spec.min_charge_time, c.penetration / (spec.penetration_speed * MARGIN)) + s.back_off / v for c in charges[1:])
        estimate = fastest[0][-1][0] + len(charges) * spec.min_dump_time + work
        return Layout(entry, charges, starts, stands, entry[2], _loaded(b, charges), estimate)
    return None


def _loaded(b: CycleBuilder, charges: list[ChargeResult]) -> float:
    return b.loaded + sum(c.delivered for c in charges) * b.yield_factor


def _full_charge(b: CycleBuilder, z: np.ndarray, firm: np.ndarray, start: tuple[float, float, float],
                 capacity: float) -> ChargeResult | None:
    """On exact ground, a charge that fills the bucket to ``capacity`` to the litre: the edge stops
    half a cell past where the public cut model fills it (the ``overfill`` rule allows a cell),
    so every bucket of the strip is a whole one (whole cells, as the cycles take, leave each a
    little short, and the target a bucket more away). None where it would take (almost) nothing
    or the wheels could not follow it."""
    spec, t = b.spec, b.sc.terrain
    x, y, yaw = start
    edge = (x + spec.bucket_offset * math.cos(yaw), y + spec.bucket_offset * math.sin(yaw))
    probe = cut_along(t, z, edge, yaw, spec.bucket_width, b.cfg.max_penetration, b.level, capacity, apply=False)
    if probe.full_at is None:
        return simulate_charge(t, z, spec, start, capacity, b.cfg.max_penetration, b.level, b.base, firm, None, b.step_base)
    pen = min(probe.full_at + t.resolution / 2, b.cfg.max_penetration)
    vol, zz, new_firm = charge_model(t, z, firm, spec, start, pen, b.level, capacity, None)
    if vol < 0.02 * spec.bucket_capacity:
        return None
    end = (x + pen * math.cos(yaw), y + pen * math.sin(yaw), yaw)
    if wheel_step_excess(t, new_firm, spec, np.array([[0.0, x, y, yaw], [1.0, end[0], end[1], yaw]]), b.step_base)[0] > -1e-3:
        return None
    return ChargeResult(pen, vol, zz, end, new_firm, vol, vol)


def _drifted(b: CycleBuilder, k: int) -> tuple[float, float]:
    """The overfill share and the step's base level for the ``k``-th charge planned without a new
    scan, as the cycles' :meth:`CycleBuilder.drift` lowers them on the realistic track."""
    if b.soil is None:
        return b.share, b.step_base
    return max(b.share - 0.025 * k, 0.6), max(b.step_base - 0.01 * k, b.base - b.ground.margin - 0.05)


def _charges(b: CycleBuilder, entry: tuple[float, float, float], s: StripSettings) -> tuple[list[ChargeResult], list]:
    """The charges along the strip from ``entry``, each after a back-off from the last one's end,
    until the target is expected or the truck may be full (:meth:`CycleBuilder.truck_took_all`;
    empty if one fails first), and where each starts."""
    spec, target = b.spec, b.sc.task.target_volume
    u = (math.cos(entry[2]), math.sin(entry[2]))
    z, firm, loaded, pose = b.z, b.firm, b.loaded, entry
    charges: list[ChargeResult] = []
    starts: list[tuple[float, float, float]] = []
    while loaded < target - 1e-9 and (not charges or b.truck_took_all(sum(c.most for c in charges))):
        if len(charges) >= b.cfg.max_cycles:
            return [], []
        start = pose if not charges else (pose[0] - s.back_off * u[0], pose[1] - s.back_off * u[1], pose[2])
        share, step_base = _drifted(b, len(charges))
        capacity = b.charge_capacity(target - loaded)
        if b.soil is None:
            ch = _full_charge(b, z, firm, start, capacity)
        else:
            public = b.public_cap(sum(c.most for c in charges), capacity, target - loaded, share)
            ch = simulate_charge(b.sc.terrain, z, spec, start, min(capacity, share * spec.bucket_capacity), b.cfg.max_penetration,
                                 b.level, b.base, firm, b.soil, step_base, public, b.load)
        if ch is None:
            return [], []
        charges.append(ch)
        starts.append(start)
        z, firm, pose = ch.z, ch.firm, ch.end
        loaded += ch.delivered * b.yield_factor
    return charges, starts


def _truck_side(b: CycleBuilder, entry: tuple[float, float, float]) -> float | None:
    """+1 if the truck's side (the floor) is left of the heading, −1 if right: the side with less
    material in the 2 m beside the strip's first metres."""
    x, y, yaw = entry
    t = b.sc.terrain
    left = (-math.sin(yaw), math.cos(yaw))
    score = {}
    for side in (1.0, -1.0):
        pts = [(x + a * math.cos(yaw) + side * d * left[0], y + a * math.sin(yaw) + side * d * left[1])
               for a in (1.2, 2.0, 3.0) for d in (1.2, 1.8, 2.4)]
        i = np.clip(((np.array(pts)[:, 0] - t.origin[0]) / t.resolution).astype(int), 0, b.z.shape[1] - 1)
        j = np.clip(((np.array(pts)[:, 1] - t.origin[1]) / t.resolution).astype(int), 0, b.z.shape[0] - 1)
        score[side] = float(np.maximum(b.z[j, i] - b.level, 0.0).sum())
    best = min(score, key=lambda k: score[k])
    return best if score[best] < score[-best] else None
