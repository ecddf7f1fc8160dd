"""Car-like routes at or above the minimum turning radius (:func:`search_routes`: reverse, two
arcs, a straight; :func:`search_dubins`: back out, then a forward Dubins path), checked with the
referee's own functions; the rays along which the loader may dump (:func:`dump_rays`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from earthbench.motion import dense_poses
from earthbench.rules import bodies_touch, cell_heights, off_map_excess, reach_of, step_excess, wheel_step_excess
from earthbench.world import LoaderSpec, Pose, Scenario


MARGIN = 0.995
RADIUS_MARGIN = 1.002
Sample = tuple[float, float, float, float]


@dataclass(frozen=True)
class RouteOptions:
    """The grid :func:`search_routes` solves over (lengths in m, curvature factors of 1/R_min)."""

    reverse_straights: tuple[float, ...] = (0.0, 0.5, 1.0, 2.0, 3.0)
    reverse_curvatures: tuple[float, ...] = (1.0, 0.7, 0.45, 0.25)
    reverse_lengths: tuple[float, ...] = (0.0, 1.0, 2.0, 3.0, 4.5, 6.0, 8.0)
    max_checked: int = 25


def _arc(x: float, y: float, yaw: float, kappa: float, length: float, n: int) -> np.ndarray:
    """n+1 poses (x, y, yaw) along an arc of signed ``length`` (negative: reverse)."""
    s = np.linspace(0.0, length, n + 1)
    if abs(kappa) < 1e-12:
        return np.stack([x + s * math.cos(yaw), y + s * math.sin(yaw), np.full_like(s, yaw)], axis=1)
    th = yaw + kappa * s
    return np.stack([x + (np.sin(th) - math.sin(yaw)) / kappa, y - (np.cos(th) - math.cos(yaw)) / kappa, th], axis=1)


def _speed(spec: LoaderSpec, kappa: float) -> float:
    v = spec.travel_speed
    if abs(kappa) > 1e-12:
        v = min(v, spec.yaw_rate / abs(kappa))
    return v * MARGIN


@dataclass
class Route:
    """Samples of a move as arrays: times ``t`` (k) and poses ``p`` (k × 3: x, y, yaw)."""

    t: np.ndarray
    p: np.ndarray
    length: float

    @property
    def samples(self) -> list[Sample]:
        return [(float(t), float(x), float(y), float(w)) for t, (x, y, w) in zip(self.t, self.p)]

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    @property
    def end(self) -> Pose:
        x, y, yaw = self.p[-1]
        return Pose(float(x), float(y), float(yaw))

    def shifted(self, dt: float) -> Route:
        return Route(self.t + dt, self.p, self.length)


def _build(start: Pose, t0: float, spec: LoaderSpec, segs: list[tuple[float, float]], end_xy: tuple[float, float], end_yaw: float) -> Route:
    """Samples for segments ``(kappa, signed length)`` from ``start``; the last sample is pinned to
    ``end_xy``/``end_yaw`` (they agree with the arcs up to rounding)."""
    ts, ps = [np.array([t0])], [np.array([[start.x, start.y, start.yaw]])]
    x, y, yaw, t, total = start.x, start.y, start.yaw, t0, 0.0
    for kappa, length in segs:
        if abs(length) < 1e-9:
            continue
        n = max(1, int(math.ceil(abs(length) / 0.25)), int(math.ceil(abs(kappa * length) / 0.08)))
        poses = _arc(x, y, yaw, kappa, length, n)[1:]
        dt = abs(length) / n / _speed(spec, kappa)
        ts.append(t + dt * np.arange(1, n + 1))
        ps.append(poses)
        t += n * dt
        x, y, yaw = (float(v) for v in poses[-1])
        total += abs(length)
    T, P = np.concatenate(ts), np.concatenate(ps)
    if len(T) > 1:
        turns = round((P[-1, 2] - end_yaw) / (2 * math.pi))
        P[-1] = (end_xy[0], end_xy[1], end_yaw + 2 * math.pi * turns)
    return Route(T, P, total)


def _reverse_part(start: Pose, opts: RouteOptions, rmin: float, arcs: int) -> tuple[np.ndarray, ...]:
    """End poses of every reverse part on the grid: straight ``S``, then ``arcs`` reverse arcs
    (curvature ``K``, length ``L`` each). Returns S, K (n × arcs), L (n × arcs), qx, qy, thq."""
    kap = np.array([s * c / rmin for c in opts.reverse_curvatures for s in (1.0, -1.0)])
    lens = np.array(opts.reverse_lengths)
    grids = np.meshgrid(np.array(opts.reverse_straights), *([kap, lens] * arcs), indexing="ij")
    flat = [g.ravel() for g in grids]
    S, K, L = flat[0], np.stack(flat[1::2], axis=1), np.stack(flat[2::2], axis=1)
    keep = np.all((L > 0) | (K == kap[0]), axis=1)  # a zero-length arc needs one curvature only
    if arcs > 1:
        keep &= (L[:, 0] > 0) | (L[:, 1] == 0)
    S, K, L = S[keep], K[keep], L[keep]
    x = start.x - S * math.cos(start.yaw)
    y = start.y - S * math.sin(start.yaw)
    th = np.full(len(S), start.yaw)
    for a in range(arcs):
        th1 = th - K[:, a] * L[:, a]
        x = x + (np.sin(th1) - np.sin(th)) / K[:, a]
        y = y - (np.cos(th1) - np.cos(th)) / K[:, a]
        th = th1
    return S, K, L, x, y, th


def search_routes(
    scenario: Scenario,
    z: np.ndarray,
    start: Pose,
    t0: float,
    rays: np.ndarray,
    lam_lo: float,
    lam_hi: float,
    stop_hi: float,
    lam_final: float,
    opts: RouteOptions,
    base: float,
    reverse_arcs: int = 1,
) -> Route | None:
    """The fastest feasible route from ``start`` to a target ray.

    ``rays`` is (m × 4): base point ``(bx, by)`` and unit direction ``(ux, uy)``; the loader ends
    at ``B + λ u`` heading ``−u``. The forward arc meets the ray at ``λ ∈ [lam_lo, lam_hi]``; the
    loader stops there if ``λ ≤ stop_hi``, else drives straight on to ``λ = lam_final``.
    Structure: reverse straight, ``reverse_arcs`` reverse arcs, (cusp), forward arc, forward
    straight — with one reverse arc, the two arcs of Singh and Cannon's constraint.
    """
    spec: LoaderSpec = scenario.machines.loader
    rmin = spec.min_turning_radius * RADIUS_MARGIN
    S0, K0, L0, qx0, qy0, thq0 = _reverse_part(start, opts, rmin, reverse_arcs)
    ci, ri = np.meshgrid(np.arange(len(S0)), np.arange(len(rays)), indexing="ij")
    ci, ri = ci.ravel(), ri.ravel()
    S, K, L, qx, qy, thq = S0[ci], K0[ci], L0[ci], qx0[ci], qy0[ci], thq0[ci]
    B, U = rays[ri, :2], rays[ri, 2:]
    th_e = np.arctan2(-U[:, 1], -U[:, 0])
    delta = (th_e - thq + math.pi) % (2 * math.pi) - math.pi
    e = np.stack([np.cos(thq + delta / 2), np.sin(thq + delta / 2)], axis=1)
    dx, dy = B[:, 0] - qx, B[:, 1] - qy
    det = -e[:, 0] * U[:, 1] + U[:, 0] * e[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = (-dx * U[:, 1] + U[:, 0] * dy) / det
        lam = (e[:, 0] * dy - e[:, 1] * dx) / det
        sin_half = np.sin(np.abs(delta) / 2)
        radius = np.where(sin_half > 1e-9, rho / (2 * sin_half), np.inf)
        arc_len = np.where(sin_half > 1e-9, radius * np.abs(delta), rho)
    ok = (np.abs(det) > 1e-9) & (rho > 1e-6) & (lam >= lam_lo) & (lam <= lam_hi) & (radius >= rmin)
    if not ok.any():
        return None
    idx = np.nonzero(ok)[0]
    # routes whose cusp or forward arc stands on the pile cannot be clear: pass them over
    # before the fastest few are checked in full (a route's order among the rest is kept)
    kf_s = np.where(np.isfinite(radius[idx]), np.sign(delta[idx]) / radius[idx], 0.0)
    pts = [np.stack([qx[idx], qy[idx]], axis=1)] + [_on_arc(qx[idx], qy[idx], thq[idx], kf_s, arc_len[idx] * f) for f in (0.25, 0.5, 0.75)]
    idx = idx[_standable(scenario, z, pts, base)]
    if idx.size == 0:
        return None
    final = np.where(lam[idx] <= stop_hi, lam[idx], lam_final)
    kf = np.where(np.isfinite(radius[idx]), 1.0 / radius[idx], 0.0)
    v = spec.travel_speed * MARGIN
    v_rev = np.minimum(spec.travel_speed, spec.yaw_rate / np.maximum(np.abs(K[idx]), 1e-12)) * MARGIN
    v_fwd = np.minimum(spec.travel_speed, spec.yaw_rate / np.maximum(kf, 1e-12)) * MARGIN
    dur = S[idx] / v + (L[idx] / v_rev).sum(axis=1) + arc_len[idx] / v_fwd + (lam[idx] - final) / v
    order = idx[np.argsort(dur, kind="stable")]
    for k in order[: opts.max_checked]:
        f = lam[k] if lam[k] <= stop_hi else lam_final
        end_xy = (B[k, 0] + f * U[k, 0], B[k, 1] + f * U[k, 1])
        kf_k = (1.0 / radius[k] if np.isfinite(radius[k]) else 0.0) * math.copysign(1.0, delta[k])
        segs = [(0.0, -S[k])] + [(K[k, a], -L[k, a]) for a in range(reverse_arcs)] + [(kf_k, arc_len[k]), (0.0, lam[k] - f)]
        route = _build(start, t0, spec, segs, end_xy, float(th_e[k]))
        if _clear(scenario, z, route, base):
            return route
    return None


def _on_arc(x: np.ndarray, y: np.ndarray, th: np.ndarray, kappa: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Points ``s`` along arcs of curvature ``kappa`` from ``(x, y)`` heading ``th`` (vectorised)."""
    straight = np.abs(kappa) < 1e-12
    k = np.where(straight, 1.0, kappa)
    px = np.where(straight, x + s * np.cos(th), x + (np.sin(th + k * s) - np.sin(th)) / k)
    py = np.where(straight, y + s * np.sin(th), y - (np.cos(th + k * s) - np.cos(th)) / k)
    return np.stack([px, py], axis=1)


def _standable(scenario: Scenario, z: np.ndarray, pts: list[np.ndarray], base: float) -> np.ndarray:
    """Per route: whether none of its points ``pts`` (a list of ``n × 2`` arrays, one point per
    route each) lies on a cell more than the loader's step (and 5 cm of slack for an arc point
    between two samples) above ``base``; a point off the map passes (the map's edge is checked
    in full later)."""
    spec: LoaderSpec = scenario.machines.loader
    n = len(pts[0])
    h = cell_heights(scenario.terrain, z, np.concatenate(pts)).reshape(len(pts), n)
    return ~np.any(np.nan_to_num(h, nan=-np.inf) > base + spec.max_step + 0.05, axis=0)


def _clear(scenario: Scenario, z: np.ndarray, route: Route, base: float) -> bool:
    """With the referee's own footprint rules: the outline on the map (0.2 m margin, or the
    outside open), the body clear of the truck's and its centre beyond the clearance (+ 0.1 m),
    the wheels' step traversable."""
    spec: LoaderSpec = scenario.machines.loader
    truck = scenario.machines.truck_pose
    xy = route.p[:, :2]
    if np.min(np.hypot(xy[:, 0] - truck.x, xy[:, 1] - truck.y)) < spec.clearance + 0.1:
        return False
    if step_excess(scenario.terrain, z, xy, base, spec.max_step)[0] > -1e-3:  # the axle: a quick first test
        return False
    path = np.column_stack([route.t, route.p[:, :3]])
    dense = dense_poses(path, scenario.terrain.resolution / 2, reach_of(spec.outline(0.0, 0.0, 0.0)))[:, 1:4]  # as the referee samples
    if not scenario.outside_open and np.max(off_map_excess(scenario, spec, dense)) > -0.05:
        return False
    if bodies_touch(spec, dense, scenario.machines.truck, np.array([truck.x, truck.y, truck.yaw]), margin=0.1).any():
        return False
    return wheel_step_excess(scenario.terrain, z, spec, path, base)[0] <= -1e-3


def search_dubins(
    scenario: Scenario,
    z: np.ndarray,
    start: Pose,
    t0: float,
    goal: tuple[float, float, float],
    opts: RouteOptions,
    base: float,
    lead_ins: tuple[float, ...] = (0.5, 2.0),
) -> Route | None:
    """The fastest feasible route from ``start`` to the pose ``goal``: a reverse part (straight and
    one arc, on the grid of ``opts``), a cusp, then a forward Dubins path (arc, straight, arc at the
    minimum turning radius: LSL, RSR, LSR, RSL) to ``goal`` less a straight lead-in, and the
    lead-in. Used for the return leg to the pile, where two arcs are often too few."""
    spec: LoaderSpec = scenario.machines.loader
    R = spec.min_turning_radius * RADIUS_MARGIN
    S0, K0, L0, qx0, qy0, thq0 = _reverse_part(start, opts, R, 1)
    gx, gy, gth = goal
    lead = np.array(lead_ins)
    ci, li, ti = np.meshgrid(np.arange(len(S0)), np.arange(len(lead)), np.arange(4), indexing="ij")
    ci, li, ti = ci.ravel(), li.ravel(), ti.ravel()
    qx, qy, th = qx0[ci], qy0[ci], thq0[ci]
    a = lead[li]
    px, py = gx - a * math.cos(gth), gy - a * math.sin(gth)
    s1 = np.where((ti == 0) | (ti == 2), 1.0, -1.0)  # first arc: +1 left, -1 right
    s2 = np.where((ti == 0) | (ti == 3), 1.0, -1.0)  # second arc
    c1x, c1y = qx - s1 * R * np.sin(th), qy + s1 * R * np.cos(th)
    c2x, c2y = px - s2 * R * math.sin(gth), py + s2 * R * math.cos(gth)
    dx, dy = c2x - c1x, c2y - c1y
    d = np.hypot(dx, dy)
    ang = np.arctan2(dy, dx)
    same = s1 == s2
    with np.errstate(invalid="ignore"):
        ell = np.where(same, d, np.sqrt(np.maximum(d * d - 4 * R * R, 0.0)))
        phi = np.where(same, ang, ang + s1 * np.arctan2(2 * R, ell))
    ok = same | (d >= 2 * R)
    two_pi = 2 * math.pi
    a1 = np.mod(s1 * (phi - th), two_pi)
    a2 = np.mod(s2 * (gth - phi), two_pi)
    v = spec.travel_speed * MARGIN
    v_arc = min(spec.travel_speed, spec.yaw_rate * R) * MARGIN
    v_rev = np.minimum(spec.travel_speed, spec.yaw_rate / np.maximum(np.abs(K0[ci, 0]), 1e-12)) * MARGIN
    dur = S0[ci] / v + L0[ci, 0] / v_rev + R * (a1 + a2) / v_arc + (ell + a) / v
    idx = np.nonzero(ok)[0]
    t1 = np.stack([c1x + s1 * R * np.sin(phi), c1y - s1 * R * np.cos(phi)], axis=1)  # where the first arc ends
    idx = idx[_standable(scenario, z, [np.stack([qx, qy], axis=1)[idx], t1[idx], (t1 + ell[:, None] * np.stack(
        [np.cos(phi), np.sin(phi)], axis=1))[idx]], base)]
    order = idx[np.argsort(dur[idx], kind="stable")]
    for k in order[: opts.max_checked]:
        segs = [
            (0.0, -S0[ci[k]]),
            (K0[ci[k], 0], -L0[ci[k], 0]),
            (s1[k] / R, R * a1[k]),
            (0.0, ell[k]),
            (s2[k] / R, R * a2[k]),
            (0.0, a[k]),
        ]
        route = _build(start, t0, spec, segs, (gx, gy), gth)
        if _clear(scenario, z, route, base):
            return route
    return None


def dump_rays(scenario: Scenario, n: int = 48) -> tuple[np.ndarray, float, float, float]:
    """Rays from the truck's centre in ``n`` directions, and the (lo, hi, target) distances of the
    loader's pose from the truck at which the bucket edge reaches the loading circle."""
    spec: LoaderSpec = scenario.machines.loader
    t = scenario.machines.truck_pose
    phi = np.arange(n) * 2 * math.pi / n
    rays = np.stack([np.full(n, t.x), np.full(n, t.y), np.cos(phi), np.sin(phi)], axis=1)
    hi = spec.bucket_offset + scenario.machines.truck.loading_radius + spec.dump_reach - 0.05
    lo = spec.clearance + 0.15
    if hi < lo:
        raise ValueError(f"the loader cannot dump here: dump distance {hi:.2f} m < clearance {lo:.2f} m")
    return rays, lo, hi, (lo + hi) / 2
