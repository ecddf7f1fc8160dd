"""Soil: how the ground really answers a dig, known to the referee only (docs/DESIGN.md §3, §5).

A scenario's :class:`~earthbench.world.Soil` section holds one site's true values; a planner is
told only the material class (:func:`earthbench.sensing.observe` replaces the section by
:func:`nominal`). Four effects separate the world from the planner's model:

- **Fill factor.** A full stroke holds ``fill_factor × bucket_capacity`` bank m³, not
  ``bucket_capacity``. Equipment handbooks (for instance the bucket fill-factor tables for
  hydraulic excavators and wheel loaders in manufacturers' performance handbooks) give the
  fill factor as the fraction of the rated heaped capacity a bucket really carries, in loose
  volume: roughly 0.95–1.10 for sand and gravel, 1.00–1.15 for moist loam or sandy clay and
  0.85–1.00 for hard, tough clay. The world model counts bank volume, so a site's bank fill
  factor is the handbook figure divided by the swell: :func:`draw` does that division.
- **Swell.** Loose ÷ bank volume; the truck's ``capacity`` counts loose m³, so it holds
  ``capacity / swell`` bank m³. Typical swell from the same handbooks' material tables and from
  construction-estimating texts: about 10–15 % for sand and gravel, 20–30 % for common earth
  (loam), 25–35 % for clay.
- **Angle of repose.** Loose soil stands at about 30–35° (dry sand), 35–40° (moist loam) and
  35–45° (cohesive clay). After each cut, :func:`slump` collapses the faces the cut left
  steeper than that back to the repose slope and levels what fell in the cut's floor (natural,
  undisturbed ground away from the cut keeps its shape: cohesion holds a bank steeper than
  loose soil's repose).
- **A harder layer** ``hard_depth`` below the initial surface (weathered topsoil over firmer
  subsoil): one stroke penetrates it by at most ``hard_penetration`` m (:func:`cut_levels`).

The values in :data:`MATERIALS` are ranges of that kind, rounded; :func:`draw` picks a site's
true values uniformly within its class's ranges from a seed, so every suite scenario is
reproducible and the planner's nominal values (:func:`nominal`, the middle of each range) are
wrong by a seeded amount.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .classes import DEFAULT_CLASS, machine_class as _class_named
from .errors import ScenarioError
from .world import Soil


@dataclass(frozen=True)
class Material:
    """A material class: ranges ``(lo, hi)`` of the handbook fill factor (loose), the swell,
    the angle of repose (degrees) and the harder layer's depth (m), and the penetration per
    stroke into that layer (m)."""

    fill_loose: tuple[float, float]
    swell: tuple[float, float]
    repose_deg: tuple[float, float]
    hard_depth: tuple[float, float]
    hard_penetration: float


MATERIALS: dict[str, Material] = {
    "sand": Material(fill_loose=(0.95, 1.10), swell=(1.10, 1.15), repose_deg=(30.0, 35.0), hard_depth=(0.6, 1.0), hard_penetration=0.25),
    "loam": Material(fill_loose=(1.00, 1.15), swell=(1.20, 1.30), repose_deg=(35.0, 40.0), hard_depth=(0.5, 0.9), hard_penetration=0.15),
    "clay": Material(fill_loose=(0.85, 1.00), swell=(1.25, 1.35), repose_deg=(35.0, 45.0), hard_depth=(0.4, 0.8), hard_penetration=0.10),
}


def _material(name: Any, where: str) -> Material:
    if name not in MATERIALS:
        raise ScenarioError(f"{where}.material must be one of {', '.join(MATERIALS)}, got {name!r:.40}")
    return MATERIALS[name]


def _fill_loose(m: Material, material: str, machines: str) -> tuple[float, float]:
    """The handbook fill factor's range of ``material`` for the buckets of the machine class
    ``machines`` (its ``fill_loose`` table, docs/machine-classes.md; else the material's)."""
    if machines == DEFAULT_CLASS:
        return m.fill_loose
    return _class_named(machines).fill_loose.get(material, m.fill_loose)


def nominal(material: str, machines: str = DEFAULT_CLASS) -> Soil:
    """The class's nominal soil: the middle of each range (what a planner may assume); the
    fill factor's for the buckets of the machine class ``machines``."""
    m = _material(material, "soil")
    fill = _fill_loose(m, material, machines)
    mid = [(a + b) / 2 for a, b in (fill, m.swell, m.repose_deg, m.hard_depth)]
    return Soil(material, round(mid[0] / mid[1], 6), round(mid[1], 6), round(mid[2], 6), round(mid[3], 6), m.hard_penetration)


def fill_range(material: str, machines: str = DEFAULT_CLASS) -> tuple[float, float]:
    """The least and the most bank m³ a full bucket of ``material`` can hold per m³ of capacity
    on a site :func:`draw` makes for the machine class ``machines``: the handbook fill factor's
    ends over the swell's other ends. What a planner may bound a load by (it knows the class)."""
    m = _material(material, "soil")
    lo, hi = _fill_loose(m, material, machines)
    return lo / m.swell[1], hi / m.swell[0]


def draw(spec: dict[str, Any], seed: int, where: str = "soil", machines: str = DEFAULT_CLASS) -> Soil:
    """A site's true soil: ``spec["material"]``'s ranges sampled with ``seed`` (any other key
    of ``spec`` — a field of :class:`~earthbench.world.Soil` — fixes that value instead), the
    fill factor's range that of the machine class ``machines``' buckets.

    Values are rounded to 1e-6 so that a seed gives the same scenario digest everywhere.
    """
    if not isinstance(spec, dict):
        raise ScenarioError(f"{where} must be a table with a material, got {spec!r:.40}")
    m = _material(spec.get("material"), where)
    fields = {"material", "fill_factor", "swell", "repose_deg", "hard_depth", "hard_penetration"}
    for key in spec:
        if key not in fields:
            raise ScenarioError(f"{where}.{key} is unknown; the fields of soil: {', '.join(sorted(fields))}")
    u = np.random.default_rng([int(seed), 0x5011]).uniform(size=4)
    fill = _fill_loose(m, spec["material"], machines)
    pick = [a + f * (b - a) for f, (a, b) in zip(u, (fill, m.swell, m.repose_deg, m.hard_depth))]
    values: dict[str, Any] = {
        "material": spec["material"],
        "fill_factor": round(pick[0] / pick[1], 6),
        "swell": round(pick[1], 6),
        "repose_deg": round(pick[2], 6),
        "hard_depth": round(pick[3], 6),
        "hard_penetration": m.hard_penetration,
    }
    values.update({k: v for k, v in spec.items() if k != "material"})
    try:
        return Soil(**values)
    except ScenarioError as exc:
        raise ScenarioError(str(exc).replace("scenario field soil.", f"{where}.")) from None


def hard_top(soil: Soil, z0: np.ndarray) -> np.ndarray | None:
    """The top of the harder layer under every cell: ``hard_depth`` below the initial heights
    ``z0`` (None: the soil has no such layer). The referee reads it once per replay."""
    return None if soil.hard_depth is None else np.asarray(z0) - soil.hard_depth


def cut_levels(soil: Soil, top: np.ndarray | None, heights: np.ndarray, level: float) -> np.ndarray | float:
    """The level each path cell is really cut to, given its current ``heights`` and ``top``, the
    harder layer's top under it (:func:`hard_top` at the cells; None: no layer): ``level``, but
    no deeper than ``hard_penetration`` into the layer (a cell already in it gives way by that
    much below its current height)."""
    if top is None:
        return level
    return np.maximum(level, np.minimum(heights, top) - soil.hard_penetration)


def slump(z: np.ndarray, resolution: float, repose_deg: float, before: np.ndarray,
          box: tuple[int, int, int, int] | None = None) -> float:
    """Collapse the faces a cut left steeper than ``repose_deg``, in place; returns the volume
    (m³) that slid. ``before`` holds the heights of ``box`` (``(j0, j1, i0, i1)``; the whole
    grid when None) before the cut, ``z`` the grid after it.

    The cut cells (lower now than before) form the channel; its depth ``D`` is the most any of
    them lost. Every other cell of the box within ``D / tan(repose)`` of the channel is cut back
    to the repose slope rising from the channel's new floor ``L`` (``L + tan(repose) × its
    distance to the nearest channel cell``), and what it loses fills the channel's cells up to
    ``L``. ``L`` is the one level at which what falls equals what fills (:func:`_balance`); the
    fill is then scaled to the fallen volume exactly, so the box's volume is conserved to rounding
    and no cell outside the box, or farther from the channel than the run of the slope, changes.
    Ground the cut did not steepen stays as it was: natural, undisturbed bank may stand steeper
    than loose soil; so does ground beyond the run ``D / tan(repose)`` that rises faster than the
    slope beside the cut (docs/DESIGN.md §5).
    """
    j0, j1, i0, i1 = box if box is not None else (0, z.shape[0], 0, z.shape[1])
    lost = before - z[j0:j1, i0:i1]
    js, is_ = np.nonzero(lost > 1e-12)
    if js.size == 0 or js.size == lost.size:
        return 0.0
    drop = float(lost[js, is_].max())
    pad = reach_cells(drop, resolution, repose_deg)  # the window: the channel's bounding box grown by the run
    window = (max(int(js.min()) - pad, 0) + j0, min(int(js.max()) + pad + 1, j1 - j0) + j0,
              max(int(is_.min()) - pad, 0) + i0, min(int(is_.max()) + pad + 1, i1 - i0) + i0)
    return slump_cells(z, resolution, repose_deg, js + j0, is_ + i0, drop, window)


def slump_cells(z: np.ndarray, resolution: float, repose_deg: float, jj: np.ndarray, ii: np.ndarray,
                drop: float, window: tuple[int, int, int, int]) -> float:
    """:func:`slump` with the channel given as its cells: the distinct cells ``(jj, ii)`` that
    the cut lowered (each by more than 1e-12 m, ``drop`` the most), and ``window`` ``(j0, j1,
    i0, i1)``, the box the slump stays in, holding the channel (:func:`slump_box` with ``drop``;
    growing it beyond the run ``drop / tan(repose)`` of the channel changes nothing). The
    referee knows the channel (the bucket's path cells), so it need not compare heights before
    and after the cut.

    One distance transform gives every window cell's nearest channel cell; the rest works on
    flat indices into a copy of the window, which is cheaper than masks (docs/DESIGN.md §5,
    "Speed with soil").
    """
    j0, j1, i0, i1 = window
    h, w = j1 - j0, i1 - i0
    if jj.size == 0 or jj.size == h * w:
        return 0.0
    from scipy.ndimage import distance_transform_edt  # only once a cut happened

    slope = math.tan(math.radians(repose_deg))
    sub = z[j0:j1, i0:i1].copy()
    flat = sub.ravel()
    channel = jj * w + ii
    channel -= j0 * w + i0
    outside = np.empty(h * w, dtype=bool)
    outside.fill(True)
    outside[channel] = False
    # the nearest channel cell of every window cell, then the squared distance to it (cells²)
    near_j, near_i = distance_transform_edt(outside.reshape(h, w), return_distances=False, return_indices=True)
    near_j -= np.arange(h, dtype=near_j.dtype)[:, None]
    near_i -= np.arange(w, dtype=near_i.dtype)
    near_j *= near_j
    near_i *= near_i
    near_j += near_i
    d2 = near_j.ravel()
    rise_all = np.sqrt(d2)
    rise_all *= slope * resolution  # the repose slope's rise from the channel
    floor = flat[channel]
    tops_all = flat - rise_all
    reach = (drop / slope + 1e-9) / resolution  # how far from the channel a face can reach (cells)
    # only cells within the run and above the lowest possible slope can fall
    band = ((d2 <= reach * reach) & (tops_all > np.minimum.reduce(floor)) & outside).nonzero()[0]
    if band.size == 0:
        return 0.0
    walls, rise = flat[band], rise_all[band]
    level = _balance(tops_all[band], floor)
    cut_back = np.minimum(walls, level + rise)
    fallen = float(np.add.reduce(walls - cut_back))
    if fallen <= 0.0:
        return 0.0
    fill = level - floor
    np.maximum(fill, 0.0, out=fill)
    total = float(np.add.reduce(fill))
    if total > 0:
        fill *= fallen / total
    else:
        fill[:] = fallen / floor.size
    fill += floor
    flat[band] = cut_back
    flat[channel] = fill
    z[j0:j1, i0:i1] = sub
    return fallen * resolution * resolution


def reach_cells(drop: float, resolution: float, repose_deg: float) -> int:
    """How many cells from a channel ``drop`` m deep a face can slump: the run of the repose
    slope over that depth, plus one cell."""
    return int(math.ceil(drop / math.tan(math.radians(repose_deg)) / resolution)) + 1


def _balance(tops: np.ndarray, floor: np.ndarray) -> float:
    """The level ``L`` at which ``Σ max(tops − L, 0) = Σ max(L − floor, 0)``; some top must lie
    above the lowest floor height. Sorts ``tops`` in place.

    Both sides are piecewise linear in ``L`` and their difference ``g`` falls strictly above
    that height. First the floor cells below ``L``: all of them when ``g`` at the highest is
    still ≥ 0 (the usual case: the fill covers the channel's floor), else those where ``g`` > 0
    (sorted floor, prefix sums). With their number ``b`` and sum fixed, the tops above ``L``
    are those where ``g`` < 0 (sorted tops, prefix sums), and ``L`` solves the one linear piece:
    (their sum + the floor cells' sum) / (their number + ``b``).
    """
    t = tops
    t.sort()
    nt, nf = t.size, floor.size
    ct = np.empty(nt + 1)
    ct[0] = 0.0
    t.cumsum(out=ct[1:])  # ct[k]: the sum of the k lowest tops
    high = float(np.maximum.reduce(floor))
    k = int(t.searchsorted(high, side="right"))
    below = float(np.add.reduce(floor))
    if (ct[nt] - ct[k]) - (nt - k) * high >= nf * high - below:
        b = nf
    else:
        f = np.sort(floor)
        cf = np.empty(nf + 1)
        cf[0] = 0.0
        f.cumsum(out=cf[1:])
        above = t.searchsorted(f, side="right")
        g = (ct[nt] - ct[above]) - (nt - above) * f - (np.arange(1, nf + 1) * f - cf[1:])
        b = int(np.count_nonzero(g > 0))
        below = float(cf[b])
    # g at each top t[k] with b floor cells below: the tops above it less (b + those) × t[k]
    a = int(np.count_nonzero((ct[nt] - ct[1:]) - np.arange(nt - 1 + b, b - 1, -1) * t + below < 0))
    return float((ct[nt] - ct[nt - a] + below) / (a + b))


def slump_box(
    shape: tuple[int, ...], jj: np.ndarray, ii: np.ndarray, resolution: float, depth: float, repose_deg: float,
    drop: float | None = None,
) -> tuple[int, int, int, int]:
    """The cells a cut at ``(jj, ii)`` up to ``depth`` deep can disturb, as a box ``(j0, j1, i0,
    i1)``: their bounding box grown by the run of a repose slope over that depth, plus two cells.
    With ``drop``, the most the cut really lowered a cell, the box grows no further than
    :func:`reach_cells` of it: the window :func:`slump_cells` needs."""
    pad = int(math.ceil(depth / math.tan(math.radians(repose_deg)) / resolution)) + 2
    if drop is not None:
        pad = min(pad, reach_cells(drop, resolution, repose_deg))
    lo, hi = np.minimum.reduce, np.maximum.reduce  # no Python wrappers: the referee calls this per dig
    return (max(int(lo(jj)) - pad, 0), min(int(hi(jj)) + pad + 1, shape[0]),
            max(int(lo(ii)) - pad, 0), min(int(hi(ii)) + pad + 1, shape[1]))
