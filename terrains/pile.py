"""``pile``: a wall of loose material for the wheel-loader track (Singh and Cannon, Fig. 8, 12).

Layout (x east, y north; default 20 m × 18 m at 0.1 m cells)::

    y
    ^   ~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~  pile: plateau of ``height`` m, runs on past the map
    |  /  zero contour near y = face_y,   \\   edge; wall from x = wall[0] to wall[1]
    |  \\_/\\  with protrusions and recesses  /
    |
    |               loader (0.6·lx, face_y − 5) = (12, 6), yaw π/2 (facing the wall)
    |   truck (0.25·lx, face_y − 7.5) = (5, 3.5), yaw 0 (parallel to the wall)
    +------------------------------------------------------------------> x

- The open ground between the wall and the truck (7.5 m) leaves room for V-shaped loading
  cycles of a loader with a 3.5 m turning radius: back out of the pile on an arc, drive on an
  arc to the truck, and back. The open ground is the design grade: ``site.floor = 0``; the whole map is the dig area.
- The zero contour (where the pile meets the floor) is ``y = face_y − Σ_k a_k g_k(x)`` between
  the wall's ends, with ``g_k`` Gaussian bumps of width ``s_k``: ``a_k > 0`` is a protrusion
  toward the loader, ``a_k < 0`` a recess. ``n_features`` bumps are drawn with centres spread
  along the face (at least 1.5 σ from each other), amplitudes ``amplitude`` and widths
  ``width``; about a third of them are recesses, and there is always at least one
  protrusion. ``features`` = ``[(x, a, s), …]`` replaces the draw (tests use one protrusion).
- Heights rise from the contour at ``slope`` (rise over horizontal distance from the nearest
  cell outside the pile: an angle-of-repose face around every protrusion and recess, and
  sloped wall ends) up to a plateau of ``height`` m; the pile runs on past the map's north
  edge. Heights are rounded to 0.1 mm.
- The loader and the truck stand on open ground at least ``min_gap`` m from any material;
  generation fails with a ScenarioError if a custom layout breaks this, if the poses are
  closer than the loader's clearance, or if the site holds less than twice the target.

Default site volume above the floor: about 80–110 m³, so the suite's targets (2 and 4 m³) leave
the planner the choice of where to dig.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import distance_transform_edt

from earthbench.errors import ScenarioError
from earthbench.world import Budget, Heightmap, Pose, Scenario

from .common import assemble_scenario, rectangle, round_heights


def _draw_features(rng: np.random.Generator, n: int, span: tuple[float, float], amplitude, width) -> list[tuple[float, float, float]]:
    """``n`` bumps (x, a, s) spread along ``span``; about a third recesses, at least one protrusion."""
    feats: list[tuple[float, float, float]] = []
    tries = 0
    while len(feats) < n and tries < 200:
        tries += 1
        s = float(rng.uniform(*width))
        x = float(rng.uniform(span[0] + s, span[1] - s))
        if any(abs(x - fx) < 1.5 * (s + fs) for fx, _, fs in feats):
            continue
        a = float(rng.uniform(*amplitude))
        if feats and rng.uniform() < 1 / 3:
            a = -0.6 * a  # recesses are shallower: the wall behind them has to stay on the map
        feats.append((x, a, s))
    return feats


def pile(
    seed: int,
    target_volume: float = 2.0,
    *,
    size: tuple[float, float] = (20.0, 18.0),
    resolution: float = 0.1,
    face_y: float = 11.0,
    wall: tuple[float, float] = (3.0, 17.0),
    height: float | tuple[float, float] = (1.0, 1.4),
    slope: float | tuple[float, float] = (0.55, 0.75),
    n_features: int | tuple[int, int] = (3, 5),
    amplitude: tuple[float, float] = (0.6, 1.5),
    width: tuple[float, float] = (0.5, 1.1),
    features: list | tuple | None = None,
    loader: tuple[float, float, float] | None = None,
    truck: tuple[float, float, float] | None = None,
    truck_capacity: float = 10.0,
    min_gap: float = 2.0,
    budget: Budget | None = None,
    scenario_id: str | None = None,
) -> Scenario:
    """A wheel-loader scenario on a pile; see the module docstring for the layout."""
    rng = np.random.default_rng(seed)
    lx, ly = size
    h = float(rng.uniform(*height)) if isinstance(height, (tuple, list)) else float(height)
    k = float(rng.uniform(*slope)) if isinstance(slope, (tuple, list)) else float(slope)
    if features is None:
        n = int(rng.integers(n_features[0], n_features[1] + 1)) if isinstance(n_features, (tuple, list)) else int(n_features)
        feats = _draw_features(rng, n, (wall[0] + 1.5, wall[1] - 1.5), amplitude, width)
    else:
        feats = [(float(x), float(a), float(s)) for x, a, s in features]
    nx, ny = int(round(lx / resolution)), int(round(ly / resolution))
    xs = (np.arange(nx) + 0.5) * resolution
    ys = (np.arange(ny) + 0.5) * resolution
    contour = np.full(nx, face_y)
    for x, a, s in feats:
        contour -= a * np.exp(-((xs - x) ** 2) / (2 * s * s))
    inside = (ys[:, None] >= contour[None, :]) & (xs[None, :] >= wall[0]) & (xs[None, :] <= wall[1])
    dist = distance_transform_edt(inside) * resolution  # to the nearest cell outside the pile
    z = np.where(inside, np.minimum(h, k * (dist - 0.5 * resolution)), 0.0)
    terrain = Heightmap((0.0, 0.0), resolution, round_heights(z))
    loader_pose = Pose(*(loader or (0.6 * lx, face_y - 5.0, math.pi / 2)))
    truck_pose = Pose(*(truck or (0.25 * lx, face_y - 7.5, 0.0)))
    sc = assemble_scenario(
        scenario_id or f"pile-{lx:g}x{ly:g}-s{seed}-v{target_volume:g}",
        terrain,
        dig_area=rectangle(0.0, 0.0, lx, ly),
        target_volume=target_volume,
        loader_pose=loader_pose,
        truck_pose=truck_pose,
        truck_capacity=truck_capacity,
        budget=budget,
        meta={
            "generator": "pile", "seed": seed, "size": list(size), "resolution": resolution,
            "features": [list(f) for f in feats],
        },
    )
    xs, ys = terrain.cell_centres()
    material = terrain.z > 0.0
    for name, p in (("loader", loader_pose), ("truck", truck_pose)):
        near = (xs[None, :] - p.x) ** 2 + (ys[:, None] - p.y) ** 2 < min_gap**2
        if np.any(material & near):
            raise ScenarioError(f"scenario {sc.id!r}: the {name} stands within {min_gap:g} m of material; move it away from the pile")
    return sc
