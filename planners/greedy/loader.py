"""``greedy-loader``: the floor every wheel-loader planner must beat.

Per bucket, the loader digs at the point of the pile's zero contour nearest to the truck,
perpendicular to the contour there: the bucket's cutting edge is centred on that point and
its heading is normal to the chord between the contour points half a bucket width either side,
into the pile. If that dig is infeasible (its charge takes nothing, or no route to it or from it
to the truck keeps the turning radius, the clearance and the traversable step), the next
nearest contour point is tried. Everything else — the contour, the charge model (the bucket
takes whole cells up to its capacity with the referee's own cut), the two-arc routes to the
truck and the return leg — is the shared machinery of :mod:`earthbench_planners.loader_cycle`, so the
difference to ``singh-cannon-loader`` is only the choice of dig: no dig region, no scoring.
The shared machinery also reads a scan (noise, offset, contour level, step margin) and the
soil's class (fill, harder layer, slump) the same way for both planners.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from earthbench.plan import Plan
from ..loader_cycle import Cycle, CycleBuilder, CyclePlanner, LoaderPlanConfig, pile_side


@dataclass(frozen=True)
class GreedyLoaderConfig(LoaderPlanConfig):
    pass


def nearest_candidates(line: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Every point of a resampled contour line with the unit normal of the chord between the
    points half a ``width`` before and after it (clamped at the line's ends)."""
    k = len(line)
    spacing = float(np.hypot(*(line[1] - line[0]))) if k > 1 else 1.0
    half = max(1, int(round(width / 2 / max(spacing, 1e-6))))
    i = np.arange(k)
    a, b = line[np.maximum(i - half, 0)], line[np.minimum(i + half, k - 1)]
    t = b - a
    norm = np.hypot(*t.T)
    ok = norm > 1e-9
    t = t[ok] / norm[ok, None]
    return line[ok], np.stack([-t[:, 1], t[:, 0]], axis=1)


class GreedyLoader(CyclePlanner):
    """Nearest contour point to the truck, perpendicular entry; see the module docstring."""

    name = "greedy-loader"
    version = "1.3"
    Config = GreedyLoaderConfig

    def _run(self, b: CycleBuilder, max_dumps: int | None = None) -> Plan:
        """Cycles until the target is loaded (or ``max_dumps`` cycles: one closed-loop step)."""
        cfg: GreedyLoaderConfig = self.config
        scenario = b.sc
        truck = scenario.machines.truck_pose

        def choose(lines: list[np.ndarray], capacity: float) -> Cycle | str:
            parts = [nearest_candidates(line, b.spec.bucket_width) for line in lines]
            M = np.concatenate([p[0] for p in parts])
            n = np.concatenate([p[1] for p in parts])
            h = n * pile_side(scenario.terrain, b.z, M, n, b.base)[:, None]
            order = np.argsort(np.hypot(M[:, 0] - truck.x, M[:, 1] - truck.y), kind="stable")
            cycle, k = b.first_feasible(M, h, order, capacity, [], cfg.max_tries)
            if cycle is None:
                return "no feasible candidate"
            cycle.candidate = {"edge_centre": [float(M[k, 0]), float(M[k, 1])]}
            return cycle

        stop = b.load_until_target(cfg.max_cycles, choose, max_dumps)
        return b.plan({"stop": stop, "digs": [c.candidate for c in b.cycles]})
