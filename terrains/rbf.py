"""``rbf``: mounds from a superposition of Gaussian radial basis functions.

The STL-TAMP paper (Satoh, Takano, Oyama, section V) generates its global maps this way on a
12 m × 6 m map, with 14 bases for the task-switching experiment and 30 for the extensive one;
the excavator starts at (13.0, 7.2) and the truck at (2.0, 13.0). The paper does not give the
amplitudes and widths, so we choose them (documented below) to give mounds of a few decimetres
to about a metre over a flat floor at z = 0, which is also the design grade.

``z(x, y) = Σ_k a_k · exp(−‖(x, y) − c_k‖² / (2 s_k²))`` with centres ``c_k`` uniform on the
map, amplitudes ``a_k ~ U(amplitude)`` and widths ``s_k ~ U(width)``, sampled at the cell
centres and rounded to 0.1 mm.
"""

from __future__ import annotations

import math

import numpy as np

from earthbench.world import Budget, Heightmap, Machines, Pose, Scenario, Site, Task


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
    rng = np.random.default_rng(seed)
    lx, ly = size
    centres = rng.uniform((0.0, 0.0), (lx, ly), size=(n_bases, 2))
    amps = rng.uniform(*amplitude, size=n_bases)
    widths = rng.uniform(*width, size=n_bases)
    nx, ny = int(round(lx / resolution)), int(round(ly / resolution))
    xs = (np.arange(nx) + 0.5) * resolution
    ys = (np.arange(ny) + 0.5) * resolution
    z = np.zeros((ny, nx))
    for (cx, cy), a, s in zip(centres, amps, widths):
        z += a * np.outer(np.exp(-((ys - cy) ** 2) / (2 * s * s)), np.exp(-((xs - cx) ** 2) / (2 * s * s)))
    return Heightmap((0.0, 0.0), resolution, np.round(z, 4))


def rbf(
    seed: int,
    target_volume: float = 1.12,
    *,
    n_bases: int = 14,
    size: tuple[float, float] = (12.0, 6.0),
    resolution: float = 0.05,
    amplitude: tuple[float, float] = (0.2, 0.8),
    width: tuple[float, float] = (0.6, 1.4),
    excavator: tuple[float, float, float] | None = None,
    truck: tuple[float, float, float] | None = None,
    budget: Budget | None = None,
    scenario_id: str | None = None,
) -> Scenario:
    """A scenario on an rbf map; the whole map is the dig area, the floor is z = 0.

    Machine poses default to the paper's, scaled with the map: excavator at
    (lx + 1.0, 1.2·ly), yaw π; truck at (2.0, 2.17·ly), yaw 0 — (13.0, 7.2) and (2.0, 13.0) on
    the 12 m × 6 m map.
    """
    lx, ly = size
    terrain = rbf_surface(seed, n_bases=n_bases, size=size, resolution=resolution, amplitude=amplitude, width=width)
    exc = Pose(*(excavator or (lx + 1.0, 1.2 * ly, math.pi)))
    trk = Pose(*(truck or (2.0, ly * 13.0 / 6.0, 0.0)))
    return Scenario(
        id=scenario_id or f"rbf-n{n_bases}-{lx:g}x{ly:g}-s{seed}-v{target_volume:g}",
        terrain=terrain,
        site=Site(dig_area=((0.0, 0.0), (lx, 0.0), (lx, ly), (0.0, ly)), floor=0.0),
        machines=Machines(excavator_pose=exc, truck_pose=trk),
        task=Task(target_volume),
        budget=budget or Budget(),
        meta={"generator": "rbf", "seed": seed, "n_bases": n_bases, "size": list(size), "resolution": resolution},
    )
