"""``rbf``: mounds from a superposition of Gaussian radial basis functions.

The STL-TAMP paper (Satoh, Takano, Oyama, section V) generates its global maps this way on a
12 m × 6 m map (x ∈ [0, 12], y ∈ [0, 6]), with 14 bases for the task-switching experiment
(V-A) and 30 for the extensive one (V-B); the excavator starts at (13.0, 7.2) and the truck at
(2.0, 13.0), both off the map, so both machines must drive before the first load.

``z(x, y) = Σ_k a_k · exp(−‖(x, y) − c_k‖² / (2 s_k²))`` with centres ``c_k`` uniform on the
map, amplitudes ``a_k ~ U(amplitude)`` and widths ``s_k ~ U(width)``, sampled at the cell
centres and rounded to 0.1 mm. The floor (design grade) is z = 0.

Amplitudes and widths are not given in the paper. We keep one distribution per base
(a ∈ [0.2, 0.8] m, s ∈ [0.6, 1.4] m) for both experiments, because the paper adds bases "to
cover a wider area", i.e. more mounds rather than flatter ones. Measured over seeds 0–19:
14 bases give 27–46 m³ above the floor with peaks of 1.0–2.3 m; 30 bases give 62–90 m³ with
peaks of 1.9–3.5 m. Either way the map holds far more than twice the paper's largest target
(7 m³), so a planner must choose where to dig, and a 0.4 m cut fills the 0.28 m³ bucket.
"""

from __future__ import annotations


import numpy as np

from earthbench.errors import ScenarioError
from earthbench.world import Budget, Heightmap, Scenario

from .common import backhoe_site, rectangle, round_heights

#: Elements of the largest array the mounds are summed through: 4 × earthbench.results.suite.MAX_CELLS
#: (the scale suite's 96 × 48 m map with 1,920 mounds needs 5.5 million).
BASIS_CAP = 16_000_000


def rbf_surface(
    seed: int,
    *,
    n_bases: int = 14,
    size: tuple[float, float] = (12.0, 6.0),
    resolution: float = 0.05,
    amplitude: tuple[float, float] = (0.2, 0.8),
    width: tuple[float, float] = (0.6, 1.4),
) -> Heightmap:
    """The heightmap alone: ``n_bases`` Gaussian mounds on a ``size`` map at ``resolution``."""
    lx, ly = float(size[0]), float(size[1])
    nx, ny = int(round(lx / resolution)), int(round(ly / resolution))
    # the mounds are summed as (ny × n)·(n × nx): bound n by the map's cells and the arrays by the cell cap
    if not 0 <= n_bases <= nx * ny or n_bases * (nx + ny) > BASIS_CAP:
        raise ScenarioError(f"rbf: n_bases = {n_bases} is out of range for a {nx} × {ny} cell map: at most "
                            f"{min(nx * ny, BASIS_CAP // max(1, nx + ny)):,} (one per cell, and n_bases × (nx + ny) ≤ {BASIS_CAP:,})")
    rng = np.random.default_rng(seed)
    centres = rng.uniform((0.0, 0.0), (lx, ly), size=(n_bases, 2))
    amps = rng.uniform(*amplitude, size=n_bases)
    widths = rng.uniform(*width, size=n_bases)
    xs = (np.arange(nx) + 0.5) * resolution
    ys = (np.arange(ny) + 0.5) * resolution
    # Each Gaussian is separable, so the sum is one matrix product: (ny × n)·(n × nx).
    gx = np.exp(-((xs[None, :] - centres[:, :1]) ** 2) / (2 * widths[:, None] ** 2))
    gy = np.exp(-((ys[None, :] - centres[:, 1:]) ** 2) / (2 * widths[:, None] ** 2))
    z = (gy.T * amps[None, :]) @ gx
    return Heightmap((0.0, 0.0), resolution, round_heights(z))


def richest_window(terrain: Heightmap, size: tuple[float, float], floor: float = 0.0) -> tuple[tuple[float, float], ...]:
    """The axis-aligned ``size`` rectangle, on cell edges, holding the most volume above ``floor``.

    Ties go to the lowest row, then the lowest column, so the choice is deterministic.
    """
    r = terrain.resolution
    w, h = int(round(size[0] / r)), int(round(size[1] / r))
    ny, nx = terrain.shape
    if not (1 <= w <= nx and 1 <= h <= ny):
        raise ScenarioError(f"rbf: local_area {tuple(size)} m does not fit the {nx * r:g} × {ny * r:g} m map")
    excess = np.clip(terrain.z - floor, 0.0, None)
    c = np.zeros((ny + 1, nx + 1))
    c[1:, 1:] = excess.cumsum(0).cumsum(1)
    win = c[h:, w:] - c[:-h, w:] - c[h:, :-w] + c[:-h, :-w]
    j, i = np.unravel_index(int(np.argmax(win)), win.shape)
    x0, y0 = terrain.origin[0] + i * r, terrain.origin[1] + j * r
    x1, y1 = x0 + w * r, y0 + h * r
    return tuple((round(x, 6), round(y, 6)) for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1)))


def rbf(
    seed: int,
    target_volume: float = 1.12,
    *,
    n_bases: int = 14,
    size: tuple[float, float] = (12.0, 6.0),
    resolution: float = 0.05,
    amplitude: tuple[float, float] = (0.2, 0.8),
    width: tuple[float, float] = (0.6, 1.4),
    local_area: tuple[float, float] | None = None,
    excavator: tuple[float, float, float] | None = None,
    truck: tuple[float, float, float] | None = None,
    truck_capacity: float = 10.0,
    budget: Budget | None = None,
    scenario_id: str | None = None,
) -> Scenario:
    """Gaussian mounds on the STL-TAMP paper's map and poses (14 or 30 bases); floor z = 0.

    Parameters:

    - ``n_bases``: number of Gaussian mounds (paper: 14 for task switching, 30 extensive).
    - ``size``: map extent (lx, ly) in m, origin at (0, 0); ``resolution``: cell size in m.
    - ``amplitude``, ``width``: (low, high) ranges of each mound's height and standard deviation (m).
    - ``local_area``: None → the whole map is the dig area (V-B). A (w, h) in m → the dig area
      is the w × h rectangle holding the most material (V-A plans "one local area" of
      S_l = 3.5 m²; the paper does not say where, so we take the richest one).
    - ``excavator``, ``truck``: initial poses (x, y, yaw). Default: the paper's poses as offsets
      from the map's corners — excavator (lx + 1.0, ly + 1.2), yaw π; truck (2.0, ly + 7.0),
      yaw 0 — i.e. (13.0, 7.2) and (2.0, 13.0) on the 12 m × 6 m map. Offsets rather than a
      scaling keep the drive to the map the same on larger maps (the ``scale`` suite).
    - ``truck_capacity``: m³; raise it above the default 10 m³ for larger targets.
    """
    lx, ly = float(size[0]), float(size[1])
    terrain = rbf_surface(
        seed, n_bases=n_bases, size=(lx, ly), resolution=resolution, amplitude=tuple(amplitude), width=tuple(width)
    )
    if local_area is None:
        dig_area = rectangle(0.0, 0.0, lx, ly)
    else:
        dig_area = richest_window(terrain, (float(local_area[0]), float(local_area[1])))
    meta = {"generator": "rbf", "seed": seed, "n_bases": n_bases, "size": [lx, ly], "resolution": resolution}
    if local_area is not None:
        meta["local_area"] = [float(local_area[0]), float(local_area[1])]
    return backhoe_site(scenario_id or f"rbf-n{n_bases}-{lx:g}x{ly:g}-s{seed}-v{target_volume:g}", terrain, dig_area=dig_area,
                        target_volume=target_volume, corner=(0.0, lx, ly), excavator=excavator, truck=truck,
                        truck_capacity=truck_capacity, budget=budget, meta=meta)
