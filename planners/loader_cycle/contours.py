"""The pile as a loader planner sees it: its zero contour (:func:`zero_contour`), the side a
heading meets (:func:`pile_side`) and the volumes in boxes along the contour (:func:`box_volumes`)."""

from __future__ import annotations

import numpy as np

from earthbench.rules import cell_heights
from earthbench.world import Heightmap


def zero_contour(terrain: Heightmap, z: np.ndarray, level: float, spacing: float, min_length: float) -> list[np.ndarray]:
    """Polylines (k × 2) of ``z = level``, resampled every ``spacing`` m, at least ``min_length`` long."""
    import contourpy

    xs, ys = terrain.cell_centres()
    gen = contourpy.contour_generator(xs, ys, z, line_type=contourpy.LineType.Separate)
    out = []
    for line in gen.lines(level):
        line = np.asarray(line, dtype=float)
        seg = np.hypot(*np.diff(line, axis=0).T)
        length = float(seg.sum())
        if len(line) < 2 or length < min_length:
            continue
        s = np.concatenate([[0.0], np.cumsum(seg)])
        q = np.arange(0.0, length + 1e-9, spacing)
        out.append(np.stack([np.interp(q, s, line[:, 0]), np.interp(q, s, line[:, 1])], axis=1))
    return out


def pile_side(terrain: Heightmap, z: np.ndarray, M: np.ndarray, n: np.ndarray, base: float) -> np.ndarray:
    """±1 per candidate: the side of ``M`` along the unit normal ``n`` where the material lies."""
    offs = np.array([0.3, 0.8, 1.5])
    across = np.array([-0.5, 0.0, 0.5])
    t = np.stack([-n[:, 1], n[:, 0]], axis=1)
    side = np.zeros(len(M))
    for sign in (1.0, -1.0):
        pts = (
            M[:, None, None, :] + sign * offs[None, :, None, None] * n[:, None, None, :] + across[None, None, :, None] * t[:, None, None, :]
        )
        h = cell_heights(terrain, z, pts.reshape(-1, 2)).reshape(len(M), -1)
        side += sign * np.nansum(np.clip(h - base, 0.0, None), axis=1)
    return np.where(side >= 0, 1.0, -1.0)


def box_volumes(
    terrain: Heightmap, z: np.ndarray, M: np.ndarray, h: np.ndarray, width: float, behind: float, ahead: float, base: float
) -> tuple[np.ndarray, np.ndarray]:
    """Material above ``base`` in the left and right halves of the box ``width`` wide from
    ``behind`` metres behind to ``ahead`` metres ahead of each ``M`` along ``h`` (vectorised)."""
    d = terrain.resolution / 2
    a = np.arange(-behind + d / 2, ahead, d)
    c = np.arange(-width / 2 + d / 2, width / 2, d)
    left = np.stack([-h[:, 1], h[:, 0]], axis=1)
    pts = M[:, None, None, :] + a[None, :, None, None] * h[:, None, None, :] + c[None, None, :, None] * left[:, None, None, :]
    hts = cell_heights(terrain, z, pts.reshape(-1, 2)).reshape(len(M), len(a), len(c))
    vol = np.nan_to_num(np.clip(hts - base, 0.0, None)) * d * d
    half = len(c) // 2
    return vol[:, :, half:].sum(axis=(1, 2)), vol[:, :, :half].sum(axis=(1, 2))
