"""``singh-cannon-loader``: Singh and Cannon's coarse-to-fine wheel-loader planner (section 3.2).

**Coarse planner** (Fig. 8). The pile's zero contour is the contour of the ground at
``floor + level``: 2 cm on exact ground, where the terrain meets the floor; on a scan, the
ground is :func:`~earthbench_planners.loader_cycle.read_scan` of it (smoothed, the floor's
offset removed) and the level at least 5 smoothed σ of the scan's estimated noise. The contour point closest
to the truck ``P*`` is located and the dig region is the part of the contour whose distance
from ``P*`` lies in ``[d1, d2]`` (straight-line distance). Only one region is used, because the
truck's pose fixes where digging pays; if no candidate in it is feasible, the region grows
(``d2`` × ``widen``, ``d1`` → 0) until the whole contour is in it.

**Refined planner** (Figs. 9, 10). The action is one number: the position ``s`` (arc length,
every ``contour_spacing`` m) of the bucket's first front corner on the contour. The second
corner is the next contour point one bucket width away, so both front corners touch the zero
contour and the heading is perpendicular to the chord between them, into the pile. Every
candidate of the region is scored at once (numpy) with the product of

- side loading ``ξ = 1 − |V1 − V2| / (V1 + V2)``,
- concavity ``ψ = min(1, (V1 + V2) / capacity)``,
- location ``ζ = max(0, 1 − dist / max_distance)``,

where ``V1``/``V2`` are the volumes above the floor in the left/right halves of the box the
bucket covers at its starting location: ``bucket_depth`` behind the cutting edge (inside the
bucket: material there is the protrusion between the corners) and ``ahead`` in front of it, and
``dist`` is the distance from the edge's centre to the truck. **Correction:** the paper prints
``ζ = min(0, 1 − Dist/MaxDistance)``, which is never positive and would make every product zero
(or negative); we use ``max(0, …)``, which falls linearly from 1 at the truck to 0 at
``max_distance`` as the text describes ("ζ decreases as the travel distance increases").

Candidates are tried best first. Hard constraints (section 3.2.2): the trajectory from the dig
to the truck must be **two arcs** at or above the minimum turning radius (a reverse arc, a cusp
and a forward arc, after backing straight out of the cut), with no collision with the truck
(clearance) or the pile (traversable step); the approach to the entry pose must be feasible in
the same way. Candidates within 0.25 m of one that failed are skipped.

**Plan**: per bucket — approach (reverse, two arcs, straight in), charge (penetration chosen so
the bucket takes whole cells up to its capacity, with the public cut model; with the soil's
class, to the harder layer and no more than 85 % of the capacity, see
:mod:`~earthbench_planners.loader_cycle`), reverse out and two arcs to the truck, dump; repeated
until the target is loaded (the last bucket takes only what is still missing). When no
candidate of the widened region is feasible for a full charge, the same search runs once for a
half charge. Closed loop: one cycle per step, from the observed ground, sized with the yield
the truck has reported so far.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from earthbench.plan import Plan
from ..loader_cycle import Cycle, CycleBuilder, CyclePlanner, LoaderPlanConfig, box_volumes, pile_side


@dataclass(frozen=True)
class SinghCannonLoaderConfig(LoaderPlanConfig):
    d1: float = 0.0
    """Inner distance (m) of the dig region from the contour point closest to the truck. The
    paper leaves it open; 0 suits sites where the truck stands well clear of the pile (``pile``:
    7.5 m), a positive value keeps digs away from a truck parked close to it."""
    d2: float = 7.0
    """Outer distance (m) of the dig region."""
    widen: float = 1.5
    """Factor on d2 when no candidate in the region is feasible."""
    bucket_depth: float = 0.9
    """Depth (m) of the box behind the cutting edge counted as inside the bucket (ψ, ξ)."""
    ahead: float = 0.5
    """Depth (m) of the box in front of the cutting edge counted for side loading and concavity."""
    max_distance: float = 12.0
    """Distance (m) from the truck at which the location score ζ reaches 0."""


def corner_candidates(line: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For every point ``i`` of a resampled contour line: the bucket-edge centre ``M`` and unit
    normal of the chord to the first later point one ``width`` away, and the index ``i``."""
    k = len(line)
    spacing = float(np.hypot(*(line[1] - line[0]))) if k > 1 else 1.0
    kw = int(np.ceil(2.5 * width / max(spacing, 1e-6))) + 1
    idx = np.arange(k)[:, None] + np.arange(1, kw + 1)[None, :]
    valid = idx < k
    pts = line[np.minimum(idx, k - 1)]
    d = np.hypot(pts[..., 0] - line[:, None, 0], pts[..., 1] - line[:, None, 1])
    far = (d >= width) & valid
    has = far.any(axis=1)
    first = np.argmax(far, axis=1)
    i = np.nonzero(has)[0]
    j = idx[i, first[i]]
    A, B = line[i], line[j]
    t = (B - A) / np.hypot(*(B - A).T)[:, None]
    n = np.stack([-t[:, 1], t[:, 0]], axis=1)
    return (A + B) / 2, n, i


class SinghCannonLoader(CyclePlanner):
    """Coarse dig region on the zero contour, refined by ξ·ψ·ζ; see the module docstring."""

    name = "singh-cannon-loader"
    version = "1.3"
    Config = SinghCannonLoaderConfig

    def _run(self, b: CycleBuilder, max_dumps: int | None = None) -> Plan:
        """Cycles until the target is loaded (or ``max_dumps`` cycles: one closed-loop step)."""
        cfg: SinghCannonLoaderConfig = self.config
        scenario = b.sc
        truck = scenario.machines.truck_pose
        widened = 0

        def choose(lines: list[np.ndarray], capacity: float) -> Cycle | str:
            nonlocal widened
            Ms, Ns = [], []
            for line in lines:
                M, n, _ = corner_candidates(line, b.spec.bucket_width)
                Ms.append(M), Ns.append(n)
            M, n = np.concatenate(Ms), np.concatenate(Ns)
            if len(M) == 0:
                return "no contour left"
            h = n * pile_side(scenario.terrain, b.z, M, n, b.base)[:, None]
            allpts = np.concatenate(lines)
            pstar = allpts[np.argmin(np.hypot(allpts[:, 0] - truck.x, allpts[:, 1] - truck.y))]
            V1, V2 = box_volumes(scenario.terrain, b.z, M, h, b.spec.bucket_width, cfg.bucket_depth, cfg.ahead, b.level)
            tot = V1 + V2
            with np.errstate(divide="ignore", invalid="ignore"):
                xi = np.where(tot > 0, 1.0 - np.abs(V1 - V2) / tot, 0.0)
            psi = np.minimum(1.0, tot / b.spec.bucket_capacity)
            zeta = np.maximum(0.0, 1.0 - np.hypot(M[:, 0] - truck.x, M[:, 1] - truck.y) / cfg.max_distance)
            score = xi * psi * zeta
            dstar = np.hypot(M[:, 0] - pstar[0], M[:, 1] - pstar[1])
            d1, d2 = cfg.d1, cfg.d2
            failed: list[np.ndarray] = []
            while True:  # the region d1–d2, widened until a candidate is feasible or nothing is left
                region = (dstar >= d1) & (dstar <= d2)
                order = np.nonzero(region)[0]
                order = order[np.lexsort((-zeta[order], -score[order]))]
                cycle, k = b.first_feasible(M, h, order, capacity, failed, cfg.max_tries)
                if cycle is not None or (d1 == 0.0 and d2 >= dstar.max()):
                    break
                d1, d2 = 0.0, d2 * cfg.widen
                widened += 1
            if cycle is None:
                return "no feasible candidate"
            cycle.candidate = {"xi": float(xi[k]), "psi": float(psi[k]), "zeta": float(zeta[k]), "score": float(score[k]),
                               "edge_centre": [float(M[k, 0]), float(M[k, 1])]}
            return cycle

        stop = b.load_until_target(cfg.max_cycles, choose, max_dumps)
        return b.plan({"stop": stop, "region_widened": widened, "digs": [c.candidate for c in b.cycles]})
