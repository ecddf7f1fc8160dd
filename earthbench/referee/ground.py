"""The ground under a cut: what a dig or charge really removes (the public cut model of
:mod:`earthbench.cut`, or on a scenario with soil its truth: fill factor, harder layer, slump,
docs/realistic.md), and that it leaves the truck's ground as it was (``truck_undercut``)."""

from __future__ import annotations

import numpy as np

from ..cut import Cut, cut_along, cut_heights, lowered
from ..motion import ABS_TOL
from ..soil import cut_levels, slump_box, slump_cells
from .site import Stands
from .state import Replay, Stroke, Violation


def cut(r: Replay, stroke: Stroke) -> tuple[Cut, Cut | None]:
    """Cut the grid along a stroke or charge into a bucket of ``stroke.capacity`` that
    already holds ``r.bucket``; returns the cut and, with soil, the nominal one.

    Without soil this is :func:`~earthbench.cut.cut_along`. With soil the bucket really
    holds ``fill_factor × bucket_capacity`` bank m³, the harder layer limits the level
    (:func:`~earthbench.soil.cut_levels`), and :func:`settle` must follow once the rules
    that look at the fresh cut have been checked; the nominal cut is what the public cut
    model does to the same ground (:func:`~earthbench.cut.cut_heights` on the heights read
    once for both).
    """
    contact, heading, width, length, level, cells = stroke.contact, stroke.heading, stroke.width, stroke.length, stroke.level, stroke.cells
    depth = stroke.depth
    budget = stroke.capacity - r.bucket
    if r.soil is None:
        return cut_along(r.terrain, r.z, contact, heading, width, length, level, budget, cells), None
    jj, ii, along = cells
    area = r.terrain.resolution * r.terrain.resolution
    heights = r.z[jj, ii]
    nominal = cut_heights(heights, along, level, budget, area)[0]
    levels = cut_levels(r.soil, None if r.hard_top is None else r.hard_top[jj, ii], heights, level)
    real, full, part = cut_heights(heights, along, levels, r.soil.fill_factor * stroke.capacity - r.bucket, area)
    n = full + (part > 0)  # the cells this cut lowers, in path order
    if n:
        was, now = heights[:n], lowered(heights, levels, full, part)
        cj, ci = jj[:n], ii[:n]
        r.z[cj, ci] = now
        lost = was - now
        hit = lost > 1e-12
        if depth is None:  # the highest face the cut can leave
            depth = float(np.max(heights - level, initial=0.0))
        drop = float(np.maximum.reduce(lost))
        if drop > 1e-12:
            window = slump_box(r.z.shape, jj, ii, r.terrain.resolution, depth, r.soil.repose_deg, drop)
            r.unsettled = (window, cj[hit], ci[hit], drop)
        if r.firm is not None:  # the firm ground is never above the heights: only cut cells change
            r.firm[cj, ci] = np.minimum(r.firm[cj, ci], now)
    return real, nominal


def settle(r: Replay, n: int, stands: Stands) -> None:
    """Slump the faces the last cut left steeper than the soil's angle of repose; then
    ``truck_undercut``: no cell the truck stood on (``stands``) is lower than before the cut."""
    if r.soil is not None and r.unsettled is not None:
        (j0, j1, i0, i1), jj, ii, drop = r.unsettled
        slump_cells(r.z, r.terrain.resolution, r.soil.repose_deg, jj, ii, drop, (j0, j1, i0, i1))
        if r.firm is not None:  # what fell is loose: the firm ground only ever goes down
            np.minimum(r.firm[j0:j1, i0:i1], r.z[j0:j1, i0:i1], out=r.firm[j0:j1, i0:i1])
    r.unsettled = None
    (tj, ti), before = stands
    if tj.size == 0:
        return
    sunk = float(np.max(before - r.z[tj, ti]))
    if sunk > ABS_TOL:
        r.violations.append(Violation(n, "truck_undercut", sunk, f"the cut lowers the ground under the truck by {sunk:.3f} m"))
