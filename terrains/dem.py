"""``dem``: real terrain — crops of the USGS elevation model that ships with matplotlib.

The data is ``matplotlib.cbook.get_sample_data("jacksboro_fault_dem.npz")``: 344 × 403
integer elevations in metres (236–1076 m) on a 3-arc-second grid over the Jacksboro fault,
Tennessee (about 74.5 m east–west × 92.6 m north–south per cell at 36.6° N; the spherical
approximation 111.32 km per degree is used). Row 0 of the file is the northern edge, so the
rows are flipped to put y north, as in the heightmap.

A crop is a real landscape shrunk onto the site: ``ground_scale`` metres of ground per
metre of site (default 100, so a 12 m × 6 m site shows 1.2 km × 0.6 km of Tennessee), its
corner drawn with the seed, resampled bicubically to the site's cell centres and then scaled
so its relief (max − min) is exactly ``relief`` metres, with the lowest cell at z = 0.
The default relief of 1.5 m matches the mounds of the ``rbf`` maps (peaks of 1.0–2.3 m with
14 bases), so the same machines and targets apply. Because the source heights are whole
metres, crops whose ground relief is under ``min_ground_relief`` (default 60 m, i.e. a
quantisation step of at most 2.5 cm after scaling) are skipped: the next draw of the same
seeded generator is taken, so the choice stays deterministic.

The site is set up as the STL-TAMP paper's: the whole map is the dig area, the floor
(design grade) is z = 0, the excavator starts at (lx + 1.0, ly + 1.2), yaw π, and the truck at
(2.0, ly + 7.0), yaw 0.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy.ndimage import map_coordinates

from earthbench.errors import ScenarioError
from earthbench.world import Budget, Heightmap, Scenario

from .common import backhoe_site, rectangle, round_heights

SAMPLE_DEM = "jacksboro_fault_dem.npz"
_M_PER_DEGREE = 111_320.0
_MAX_DRAWS = 1000


@functools.lru_cache(maxsize=1)
def sample_dem() -> tuple[np.ndarray, float, float, float, float]:
    """(elevation[row south → north, col west → east] in m, cell dx and dy in m, west lon, south lat)."""
    from matplotlib import cbook

    with cbook.get_sample_data(SAMPLE_DEM) as d:
        elev = np.flipud(np.asarray(d["elevation"], dtype=np.float64))
        lat_n, lat_s = float(d["ymin"]), float(d["ymax"])  # the file labels its north edge "ymin"
        dlon, dlat, west = float(d["dx"]), float(d["dy"]), float(d["xmin"])
    south, north = min(lat_n, lat_s), max(lat_n, lat_s)
    lat_mid = math.radians(0.5 * (south + north))
    dx = dlon * _M_PER_DEGREE * math.cos(lat_mid)
    dy = dlat * _M_PER_DEGREE
    elev = np.ascontiguousarray(elev)
    elev.setflags(write=False)
    return elev, dx, dy, west, south


def dem_crop(
    seed: int,
    *,
    size: tuple[float, float] = (12.0, 6.0),
    resolution: float = 0.05,
    ground_scale: float = 100.0,
    relief: float = 1.5,
    min_ground_relief: float = 60.0,
) -> tuple[Heightmap, dict]:
    """The heightmap of one crop and where it came from (corner lon/lat, ground relief)."""
    elev, dx, dy, west, south = sample_dem()
    lx, ly = float(size[0]), float(size[1])
    if ground_scale <= 0 or relief <= 0:
        raise ScenarioError(f"dem: ground_scale and relief must be positive, got {ground_scale}, {relief}")
    nrow, ncol = elev.shape
    span_c, span_r = lx * ground_scale / dx, ly * ground_scale / dy  # crop size in DEM cells
    if span_c > ncol - 2 or span_r > nrow - 2:
        raise ScenarioError(
            f"dem: a {lx:g} × {ly:g} m site at ground_scale {ground_scale:g} needs "
            f"{span_c:.0f} × {span_r:.0f} DEM cells; the sample has {ncol} × {nrow}. Lower ground_scale."
        )
    nx, ny = int(round(lx / resolution)), int(round(ly / resolution))
    xs = (np.arange(nx) + 0.5) * resolution * ground_scale / dx
    ys = (np.arange(ny) + 0.5) * resolution * ground_scale / dy
    rng = np.random.default_rng(seed)
    for _ in range(_MAX_DRAWS):
        c0 = rng.uniform(0.0, ncol - 1 - span_c)
        r0 = rng.uniform(0.0, nrow - 1 - span_r)
        rows, cols = np.meshgrid(r0 + ys, c0 + xs, indexing="ij")
        ground = map_coordinates(elev, [rows, cols], order=3, mode="nearest")
        lo, hi = float(ground.min()), float(ground.max())
        if hi - lo >= min_ground_relief:
            break
    else:
        raise ScenarioError(f"dem: no crop with {min_ground_relief:g} m of ground relief in {_MAX_DRAWS} draws; lower min_ground_relief")
    z = round_heights((ground - lo) * (relief / (hi - lo)))
    source = {
        "source": "matplotlib sample data " + SAMPLE_DEM + " (USGS)",
        "corner_lon": round(west + c0 * dx / (_M_PER_DEGREE * math.cos(math.radians(south))), 6),
        "corner_lat": round(south + r0 * dy / _M_PER_DEGREE, 6),
        "ground_relief_m": round(hi - lo, 2),
    }
    return Heightmap((0.0, 0.0), resolution, z), source


def dem(
    seed: int,
    target_volume: float = 4.0,
    *,
    size: tuple[float, float] = (12.0, 6.0),
    resolution: float = 0.05,
    ground_scale: float = 100.0,
    relief: float = 1.5,
    min_ground_relief: float = 60.0,
    excavator: tuple[float, float, float] | None = None,
    truck: tuple[float, float, float] | None = None,
    truck_capacity: float = 10.0,
    budget: Budget | None = None,
    scenario_id: str | None = None,
) -> Scenario:
    """Real terrain: a crop of matplotlib's USGS sample DEM on the paper's site and poses.

    Parameters:

    - ``size``, ``resolution``: site extent (m, origin (0, 0)) and cell size (m).
    - ``ground_scale``: metres of real ground per metre of site (default 100).
    - ``relief``: max − min height of the site after scaling (m); the lowest cell is z = 0.
    - ``min_ground_relief``: skip crops flatter than this on the ground (m), see the module doc.
    - ``excavator``, ``truck``: initial poses (x, y, yaw); default the paper's corner offsets.
    - ``truck_capacity``: m³.
    """
    lx, ly = float(size[0]), float(size[1])
    terrain, source = dem_crop(
        seed, size=(lx, ly), resolution=resolution, ground_scale=ground_scale, relief=relief, min_ground_relief=min_ground_relief
    )
    meta = {"generator": "dem", "seed": seed, "size": [lx, ly], "resolution": resolution, "ground_scale": ground_scale,
            "relief": relief, **source}
    return backhoe_site(scenario_id or f"dem-{lx:g}x{ly:g}-s{seed}-v{target_volume:g}", terrain,
                        dig_area=rectangle(0.0, 0.0, lx, ly), target_volume=target_volume, corner=(0.0, lx, ly),
                        excavator=excavator, truck=truck, truck_capacity=truck_capacity, budget=budget, meta=meta)
