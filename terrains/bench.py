"""``bench``: bench loading — a backhoe on a raised bench digs the face and loads a truck below.

After Singh and Cannon (Fig. 1a, Fig. 5): "an excavator sits on a raised section of the
terrain and digs in the face of the bench. The material is then dumped into a nearby truck."

Layout (x east, y north; default 14 m × 12 m at 0.05 m cells)::

    y
    ^      lower level (z = 0)  | face |  bench top (z ≈ height)
    |                           |      |
    |   truck (4.0, 3.0)        toe  crest      excavator (10.0, 6.0), yaw π (facing west)
    +------------------------------------------------------------------> x

- The lower level, where the truck stands, is the design grade: ``site.floor = 0``.
- The face runs north–south; its crest lies ``setback`` m west of the excavator and its toe
  ``height / tan(face_angle)`` further west. The toe and crest lines wander by up to
  ``irregularity`` m (a sum of four seeded sinusoids: protrusions and recesses), the bench top
  height varies by ±10 % along the face, and ``n_lumps`` seeded Gaussian lumps (spill and
  boulders, a third of them hollows) sit on the face. Heights are clipped at the floor.
- The dig area is the strip from 0.3 m west of the farthest possible toe to 0.5 m in front
  of the excavator, ``face_length`` m long (north–south) and centred on it, so the
  excavator's own pad is never part of it.

Geometry the referee needs, true for every seed with the defaults: the nominal toe lies
2.5 + run ≤ 4.3 m from the base (inside the 2.0–6.1 m reach annulus); the truck's centre lies
√(6² + 3²) = 6.71 m from the base, so its loading circle (radius 1.0 m) is within the 6.1 m
reach and the 3.5 m clearance holds; the truck (x = 4.0) stands on the floor, west of every
toe (x ≥ 7.5 − 1.8 − 0.4 = 5.3 m: crest, longest run, largest wander).
"""

from __future__ import annotations

import math

import numpy as np

from earthbench.errors import ScenarioError
from earthbench.world import Budget, ExcavatorSpec, Heightmap, Pose, Scenario, TruckSpec

from .common import assemble_scenario, rectangle, round_heights


def _sample(rng: np.random.Generator, value: float | tuple[float, float]) -> float:
    """A fixed value, or a uniform draw from a (low, high) range."""
    if isinstance(value, (tuple, list)):
        return float(rng.uniform(value[0], value[1]))
    return float(value)


def _wiggle(rng: np.random.Generator, y: np.ndarray, period: float, peak: float) -> np.ndarray:
    """Four seeded sinusoids along y, scaled so the largest excursion is exactly ``peak``."""
    w = np.zeros_like(y)
    for k in range(1, 5):
        a = rng.uniform(0.3, 1.0) / k
        phase = rng.uniform(0.0, 2.0 * math.pi)
        w += a * np.sin(2.0 * math.pi * k * y / period + phase)
    m = float(np.max(np.abs(w)))
    return w * (peak / m) if m > 0 else w


def _add_lumps(rng: np.random.Generator, z: np.ndarray, xs: np.ndarray, ys: np.ndarray, resolution: float,
               toe: np.ndarray, run: float, strip: tuple[float, float], n: int, height: tuple[float, float],
               width: tuple[float, float]) -> np.ndarray:
    """Seeded Gaussian lumps and hollows (a third of them) on the face: centred on the face line
    (``toe`` per row, ``run`` wide), anywhere along the dig ``strip`` (its south and north ends);
    ``z`` is added to in place."""
    for _ in range(n):
        cy = rng.uniform(*strip)
        j = min(max(int(cy / resolution), 0), len(ys) - 1)
        cx = toe[j] + run * rng.uniform(-0.2, 1.2)
        a = rng.uniform(*height) * (-1.0 if rng.uniform() < 1.0 / 3.0 else 1.0)
        s = rng.uniform(*width)
        z += a * np.outer(np.exp(-((ys - cy) ** 2) / (2 * s * s)), np.exp(-((xs - cx) ** 2) / (2 * s * s)))
    return z


def _check_reach(excavator: tuple[float, float, float], truck: tuple[float, float, float], toe0: float, strip_ok: bool) -> None:
    """The nominal toe within the backhoe's reach (and a dig strip left in front of its pad), the
    truck's loading circle within dump reach: otherwise no plan could be valid."""
    ex, ey, _ = excavator
    spec = ExcavatorSpec()
    if not (spec.reach_min <= ex - toe0 <= spec.reach_max and strip_ok):
        raise ScenarioError(
            f"bench: the nominal toe lies {ex - toe0:.2f} m in front of the excavator, outside its reach "
            f"{spec.reach_min}–{spec.reach_max} m; lower setback or height, or steepen face_angle"
        )
    d_truck = math.hypot(truck[0] - ex, truck[1] - ey)
    if d_truck - TruckSpec().loading_radius > spec.reach_max:
        raise ScenarioError(f"bench: the truck stands {d_truck:.2f} m from the excavator, beyond dump reach; move it closer")


def bench(
    seed: int,
    target_volume: float = 4.0,
    *,
    size: tuple[float, float] = (14.0, 12.0),
    resolution: float = 0.05,
    height: float | tuple[float, float] = (1.2, 1.8),
    face_angle: float | tuple[float, float] = (45.0, 65.0),
    face_length: float = 10.0,
    setback: float = 2.5,
    irregularity: float = 0.4,
    n_lumps: int = 12,
    lump_height: tuple[float, float] = (0.1, 0.3),
    lump_width: tuple[float, float] = (0.25, 0.6),
    excavator: tuple[float, float, float] = (10.0, 6.0, math.pi),
    truck: tuple[float, float, float] = (4.0, 3.0, math.pi / 2),
    truck_capacity: float = 10.0,
    budget: Budget | None = None,
    scenario_id: str | None = None,
) -> Scenario:
    """Bench loading: a backhoe on a raised bench digs its face and loads a truck below.

    Parameters (lengths in m, angles in degrees):

    - ``height``: bench height above the lower level (fixed, or a (low, high) range drawn per seed).
    - ``face_angle``: face slope from horizontal (fixed or range); run = height / tan(angle).
    - ``face_length``: north–south length of the dig area, centred on the excavator.
    - ``setback``: distance from the excavator west to the nominal crest.
    - ``irregularity``: peak wander of the toe/crest line (seeded protrusions and recesses).
    - ``n_lumps``, ``lump_height``, ``lump_width``: seeded lumps and hollows on the face.
    - ``excavator``, ``truck``: initial poses ``(x, y, yaw)``; ``truck_capacity`` in m³.
    - ``size``, ``resolution``: map extent and cell size.
    """
    rng = np.random.default_rng(seed)
    lx, ly = size
    h0 = _sample(rng, height)
    angle = _sample(rng, face_angle)
    if not (0.0 < angle < 90.0) or h0 <= 0.0:
        raise ScenarioError(f"bench: need 0 < face_angle < 90 degrees and height > 0, got {angle}, {h0}")
    run = h0 / math.tan(math.radians(angle))
    ex, ey, _ = excavator
    crest0 = ex - setback
    toe0 = crest0 - run

    nx, ny = int(round(lx / resolution)), int(round(ly / resolution))
    xs = (np.arange(nx) + 0.5) * resolution
    ys = (np.arange(ny) + 0.5) * resolution
    toe = toe0 + _wiggle(rng, ys, ly, irregularity)  # per row y
    top = h0 * (1.0 + 0.1 * _wiggle(rng, ys, ly, 1.0))
    u = (xs[None, :] - toe[:, None]) / run
    z = top[:, None] * np.clip(u, 0.0, 1.0)
    z = np.clip(_add_lumps(rng, z, xs, ys, resolution, toe, run, (ey - face_length / 2, ey + face_length / 2), n_lumps,
                           lump_height, lump_width), 0.0, None)

    x_lo = max(toe0 - irregularity - 0.3, 0.0)
    x_hi = ex - 0.5  # the excavator's pad stays outside the dig area
    y_lo, y_hi = max(ey - face_length / 2, 0.0), min(ey + face_length / 2, ly)
    _check_reach(excavator, truck, toe0, x_lo < x_hi)
    return assemble_scenario(
        scenario_id or f"bench-s{seed}-v{target_volume:g}",
        Heightmap((0.0, 0.0), resolution, round_heights(z)),
        dig_area=rectangle(x_lo, y_lo, x_hi, y_hi),
        target_volume=target_volume,
        excavator_pose=Pose(*excavator),
        truck_pose=Pose(*truck),
        truck_capacity=truck_capacity,
        budget=budget,
        meta={
            "generator": "bench",
            "seed": seed,
            "height": round(h0, 4),
            "face_angle": round(angle, 3),
            "size": list(size),
            "resolution": resolution,
        },
    )
