"""``file``: a user's own heightmap (``.npy``, ``.npz``, CSV grid or GeoTIFF) as a scenario.

Row convention, the same for every format: ``z[j, i]`` is the cell at column ``i`` (east) and
row ``j`` (north), so the *first* row of the file is the *southern* edge at ``origin[1]``,
exactly as ``numpy.save(z)`` / ``numpy.savetxt(z, delimiter=",")`` write an earthbench
heightmap. Heights are metres. The cell size and origin are not in ``.npy`` and CSV files,
so they are parameters; a ``.npz`` may carry them as arrays ``resolution`` and ``origin``
(parameters given explicitly win). The height array of a ``.npz`` is ``z`` (or, failing that,
``elevation`` or ``heights``, or its only array).

Registered as the terrain generator ``file``, so a suite family or the CLI can use it:
``earthbench plan --terrain file --param path='"site.csv"' --param resolution=0.1``. The seed is
ignored (a file is one terrain); the target is checked against the volume above the floor.

A GeoTIFF (``.tif``/``.tiff``: a drone survey's or a lidar tile's digital elevation model) is
read with rasterio, an optional extra (``pip install 'earthbench[geotiff]'``). Its cell size,
origin and no-data cells come from the file; its CRS must be projected, in metres (a
geographic CRS in degrees, or feet, is refused: reproject it, e.g. to its UTM zone). Band 1
holds the heights, row 0 its northern edge (the file is flipped to earthbench's south-first
rows). ``bounds = [xmin, ymin, xmax, ymax]`` (metres, in the file's CRS) reads a window of a
larger tile; ``resolution`` different from the file's cell size resamples it, and then
``resampling`` must say how (``nearest``, ``bilinear``, ``cubic``, ``average``): nothing is
resampled silently. A no-data cell inside the area read is an error that counts them.
"""

from __future__ import annotations

import math
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from earthbench.errors import ScenarioError
from earthbench.world import Budget, Heightmap, Scenario

from .common import backhoe_site, rectangle, round_heights

FORMATS = (".npy", ".npz", ".csv", ".tif", ".tiff")
GEOTIFF = (".tif", ".tiff")
#: Resampling methods a GeoTIFF may be read with (rasterio.enums.Resampling names).
RESAMPLING = ("nearest", "bilinear", "cubic", "average")
#: The cell cap of a suite's heightmap (earthbench.results.suite.MAX_CELLS), checked before a GeoTIFF is read.
MAX_CELLS = 4_000_000
_NPZ_KEYS = ("z", "elevation", "heights")


def _read_npz(p: Path) -> tuple[np.ndarray, dict[str, Any]]:
    with np.load(p, allow_pickle=False) as d:
        files = list(d.files)
        if not files:
            raise ScenarioError(f"heightmap file {str(p)!r} is an empty .npz archive; save the heights as array 'z'")
        key = next((k for k in _NPZ_KEYS if k in files), files[0] if len(files) == 1 else None)
        if key is None:
            raise ScenarioError(f"heightmap file {str(p)!r} has arrays {files} but none named {', '.join(_NPZ_KEYS)}; name the heights 'z'")
        extra: dict[str, Any] = {}
        if "resolution" in files:
            extra["resolution"] = float(np.asarray(d["resolution"]).reshape(-1)[0])
        if "origin" in files:
            o = np.asarray(d["origin"], dtype=float).reshape(-1)
            if o.size != 2:
                raise ScenarioError(f"heightmap file {str(p)!r}: 'origin' must hold 2 numbers (x, y), got {o.size}")
            extra["origin"] = (float(o[0]), float(o[1]))
        return np.asarray(d[key]), extra


def _read_csv(p: Path) -> np.ndarray:
    text = p.read_text()
    rows = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not rows:
        raise ScenarioError(f"heightmap file {str(p)!r} holds no rows of numbers")
    delim = "," if "," in rows[0] else None
    out: list[list[float]] = []
    for n, ln in enumerate(rows):
        cells = ln.split(delim)
        try:
            out.append([float(c) if c.strip() else math.nan for c in cells])
        except ValueError as exc:
            raise ScenarioError(
                f"heightmap file {str(p)!r}, data row {n + 1}: {exc}; the CSV must be a grid of numbers without a header"
            ) from None
        if len(out[-1]) != len(out[0]):
            raise ScenarioError(
                f"heightmap file {str(p)!r} is not a rectangular grid: data row {n + 1} has {len(out[-1])} values, row 1 has {len(out[0])}"
            )
    return np.array(out, dtype=np.float64)


def _read_geotiff(p: Path, resolution: float | None, resampling: str | None,
                  bounds: tuple[float, float, float, float] | None) -> tuple[np.ndarray, dict[str, Any]]:
    """Band 1 of a north-up GeoTIFF in a projected CRS in metres, south row first, with its cell size and origin."""
    try:
        import rasterio
        from rasterio.enums import Resampling
        from rasterio.windows import from_bounds
    except ImportError:
        raise ScenarioError(f"heightmap file {str(p)!r} is a GeoTIFF, which needs rasterio: pip install 'earthbench[geotiff]'") from None
    name = repr(str(p))
    try:
        ds = rasterio.open(p)
    except rasterio.errors.RasterioIOError as exc:
        raise ScenarioError(f"heightmap file {name} cannot be read as a GeoTIFF: {exc}") from None
    with ds:
        crs, tf = ds.crs, ds.transform
        if crs is None:
            raise ScenarioError(f"heightmap file {name} has no coordinate reference system; earthbench needs a projected CRS in metres")
        if not crs.is_projected:
            raise ScenarioError(f"heightmap file {name} is in {crs.to_string()}, a geographic CRS (degrees); reproject it to a projected "
                                f"CRS in metres, e.g. its UTM zone (gdalwarp -t_srs EPSG:326NN -r bilinear in.tif out.tif)")
        unit, factor = crs.linear_units_factor
        if abs(factor - 1.0) > 1e-12:
            raise ScenarioError(f"heightmap file {name} is in {crs.to_string()}, whose unit is {unit!r}, not metres; "
                                "reproject it to a projected CRS in metres (gdalwarp -t_srs ...)")
        if tf.b != 0 or tf.d != 0 or tf.a <= 0 or tf.e >= 0:
            raise ScenarioError(f"heightmap file {name} is not north-up (its transform is rotated or flipped); warp it north-up first")
        cell_x, cell_y = tf.a, -tf.e
        left, bottom, right, top = ds.bounds
        if bounds is not None:
            bx0, by0, bx1, by1 = (float(v) for v in bounds)
            if not (left <= bx0 < bx1 <= right and bottom <= by0 < by1 <= top):
                raise ScenarioError(f"heightmap file {name}: bounds {[bx0, by0, bx1, by1]} are not inside the file's "
                                    f"{[left, bottom, right, top]}")
            left, bottom, right, top = bx0, by0, bx1, by1
        if resolution is None:
            if abs(cell_x - cell_y) > 1e-9 * max(cell_x, cell_y):
                raise ScenarioError(f"heightmap file {name} has {cell_x:g} × {cell_y:g} m cells; earthbench's are square: "
                                    f"give resolution=... and resampling=... to resample it")
            res = cell_x
        else:
            res = float(resolution)
            if res <= 0 or not math.isfinite(res):
                raise ScenarioError(f"heightmap file {name}: resolution must be a positive number of metres, got {resolution}")
        cols, rows = int(round((right - left) / res)), int(round((top - bottom) / res))
        if cols < 2 or rows < 2:
            raise ScenarioError(f"heightmap file {name}: {right - left:g} × {top - bottom:g} m at {res:g} m is fewer than 2 × 2 cells")
        if rows * cols > MAX_CELLS:
            raise ScenarioError(f"heightmap file {name}: {right - left:g} × {top - bottom:g} m at {res:g} m is {rows * cols:,} cells, "
                                f"over the limit of {MAX_CELLS:,}; read a window (bounds=[xmin, ymin, xmax, ymax]) or coarser cells")
        same = abs(res - cell_x) <= 1e-9 * res and abs(res - cell_y) <= 1e-9 * res
        if not same and resampling is None:
            raise ScenarioError(f"heightmap file {name} has {cell_x:g} m cells and {res:g} m were asked for: say how to resample "
                                f"it (resampling = one of {', '.join(RESAMPLING)})")
        if resampling is not None and resampling not in RESAMPLING:
            raise ScenarioError(f"heightmap file {name}: unknown resampling {resampling!r}; use one of {', '.join(RESAMPLING)}")
        window = from_bounds(left, bottom, right, top, transform=tf)
        method = Resampling[resampling or "nearest"]
        data = ds.read(1, window=window, out_shape=(rows, cols), resampling=method, masked=True, boundless=False)
        missing = int(np.count_nonzero(np.ma.getmaskarray(data)))
        if missing:
            raise ScenarioError(f"heightmap file {name}: {missing} of {data.size} cells in the area read are no-data; "
                                "read a window without them (bounds=[xmin, ymin, xmax, ymax]) or fill them first (gdal_fillnodata)")
        z = np.asarray(data.filled(np.nan), dtype=np.float64)[::-1]
    return z, {"resolution": res, "origin": (float(left), float(bottom))}


def load_heightmap(
    path: str | Path,
    *,
    resolution: float | None = None,
    origin: tuple[float, float] | None = None,
    resampling: str | None = None,
    bounds: tuple[float, float, float, float] | None = None,
) -> Heightmap:
    """Read a heightmap file; every way it can be unusable is a ScenarioError saying what to do.

    For a GeoTIFF, ``resolution`` is the cell size wanted (default the file's), and ``origin``
    replaces the file's (e.g. ``(0, 0)`` for local coordinates).
    """
    p = Path(path)
    if not p.is_file():
        raise ScenarioError(f"heightmap file {str(p)!r} not found")
    suffix = p.suffix.lower()
    if suffix not in FORMATS:
        raise ScenarioError(f"heightmap file {str(p)!r}: unsupported format {suffix or '(none)'!r}; use one of {', '.join(FORMATS)}")
    if p.stat().st_size == 0:
        raise ScenarioError(f"heightmap file {str(p)!r} is empty")
    extra: dict[str, Any] = {}
    if suffix in GEOTIFF:
        z, extra = _read_geotiff(p, resolution, resampling, bounds)
        resolution = None  # the file's cells, resampled as asked: now in extra
    elif resampling is not None or bounds is not None:
        raise ScenarioError(f"heightmap file {str(p)!r}: resampling and bounds apply to GeoTIFF files only")
    else:
        try:
            if suffix == ".npy":
                z = np.load(p, allow_pickle=False)
            elif suffix == ".npz":
                z, extra = _read_npz(p)
            else:
                z = _read_csv(p)
        except ScenarioError:
            raise
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
            raise ScenarioError(f"heightmap file {str(p)!r} cannot be read as {suffix}: {exc}") from None
    z = np.asarray(z)
    if z.dtype.kind not in "biuf":
        raise ScenarioError(f"heightmap file {str(p)!r} holds {z.dtype} data; heights must be numbers")
    if z.size == 0:
        raise ScenarioError(f"heightmap file {str(p)!r} holds an empty array (shape {z.shape})")
    if z.ndim != 2 or min(z.shape) < 2:
        raise ScenarioError(
            f"heightmap file {str(p)!r} holds an array of shape {z.shape}; a heightmap is a 2-D grid of at least 2 × 2 cells"
        )
    z = z.astype(np.float64)
    bad = int(np.count_nonzero(~np.isfinite(z)))
    if bad:
        what = "only NaN or infinite values" if bad == z.size else f"{bad} NaN or infinite cells of {z.size}"
        raise ScenarioError(f"heightmap file {str(p)!r} holds {what}; fill the gaps (e.g. interpolate) or crop them away")
    res = resolution if resolution is not None else extra.get("resolution")
    if res is None:
        raise ScenarioError(f"heightmap file {str(p)!r}: give the cell size in metres (resolution=...); {suffix} files do not store it")
    org = origin if origin is not None else extra.get("origin", (0.0, 0.0))
    return Heightmap((float(org[0]), float(org[1])), float(res), z)


def heightmap_file(
    seed: int,
    target_volume: float,
    *,
    path: str,
    resolution: float | None = None,
    origin: tuple[float, float] | None = None,
    resampling: str | None = None,
    bounds: list[float] | None = None,
    floor: float | None = None,
    dig_area: list[tuple[float, float]] | None = None,
    excavator: tuple[float, float, float] | None = None,
    truck: tuple[float, float, float] | None = None,
    truck_capacity: float = 10.0,
    budget: Budget | None = None,
    scenario_id: str | None = None,
) -> Scenario:
    """Your own heightmap file (.npy, .npz, CSV grid or GeoTIFF) as a scenario.

    Parameters:

    - ``path``: the ``.npy``/``.npz``/``.csv``/``.tif`` file; ``resolution`` (m) and ``origin``
      (x, y of the lower-left cell corner, default (0, 0); a GeoTIFF's own) as described in the
      module doc; for a GeoTIFF also ``resampling`` and ``bounds``.
    - ``floor``: design grade in m; default the lowest cell of the map.
    - ``dig_area``: polygon [[x, y], ...]; default the whole map.
    - ``excavator``, ``truck``: initial poses (x, y, yaw); default the STL-TAMP paper's offsets
      from the map's corners (east of the map, and north-west of it), as for ``rbf``.
    - ``truck_capacity``: m³. ``seed`` is ignored.
    """
    terrain = load_heightmap(path, resolution=resolution, origin=origin, resampling=resampling,
                             bounds=tuple(bounds) if bounds is not None else None)  # type: ignore[arg-type]
    terrain = terrain.with_z(round_heights(terrain.z))
    xmin, xmax, ymin, ymax = terrain.extent
    return backhoe_site(scenario_id or f"file-{Path(path).stem}-v{target_volume:g}", terrain,
                        dig_area=tuple(dig_area) if dig_area is not None else rectangle(xmin, ymin, xmax, ymax),
                        floor=float(terrain.z.min()) if floor is None else floor, target_volume=target_volume,
                        corner=(xmin, xmax, ymax), excavator=excavator, truck=truck, truck_capacity=truck_capacity,
                        budget=budget, meta={"generator": "file", "path": str(path)})
