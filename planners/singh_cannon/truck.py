"""The truck's side of the singh-cannon backhoe's session: where the truck can stand to be
loaded from a base, the route it drives there and back (clear of the excavator and the keep-out
zones, on ground within its limits), and its moves in the plan."""

from __future__ import annotations

import math

import numpy as np
from shapely.geometry import LineString, Point

from earthbench.motion import turn_drive_turn
from earthbench.plan import Move
from earthbench.world import Pose


class TruckMoves:
    """The truck's moves of a :class:`~earthbench_planners.singh_cannon.backhoe.Session`, which
    holds the state they read and change (the scenario, the machines' poses, the actions so far)."""

    def truck_in_reach(self, base: Pose, truck: tuple[float, float]) -> bool:
        d = math.hypot(truck[0] - base.x, truck[1] - base.y)
        r = self.truck_spec.loading_radius
        return d - r <= self.spec.reach_max - 0.05 and d >= self.spec.clearance + 0.1 and d + r >= self.spec.reach_min + 0.05

    def clear(self, a: tuple[float, float], b: tuple[float, float], other: tuple[float, float]) -> bool:
        seg = LineString([a, b]) if math.hypot(a[0] - b[0], a[1] - b[1]) > 1e-9 else Point(a)
        if any(seg.intersects(k) for k in self.keep_outs):
            return False
        return seg.distance(Point(other)) >= self.spec.clearance + 0.05

    def truck_route(self, base: Pose, bearing: float, force: bool = False) -> tuple[list[tuple[float, float]], float | None] | None:
        """Waypoints taking the truck to a stand serving ``base`` whose material lies toward
        ``bearing``, and its yaw there (:meth:`..truck_stands.TruckStands.parking`: off the dig
        area on ground within its limits, the cheapest in travel and swing first); ``([], None)``
        when it stays where it is (without ``force``: whenever it is in reach already)."""
        here = (self.truck.x, self.truck.y)
        if not force and self.truck_in_reach(base, here):
            return [], None
        e = self.spec
        b = (base.x, base.y)
        ring = e.clearance + 1.0
        vias = [(base.x + ring * math.cos(a), base.y + ring * math.sin(a)) for a in np.linspace(-math.pi, math.pi, 16, endpoint=False)]
        buckets = max((self.sc.task.target_volume - self.loaded) / self.cap, 1.0)
        # the cheapest stands in travel and swing first; failing those, the nearest ones
        for weight in (buckets, 0.0):
            tried, failed = 0, set()
            for stand in self.stands.parking(base, self.truck, bearing, weight):
                p = (stand.x, stand.y)
                if stand == self.truck:
                    return [], None
                if (round(p[0], 2), round(p[1], 2)) in failed:
                    continue  # the same place, another yaw: its way fails as well
                if not self.truck_in_reach(base, p) or any(k.buffer(0.5).contains(Point(p)) for k in self.keep_outs):
                    continue
                route = None
                if self.clear(here, p, b):
                    route = [p]
                else:
                    best = None
                    for v in vias:
                        if self.clear(here, v, b) and self.clear(v, p, b):
                            length = math.dist(here, v) + math.dist(v, p)
                            if best is None or length < best[0]:
                                best = (length, v)
                    if best is not None:
                        route = [best[1], p]
                if route is None:
                    continue
                tried += 1
                if self.stands.path_ok(self.truck_path(route, 0.0, stand.yaw)):
                    return route, stand.yaw  # its way keeps the truck's ground limits
                failed.add((round(p[0], 2), round(p[1], 2)))
                if tried >= 40:
                    break
        return None

    def truck_path(self, route: list[tuple[float, float]], t0: float, yaw: float | None = None) -> list[tuple[float, float, float, float]]:
        """Samples of the truck driving through ``route`` from its current pose, starting at ``t0``,
        turning to ``yaw`` at the end."""
        pose, t = self.truck, t0
        samples = [(t0, pose.x, pose.y, pose.yaw)]
        for k, p in enumerate(route):
            seg = turn_drive_turn(pose, p, t, self.truck_spec.travel_speed, self.truck_spec.yaw_rate,
                                  final_yaw=yaw if k == len(route) - 1 else None)
            samples.extend(seg[1:])
            pose, t = Pose(seg[-1][1], seg[-1][2], seg[-1][3]), seg[-1][0]
        return samples

    def apart(self, a: list, b: list) -> bool:
        """Whether two sample paths stay the clearance apart at every instant (checked every 0.05 s
        and at every sample; each machine waits at its path's ends)."""
        A, B = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        t0, t1 = min(A[0, 0], B[0, 0]), max(A[-1, 0], B[-1, 0])
        ts = np.unique(np.concatenate([A[:, 0], B[:, 0], np.arange(t0, t1, 0.05), [t1]]))
        dx = np.interp(ts, A[:, 0], A[:, 1]) - np.interp(ts, B[:, 0], B[:, 1])
        dy = np.interp(ts, A[:, 0], A[:, 2]) - np.interp(ts, B[:, 0], B[:, 2])
        return bool(np.hypot(dx, dy).min() >= self.spec.clearance + 0.05)

    def add_truck_path(self, samples: list) -> None:
        if len(samples) < 2:
            return
        self.actions.append(Move("truck", tuple(samples)))
        self.truck = Pose(samples[-1][1], samples[-1][2], samples[-1][3])
        self.truck_ready = samples[-1][0]
        # its way, kept out of the arm's shadow by any dig's stroke before it arrives
        self.pending = np.asarray(samples, dtype=float) if self.truck_ready > self.t else None

    def bring_truck(self, route: list[tuple[float, float]], yaw: float | None, t0: float) -> None:
        self.add_truck_path(self.truck_path(route, max(t0, self.truck_ready), yaw))
