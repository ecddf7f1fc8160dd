"""Perception: the planner's view of a scenario, never the truth (docs/DESIGN.md §3, §6).

:func:`observe` is the one hand-over from the world to a planner. The harness calls it in its
own process and sends the planner only what it returns; the referee judges on the truth.

The scan of a :class:`~earthbench.world.Sensing` section, in this order:

1. **Occlusion** (when ``occlusion``): a sensor sits ``sensor_height`` m above the ground at
   the working machine's pose (a lidar on the cab). A cell is hidden when the terrain between
   the sensor and it rises above the line of sight to the top of its centre. The line of sight
   is traced on the grid itself (a 2.5-D heightmap has no overhangs, so a cell's top is the
   whole of what a sensor can see of it): along rays a quarter of a degree apart (only those
   that cross the map), sampled every cell, the steepest elevation angle seen so far is carried
   outward (``maximum.accumulate``), and a cell is visible when its own angle reaches what the
   samples more than one cell nearer the sensor reached. The ground off the map is level at the site's open-ground height.
2. **Resolution**: the visible cells are averaged over blocks of ``cell_size`` (a whole multiple
   of the terrain's resolution) from the map's origin; a block with no visible cell is hidden,
   and a partial block at the far edges is left out (the scan covers whole blocks).
3. **Filling**: each hidden cell takes the height of the nearest visible one, but no more than
   the line of sight over it (which it lies below): a scan delivers a full grid, not holes, and
   the planner cannot tell a filled cell from a measured one.
4. **Noise**: every cell gets ``bias`` plus Gaussian noise of σ ``noise``, drawn from
   ``default_rng([seed, step])``, so a scan is reproducible. A closed loop passes the step of
   the first scan taken from the scanner's station (:class:`Stations`): scans from one station
   share one error field, scans from a new one get their own.

**What a scan costs on a closed loop.** A scan is a sweep of :data:`SCAN_S` seconds taken
after the machines stop: the observation after a step comes :data:`SCAN_S` of plan time after
its actions end, and the next actions start no earlier (:func:`scan_seconds`). The first scan
(the one an open-loop plan is made on too) is taken before the clock starts. And a scan's error
is not white noise that fresh sweeps average away: a lidar's or a stereo rig's error on a
patch of ground is mostly set by where the sensor stands (range, incidence, calibration,
mixed returns at edges), so repeated sweeps from one station repeat it. Here every scan from
within :data:`STATION_M` of an earlier scan's position repeats that scan's error field exactly;
scanning the site again from elsewhere costs the drive there and the sweep, as it does on site.

Heights are rounded to 1e-9 m so that a scan is the same on every machine.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .soil import nominal
from .world import Heightmap, Pose, Scenario, Sensing

#: Rays cast around the sensor (a quarter of a degree apart).
RAYS = 1440
#: Plan seconds one scan after a closed-loop step takes: one sweep of a machine-mounted scanner
#: building a dense map of the site (a nodding or spinning lidar accumulating returns for about a
#: second; module docstring).
SCAN_S = 1.0
#: A scan from within this distance (m) of an earlier scan's position is taken from the same
#: station, and repeats that scan's error field.
STATION_M = 1.0


def scan_seconds(truth: Scenario) -> float:
    """Plan seconds between a closed-loop step's last action and its observation: :data:`SCAN_S`
    when the scenario is scanned (a ``sensing`` section), 0 when the planner sees the truth."""
    return SCAN_S if truth.sensing is not None else 0.0


class Stations:
    """The scan positions of one closed loop: each scan's noise step is the step of the first
    scan taken within :data:`STATION_M` of it (the initial pose is step 0's station)."""

    def __init__(self) -> None:
        self.seen: list[tuple[float, float, int]] = []

    def noise_step(self, pose: Pose, step: int) -> int:
        """The step whose error field a scan from ``pose`` at ``step`` repeats (``step`` itself at a new station)."""
        for x, y, first in self.seen:
            if math.hypot(pose.x - x, pose.y - y) <= STATION_M:
                return first
        self.seen.append((pose.x, pose.y, step))
        return step


def visible_cells(terrain: Heightmap, sensor: tuple[float, float, float], outside_level: float) -> np.ndarray:
    """Boolean mask ``[ny, nx]`` of the cells whose top is in line of sight from ``sensor``
    ``(x, y, z)`` (the module docstring, step 1)."""
    return _sight(terrain, sensor, outside_level)[0]


def _sight(terrain: Heightmap, sensor: tuple[float, float, float], outside_level: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`visible_cells` and the height of the line of sight over each cell (a hidden cell
    lies below it)."""
    z = terrain.z
    ny, nx = z.shape
    r = terrain.resolution
    xs, ys = terrain.cell_centres()
    sx, sy, sz = sensor
    dx, dy = xs[None, :] - sx, ys[:, None] - sy
    dist = np.hypot(dx, dy)
    d_ray = 2 * math.pi / RAYS
    ray = np.rint(np.arctan2(dy, dx) / d_ray).astype(np.int64)
    if terrain.contains(sx, sy):
        ray %= RAYS
        first, n_rays = 0, RAYS
    else:  # the map lies in a sector of less than a half-turn: cast only the rays that cross it
        mid = int(np.rint(math.atan2(ys.mean() - sy, xs.mean() - sx) / d_ray))
        ray = (ray - mid + RAYS // 2) % RAYS - RAYS // 2 + mid
        first, n_rays = int(ray.min()), int(ray.max() - ray.min()) + 1
    step = r
    n_r = int(math.ceil(float(dist.max()) / step)) + 1
    theta = (first + np.arange(n_rays)) * d_ray
    radii = (np.arange(n_r) + 0.5) * step
    px = sx + np.cos(theta)[:, None] * radii[None, :]
    py = sy + np.sin(theta)[:, None] * radii[None, :]
    # the map with a border of open ground: a sample off the map reads the border
    i = np.clip(np.floor((px - terrain.origin[0]) / r), -1, nx).astype(np.int64) + 1
    j = np.clip(np.floor((py - terrain.origin[1]) / r), -1, ny).astype(np.int64) + 1
    h = np.pad(z, 1, constant_values=outside_level)[j, i]
    slope = np.maximum.accumulate((h - sz) / radii[None, :], axis=1)
    nearer = np.floor((dist - r) / step - 0.5).astype(np.int64)  # last sample more than a cell nearer
    blocked = np.where(nearer >= 0, slope[ray - first, np.clip(nearer, 0, n_r - 1)], -np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        own = np.where(dist > 0, (z - sz) / dist, np.inf)
    return own >= blocked - 1e-12, sz + blocked * dist


def scan(truth: Scenario, sensing: Sensing, pose: Pose, step: int = 0) -> Heightmap:
    """The heightmap the sensor delivers from ``pose`` (the module docstring, steps 1–4)."""
    terrain = truth.terrain
    z = terrain.z
    if sensing.occlusion:
        ground = terrain.height_at(pose.x, pose.y) if terrain.contains(pose.x, pose.y) else truth.outside_level
        seen, sight = _sight(terrain, (pose.x, pose.y, ground + sensing.sensor_height), truth.outside_level)
    else:
        seen, sight = np.ones(z.shape, dtype=bool), np.full(z.shape, np.inf)
    k = 1 if sensing.cell_size is None else int(round(sensing.cell_size / terrain.resolution))
    ny, nx = z.shape[0] // k, z.shape[1] // k
    zs = np.where(seen, z, 0.0)[: ny * k, : nx * k].reshape(ny, k, nx, k).sum(axis=(1, 3))
    count = seen[: ny * k, : nx * k].reshape(ny, k, nx, k).sum(axis=(1, 3))
    hit = count > 0
    out = np.full((ny, nx), truth.outside_level)
    if hit.any():
        out[hit] = zs[hit] / count[hit]
        if not hit.all():
            from scipy.ndimage import distance_transform_edt

            _, (jj, ii) = distance_transform_edt(~hit, return_indices=True)
            cap = sight[: ny * k, : nx * k].reshape(ny, k, nx, k).min(axis=(1, 3))
            out = np.where(hit, out, np.minimum(out[jj, ii], cap))
    rng = np.random.default_rng([sensing.seed, int(step)])
    out = out + sensing.bias + (rng.normal(0.0, sensing.noise, out.shape) if sensing.noise > 0 else 0.0)
    return Heightmap(terrain.origin, terrain.resolution * k, np.round(out, 9))


#: The id every observation carries: a machine on site is not told which benchmark scenario it
#: stands in (docs/sealed-evaluation.md). The truth keeps its id for the store and the board.
ANONYMOUS_ID = "site"


def observe(truth: Scenario, *, pose: Pose | None = None, step: int = 0, stations: Stations | None = None) -> Scenario:
    """The planner's view of ``truth``: its terrain replaced by the scan of its ``sensing``
    section taken from ``pose`` (default: the working machine's initial pose), its soil by the
    material's nominal values (:func:`earthbench.soil.nominal`), and no ``sensing`` section.

    Every view is anonymous, on the exact track too: its id is :data:`ANONYMOUS_ID` and its
    ``meta`` is empty (the id and ``meta`` name the suite, family, generator and seed that made
    the truth; with them, a planner could regenerate the hidden world). ``step`` is mixed into
    the noise's seed; a closed loop passes its step count and its ``stations``, so that a scan
    from a station already scanned from repeats that scan's error (the module docstring).
    """
    changes: dict = {"id": ANONYMOUS_ID, "meta": {}}
    if truth.soil is None and truth.sensing is None:
        return dataclasses.replace(truth, **changes)
    changes["sensing"] = None
    if truth.soil is not None:
        changes["soil"] = nominal(truth.soil.material, truth.machines.machine_class)
    if truth.sensing is not None:
        where = pose if pose is not None else truth.machines.pose(truth.worker)
        changes["terrain"] = scan(truth, truth.sensing, where, step if stations is None else stations.noise_step(where, step))
    return dataclasses.replace(truth, **changes)
