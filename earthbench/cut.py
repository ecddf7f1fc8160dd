"""The referee's cut model, public so that planners can predict exactly what a dig removes.

A backhoe stroke (:func:`apply_cut`) and a loader charge (:func:`charge_cut`) lower the cells
whose centre lies in the bucket's path to a flat cut level, in path order, until the bucket is
full; the cell that fills it is lowered only partly and the rest stays in place. The referee
judges with exactly these functions; :func:`cut_along` also says how far along the path the
bucket filled, which the loader's ``overfill`` rule needs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from shapely.geometry import Polygon

from .world import Heightmap, LoaderSpec


@dataclass(frozen=True)
class Cut:
    """What one cut did: the bank volume removed, and ``full_at`` — the distance along the path
    of the cell that filled the bucket (``None``: the bucket did not fill)."""

    volume: float
    full_at: float | None = None


def footprint(contact: tuple[float, float], heading: float, width: float, length: float) -> Polygon:
    """The bucket's rectangle: ``length`` from the contact along ``heading``, ``width`` across."""
    cx, cy = contact
    ux, uy = math.cos(heading), math.sin(heading)
    vx, vy = -uy * width / 2, ux * width / 2
    ex, ey = cx + ux * length, cy + uy * length
    return Polygon([(cx + vx, cy + vy), (ex + vx, ey + vy), (ex - vx, ey - vy), (cx - vx, cy - vy)])


def apply_cut(
    terrain: Heightmap,
    z: np.ndarray,
    contact: tuple[float, float],
    heading: float,
    width: float,
    length: float,
    level: float,
    capacity: float,
) -> float:
    """Cut ``z`` in place down to ``level`` inside the footprint, in drag order, up to capacity.

    Cells whose centre lies in the footprint are lowered to ``level`` one after another along
    the drag; the cell that reaches ``capacity`` is lowered only partly, and the rest stays in
    place. Returns the removed bank volume (m³).
    """
    return cut_along(terrain, z, contact, heading, width, length, level, capacity).volume


def cut_along(
    terrain: Heightmap,
    z: np.ndarray,
    contact: tuple[float, float],
    heading: float,
    width: float,
    length: float,
    level: float | np.ndarray,
    capacity: float,
    cells: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    apply: bool = True,
) -> Cut:
    """:func:`apply_cut`, also telling where along the path the bucket filled; ``cells`` is
    :func:`path_cells` of the same path when the caller already has it. ``level`` may also be
    an array, one level per path cell (the referee's soil: a harder layer, ``earthbench.soil``).
    With ``apply`` False, ``z`` is left as it is: the same answer, for a prediction."""
    if capacity <= 0:
        return Cut(0.0, 0.0)
    r = terrain.resolution
    jj, ii, dist = path_cells(terrain, z.shape, contact, heading, width, length) if cells is None else cells
    heights = z[jj, ii]
    got, full, part = cut_heights(heights, dist, level, capacity, r * r)
    if apply:
        n = full + (part > 0)
        z[jj[:n], ii[:n]] = lowered(heights, level, full, part)
    return got


def cut_heights(
    heights: np.ndarray, dist: np.ndarray, level: float | np.ndarray, capacity: float, cell_area: float
) -> tuple[Cut, int, float]:
    """The cut model on the heights of a path's cells (path order, ``dist`` along it), changing
    nothing: the :class:`Cut`, how many leading cells are lowered to ``level`` whole, and by how
    much the next one is lowered (0.0: none). :func:`cut_along` applies it to a grid; the referee
    with soil applies it to heights it has already read (docs/DESIGN.md §5)."""
    if capacity <= 0:
        return Cut(0.0, 0.0), 0, 0.0
    if heights.size == 0:
        return Cut(0.0), 0, 0.0
    total = (np.maximum(heights - level, 0.0) * cell_area).cumsum()
    full = int(total.searchsorted(capacity, side="right"))
    removed = float(total[full - 1]) if full else 0.0
    if full < heights.size and removed < capacity:
        return Cut(capacity, float(dist[full])), full, (capacity - removed) / cell_area
    if full and removed >= capacity:
        return Cut(removed, float(dist[full - 1])), full, 0.0
    return Cut(removed), full, 0.0


def lowered(heights: np.ndarray, level: float | np.ndarray, full: int, part: float) -> np.ndarray:
    """The new heights of the cells a :func:`cut_heights` answer lowers (its first ``full``, to
    ``level``, and the next by ``part`` when ``part`` > 0), from the path's ``heights`` before it."""
    n = full + (part > 0)
    levels = np.asarray(level)
    now = np.minimum(heights[:n], levels if levels.ndim == 0 else levels[:n])
    if part:
        now[full] = heights[full] - part
    return now


def path_cells(
    terrain: Heightmap, shape: tuple[int, ...], contact: tuple[float, float], heading: float, width: float, length: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Row and column indices of the cells whose centre lies in the bucket's path, in path
    order, with each centre's distance along the path."""
    r = terrain.resolution
    x0, y0 = terrain.origin
    cx, cy = contact
    ux, uy = math.cos(heading), math.sin(heading)
    half = width / 2
    rows, cols = path_window(terrain, shape, contact, heading, width, length)
    j0, j1, i0, i1 = rows.start, rows.stop, cols.start, cols.stop
    empty = np.zeros(0, dtype=int)
    if i0 >= i1 or j0 >= j1:
        return empty, empty, np.zeros(0)
    px = x0 + (np.arange(i0, i1) + 0.5) * r - cx
    py = y0 + (np.arange(j0, j1) + 0.5) * r - cy
    along = py[:, None] * uy + px[None, :] * ux
    across = py[:, None] * ux - px[None, :] * uy
    inside = (along >= 0) & (along <= length) & (np.abs(across) <= half)
    jj, ii = np.nonzero(inside)
    order = np.argsort(along[jj, ii], kind="stable")
    return jj[order] + j0, ii[order] + i0, along[jj, ii][order]


def path_window(
    terrain: Heightmap, shape: tuple[int, ...], contact: tuple[float, float], heading: float, width: float, length: float
) -> tuple[slice, slice]:
    """The rows and columns of the grid that hold every cell of :func:`path_cells`: all a cut
    along this path can change (the replay viewer compares only these, not the whole map)."""
    r = terrain.resolution
    x0, y0 = terrain.origin
    cx, cy = contact
    xs = (cx, cx + math.cos(heading) * length)
    ys = (cy, cy + math.sin(heading) * length)
    pad = width / 2 + r
    i0 = max(int(math.floor((min(xs) - pad - x0) / r)), 0)
    i1 = min(int(math.ceil((max(xs) + pad - x0) / r)), shape[1])
    j0 = max(int(math.floor((min(ys) - pad - y0) / r)), 0)
    j1 = min(int(math.ceil((max(ys) + pad - y0) / r)), shape[0])
    return slice(j0, max(j1, j0)), slice(i0, max(i1, i0))


def charge_cut(
    terrain: Heightmap,
    z: np.ndarray,
    spec: LoaderSpec,
    entry: tuple[float, float, float],
    penetration: float,
    level: float,
    capacity: float,
) -> float:
    """:func:`charge_along`'s removed volume (m³)."""
    return charge_along(terrain, z, spec, entry, penetration, level, capacity).volume


def charge_along(
    terrain: Heightmap,
    z: np.ndarray,
    spec: LoaderSpec,
    entry: tuple[float, float, float],
    penetration: float,
    level: float,
    capacity: float,
    apply: bool = True,
) -> Cut:
    """Cut ``z`` in place along a charge from ``entry`` (the loader's pose) and return the volume.

    The cutting edge starts ``spec.bucket_offset`` ahead of the pose and sweeps ``penetration``
    metres along the heading; the cells whose centre lies in that ``bucket_width`` wide path are
    lowered to ``level`` in path order until ``capacity`` is reached (the last cell partly),
    exactly as :func:`apply_cut` does for a backhoe drag (``apply`` False: a prediction only).
    """
    x, y, yaw = entry
    edge = (x + spec.bucket_offset * math.cos(yaw), y + spec.bucket_offset * math.sin(yaw))
    return cut_along(terrain, z, edge, yaw, spec.bucket_width, penetration, level, capacity, apply=apply)


def cut_level(terrain: Heightmap, z: np.ndarray, contact: tuple[float, float], depth: float) -> float:
    """The flat cut level of a dig: the current height at the contact minus the depth."""
    return terrain.height_at(contact[0], contact[1], z) - depth
