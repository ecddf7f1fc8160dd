"""The ground as a loader planner reads it (docs/realistic.md): a scan's noise estimated from the
scan itself, smoothed in proportion, the floor's offset taken off (:func:`read_scan`); exact
terrain comes back as it is."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from earthbench.world import Heightmap


#: Below this estimated σ (m) a grid is taken as exact: left as it is, no smoothing, no margins.
EXACT_NOISE = 0.002


@dataclass(frozen=True)
class GroundModel:
    """The planner's ground (:func:`read_scan`): heights ``z`` with the floor's offset removed,
    the estimated noise ``noise`` of a scanned cell (σ, m), the smoothed grid's σ ``smooth_noise``,
    the contour ``level`` above the floor and the height ``margin`` the step checks keep."""

    z: np.ndarray
    noise: float
    smooth_noise: float
    offset: float
    level: float
    margin: float


def scan_noise(z: np.ndarray) -> float:
    """σ of a cell's independent error, estimated from the grid alone: the second differences
    along rows and columns (``z[i-1] − 2 z[i] + z[i+1]``, variance 6σ² for white noise, 0 on
    planes and on the pile's straight slopes), their spread by the median absolute deviation,
    which the few cells at the pile's edges do not move."""
    if min(z.shape) < 3:
        return 0.0
    d = np.concatenate([(z[:, :-2] - 2 * z[:, 1:-1] + z[:, 2:]).ravel(), (z[:-2, :] - 2 * z[1:-1, :] + z[2:, :]).ravel()])
    mad = float(np.median(np.abs(d - np.median(d))))
    return 1.4826 * mad / math.sqrt(6.0)


def read_scan(terrain: Heightmap, floor: float, contour_level: float) -> GroundModel:
    """The ground a loader plans on, from the grid it is given.

    A scan's σ is estimated (:func:`scan_noise`); below :data:`EXACT_NOISE` the grid is
    returned unchanged with ``contour_level``. Otherwise the grid is smoothed with a Gaussian of
    ``s = clip(σ / 0.02, 0.75, 2)`` cells (a σ/(2√π s) error is left per cell), the floor's offset
    is the median of the open ground (cells within a few σ of the floor, twice), the contour
    level is the larger of ``contour_level`` and 5 smoothed σ above the floor, and every cell
    below that level is the floor: a scan's noise and bias no longer read as material, and the
    loader's step checks keep 3 smoothed σ plus half the offset as a margin for what the scan
    cannot tell."""
    z = np.asarray(terrain.z, dtype=float)
    noise = scan_noise(z)
    if noise < EXACT_NOISE:
        return GroundModel(np.array(z), noise, noise, 0.0, contour_level, 0.0)
    from scipy.ndimage import gaussian_filter

    s = min(max(noise / 0.02, 0.75), 2.0)
    zs = gaussian_filter(z, s, mode="nearest")
    sn = noise / (2 * math.sqrt(math.pi) * s)
    offset = 0.0
    for width in (0.05 + 5 * noise, 0.01 + 5 * sn):
        band = np.abs(zs - floor - offset) <= width
        if band.sum() < 0.05 * zs.size:  # hardly any open ground: no offset can be measured
            break
        offset = float(np.median(zs[band])) - floor
    zs -= offset
    level = max(contour_level, 5 * sn)
    zs[zs < floor + level] = floor
    return GroundModel(zs, noise, sn, offset, level, 3 * sn + abs(offset) / 2)
