"""A charge on the planner's ground: its entry pose (:func:`entry_for`) and the public cut model
run on a copy of the grid (:func:`simulate_charge`), with the soil's class when it has one."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from earthbench.cut import cut_along, path_cells
from earthbench.rules import wheel_step_excess
from earthbench.soil import slump
from earthbench.world import Heightmap, LoaderSpec

from ..truck_load import LoadBound
from .soil_model import SoilModel


def entry_for(
    terrain: Heightmap, z: np.ndarray, spec: LoaderSpec, M: np.ndarray, h: np.ndarray, base: float, reach: float = 3.0, margin: float = 0.05
) -> tuple[float, float, float] | None:
    """The entry pose (front axle) whose cutting edge starts ``margin`` before the first material
    (> 1 cm above ``base``) in the bucket's corridor from ``reach`` behind to ``reach`` ahead of M."""
    r = terrain.resolution
    xs, ys = terrain.cell_centres()
    i0 = max(int((M[0] - reach - spec.bucket_width - terrain.origin[0]) / r), 0)
    i1 = min(int((M[0] + reach + spec.bucket_width - terrain.origin[0]) / r) + 1, len(xs))
    j0 = max(int((M[1] - reach - spec.bucket_width - terrain.origin[1]) / r), 0)
    j1 = min(int((M[1] + reach + spec.bucket_width - terrain.origin[1]) / r) + 1, len(ys))
    px = xs[i0:i1] - M[0]
    py = ys[j0:j1] - M[1]
    along = py[:, None] * h[1] + px[None, :] * h[0]
    across = py[:, None] * h[0] - px[None, :] * h[1]
    mat = (z[j0:j1, i0:i1] > base + 0.01) & (np.abs(across) <= spec.bucket_width / 2 + r) & (np.abs(along) <= reach)
    if not mat.any():
        return None
    a0 = float(along[mat].min()) - margin
    yaw = math.atan2(h[1], h[0])
    off = a0 - spec.bucket_offset
    return (float(M[0] + off * h[0]), float(M[1] + off * h[1]), yaw)


@dataclass(frozen=True)
class ChargeResult:
    """A simulated charge: its penetration, the model's cut volume, the bank volume the truck is
    expected to get (``delivered``: the cut, but no more than the bucket's nominal fill), the
    grid after the cut and its slump (``z``), the firm ground under it (``firm``: what the
    wheels stand on, without what slumped), the loader's pose at the end, and the most the
    truck may really get from it (``most``, :meth:`LoadBound.most`; ``delivered`` on
    exact ground)."""

    penetration: float
    volume: float
    z: np.ndarray
    end: tuple[float, float, float]
    firm: np.ndarray
    delivered: float
    most: float


def charge_model(
    terrain: Heightmap,
    z: np.ndarray,
    firm: np.ndarray,
    spec: LoaderSpec,
    entry: tuple[float, float, float],
    penetration: float,
    level: float,
    capacity: float,
    soil: SoilModel | None,
) -> tuple[float, np.ndarray, np.ndarray]:
    """The planner's charge on copies of ``z`` and ``firm``: the public cut model
    (:func:`earthbench.cut.cut_along` on the bucket's path), with ``soil`` to the harder layer's
    levels (:meth:`SoilModel.levels`), the bucket full at the nominal fill of its
    capacity (the rest of the path is left), and then the faces' slump to the nominal repose
    (:func:`earthbench.soil.slump`). Returns the volume, the settled grid and the firm ground
    (the fresh cut: what slumped is loose)."""
    x, y, yaw = entry
    edge = (x + spec.bucket_offset * math.cos(yaw), y + spec.bucket_offset * math.sin(yaw))
    cells = path_cells(terrain, z.shape, edge, yaw, spec.bucket_width, penetration)
    jj, ii, _ = cells
    lv: float | np.ndarray = level
    if soil is not None and jj.size:
        lv = soil.levels(jj, ii, z[jj, ii], level)
    if soil is not None:  # the bucket fills at its nominal fill: what lies beyond stays where it is
        capacity = min(capacity, soil.fill * spec.bucket_capacity)
    zz = np.array(z)
    vol = cut_along(terrain, zz, edge, yaw, spec.bucket_width, penetration, level if jj.size == 0 else lv, capacity, cells).volume
    new_firm = np.minimum(firm, zz)
    if soil is not None and jj.size and vol > 0:
        # the box the faces can slump in: the path grown by the run of the repose slope over its depth
        depth = float(np.max(z[jj, ii] - level, initial=0.0))
        pad = int(math.ceil(depth / math.tan(math.radians(soil.repose_deg)) / terrain.resolution)) + 2
        box = (max(int(jj.min()) - pad, 0), min(int(jj.max()) + pad + 1, zz.shape[0]),
               max(int(ii.min()) - pad, 0), min(int(ii.max()) + pad + 1, zz.shape[1]))
        j0, j1, i0, i1 = box
        slump(zz, terrain.resolution, soil.repose_deg, np.array(z[j0:j1, i0:i1]), box)
    return vol, zz, new_firm


def simulate_charge(
    terrain: Heightmap,
    z: np.ndarray,
    spec: LoaderSpec,
    entry: tuple[float, float, float],
    capacity: float,
    max_penetration: float,
    level: float,
    base: float,
    firm: np.ndarray | None = None,
    soil: SoilModel | None = None,
    step_base: float | None = None,
    overfill_cap: float = math.inf,
    load: LoadBound | None = None,
) -> ChargeResult | None:
    """The longest penetration (≤ ``max_penetration``) whose bucket path holds ≤ ``capacity`` in
    whole cells (cut to the harder layer's levels with ``soil``, and then no more than
    ``overfill_cap`` of the public cut model to the floor), cut with :func:`charge_model`;
    None when it takes (almost) nothing or the wheels' path over the firm ground after the cut
    would not be traversable with ``step_base`` (default ``base``) as the base level. ``load``
    bounds what it may really deliver (:meth:`LoadBound.most`; without it, the model's volume)."""
    firm = z if firm is None else firm
    x, y, yaw = entry
    ux, uy = math.cos(yaw), math.sin(yaw)
    ex, ey = x + spec.bucket_offset * ux, y + spec.bucket_offset * uy  # as charge_cut computes it
    jj, ii, a = path_cells(terrain, z.shape, (ex, ey), yaw, spec.bucket_width, max_penetration)
    if a.size == 0:
        return None
    h = z[jj, ii]
    lv: float | np.ndarray = level
    if soil is not None:
        lv = soil.levels(jj, ii, h, level)
    r = terrain.resolution
    ex_v = np.maximum(h - lv, 0.0) * r * r
    if ex_v.sum() <= 1e-9:
        return None
    cum = np.cumsum(ex_v)
    last = np.nonzero(ex_v > 0)[0][-1]
    if cum[-1] <= capacity:
        k = last  # everything fits: stop just past the last cell with material
    else:
        k = int(np.searchsorted(cum, capacity, side="right")) - 1
        if k < 0:
            return None
    if soil is not None:
        # the overfill rule reads the public cut model (to the floor, no harder layer) on the
        # true ground: the path may hold no more than ``overfill_cap`` of it
        public = np.cumsum(np.maximum(h - level, 0.0)) * r * r
        k = min(k, int(np.searchsorted(public, overfill_cap, side="right")) - 1)
        if k < 0:
            return None
        while k >= 0 and k + 1 < len(a) and a[k + 1] == a[k]:  # never split a row of equal along
            k -= 1
        if k < 0:
            return None
    pen = float((a[k] + a[k + 1]) / 2) if k + 1 < len(a) else float(max_penetration)
    pen = min(pen, max_penetration)
    if pen < 0.05:
        return None
    vol, zz, new_firm = charge_model(terrain, z, firm, spec, entry, pen, level, capacity, soil)
    if vol < 0.02 * spec.bucket_capacity:
        return None
    end = (x + pen * ux, y + pen * uy, yaw)
    sb = base if step_base is None else step_base
    if wheel_step_excess(terrain, new_firm, spec, np.array([[0.0, x, y, yaw], [1.0, end[0], end[1], yaw]]), sb)[0] > -1e-3:
        return None
    if soil is None:
        return ChargeResult(pen, vol, zz, end, new_firm, vol, vol)
    delivered = min(vol, soil.fill * spec.bucket_capacity)
    most = delivered if load is None else load.most(float(public[k]), spec.bucket_capacity)
    return ChargeResult(pen, vol, zz, end, new_firm, delivered, most)
