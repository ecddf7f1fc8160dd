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


def nominal(material: str) -> Soil:
    """The class's nominal soil: the middle of each range (what a planner may assume)."""
    m = _material(material, "soil")
    mid = [(a + b) / 2 for a, b in (m.fill_loose, m.swell, m.repose_deg, m.hard_depth)]
    return Soil(material, round(mid[0] / mid[1], 6), round(mid[1], 6), round(mid[2], 6), round(mid[3], 6), m.hard_penetration)


def draw(spec: dict[str, Any], seed: int, where: str = "soil") -> Soil:
    """A site's true soil: ``spec["material"]``'s ranges sampled with ``seed`` (any other key
    of ``spec`` — a field of :class:`~earthbench.world.Soil` — fixes that value instead).

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
    pick = [a + f * (b - a) for f, (a, b) in zip(u, (m.fill_loose, m.swell, m.repose_deg, m.hard_depth))]
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


def cut_levels(soil: Soil, z0: np.ndarray, z: np.ndarray, jj: np.ndarray, ii: np.ndarray, level: float) -> np.ndarray | float:
    """The level each path cell ``(jj, ii)`` is really cut to: ``level``, but no deeper than
    ``hard_penetration`` into the harder layer (its top lies ``hard_depth`` below the initial
    heights ``z0``; a cell already in it gives way by that much below its current height)."""
    if soil.hard_depth is None:
        return level
    top = z0[jj, ii] - soil.hard_depth
    return np.maximum(level, np.minimum(z[jj, ii], top) - soil.hard_penetration)


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
    return slump_cells(z, resolution, repose_deg, js + j0, is_ + i0, lost[js, is_], (j0, j1, i0, i1))


def slump_cells(z: np.ndarray, resolution: float, repose_deg: float, jj: np.ndarray, ii: np.ndarray,
                lost: np.ndarray, box: tuple[int, int, int, int]) -> float:
    """:func:`slump` with the channel given as its cells: the distinct cells ``(jj, ii)`` of
    ``box`` that the cut lowered, by ``lost`` (each > 1e-12 m). The referee knows them (the
    bucket's path cells), so it need not compare the whole box before and after the cut; the
    result is bit for bit :func:`slump`'s (docs/DESIGN.md §5, "Speed with soil")."""
    j0, j1, i0, i1 = box
    if jj.size == 0 or jj.size == (j1 - j0) * (i1 - i0):
        return 0.0
    from scipy.ndimage import distance_transform_edt  # only once a cut happened

    slope = math.tan(math.radians(repose_deg))
    run = float(lost.max()) / slope  # how far from the channel a face can reach
    pad = int(math.ceil(run / resolution)) + 1
    cj0, ci0 = max(int(jj.min()) - pad, j0), max(int(ii.min()) - pad, i0)
    cj1, ci1 = min(int(jj.max()) + pad + 1, j1), min(int(ii.max()) + pad + 1, i1)
    sub = z[cj0:cj1, ci0:ci1]  # a view: what changes lands in ``z``
    channel = np.zeros(sub.shape, dtype=bool)
    channel[jj - cj0, ii - ci0] = True
    outside = ~channel
    dist = distance_transform_edt(outside) * resolution
    floor = sub[channel]
    rise_all = slope * dist
    band = outside & (dist <= run + 1e-9) & (sub - rise_all > floor.min())  # only cells above the lowest possible slope can fall
    walls = sub[band]
    if walls.size == 0:
        return 0.0
    rise = rise_all[band]
    level = _balance(walls - rise, floor)
    cut_back = np.minimum(walls, level + rise)
    fallen = float((walls - cut_back).sum())
    if fallen <= 0.0:
        return 0.0
    fill = np.maximum(level - floor, 0.0)
    total = float(fill.sum())
    fill = fill * (fallen / total) if total > 0 else np.full(floor.shape, fallen / floor.size)
    sub[band] = cut_back
    sub[channel] = floor + fill
    return fallen * resolution * resolution


def _balance(tops: np.ndarray, floor: np.ndarray) -> float:
    """The level ``L`` at which ``Σ max(tops − L, 0) = Σ max(L − floor, 0)``.

    The left side falls and the right side grows with ``L``, both piecewise linear with kinks
    at the given heights: evaluate the difference at every kink at once (sorted prefix sums),
    then solve the one linear piece that changes sign.
    """
    t, f = np.sort(tops), np.sort(floor)
    kinks = np.sort(np.concatenate([t, f]))
    ct = np.concatenate([[0.0], np.cumsum(t[::-1])])  # sum of the k largest tops
    cf = np.concatenate([[0.0], np.cumsum(f)])  # sum of the k smallest floor heights
    above = len(t) - np.searchsorted(t, kinks, side="right")  # tops above each kink
    below = np.searchsorted(f, kinks, side="right")  # floor cells at or below each kink
    g = (ct[above] - above * kinks) - (below * kinks - cf[below])
    k = int(np.searchsorted(-g, 0.0, side="left"))  # first kink where the balance is ≤ 0
    if k == 0:
        return float(kinks[0])
    if k >= len(kinks):
        return float(kinks[-1])
    # between kinks k-1 and k the balance is linear: g(L) = g[k-1] - (above + below) (L - kink)
    n = above[k - 1] + below[k - 1]
    return float(kinks[k - 1] + g[k - 1] / n) if n else float(kinks[k])


def slump_box(
    shape: tuple[int, ...], jj: np.ndarray, ii: np.ndarray, resolution: float, depth: float, repose_deg: float
) -> tuple[int, int, int, int]:
    """The cells a cut at ``(jj, ii)`` up to ``depth`` deep can disturb, as a box ``(j0, j1, i0,
    i1)``: their bounding box grown by the run of a repose slope over that depth, plus two cells."""
    pad = int(math.ceil(depth / math.tan(math.radians(repose_deg)) / resolution)) + 2
    return (max(int(jj.min()) - pad, 0), min(int(jj.max()) + pad + 1, shape[0]),
            max(int(ii.min()) - pad, 0), min(int(ii.max()) + pad + 1, shape[1]))
