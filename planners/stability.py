"""Margins for the scan's error in the stability rules a backhoe planner checks (undermining, tilt).

The referee judges ``undermining`` and ``tilt`` on the true ground (docs/DESIGN.md §5), while a
planner on the realistic track checks them on a scan. Trusting the scan as exact breaks them:
the lowest scanned cell under the tracks lies about ``√(2 ln N)·σ`` below the true lowest one
(the least of ``N`` noisy cells), so the planner's undermining line is too low, and the cut
level it plans from the scanned contact height is off by about σ as well. ``greedy`` and
``singh-cannon-backhoe`` keep the margins of :func:`margins` (their ``scan_margin`` setting).

A scan also misplaces faces (:func:`face_blur`): ``stl-tamp`` keeps the truck's ground on the
scan's envelope (:func:`envelope`) so that its wheels stay off a bank the scan shows elsewhere.

The scan's σ is not told to a planner (the observation has no ``sensing`` section), so it is
estimated from the scan itself (:func:`noise_sigma`). A scenario without soil is the exact
track, where the planner sees the truth: no margin, and its plans are what they were.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from earthbench.world import ExcavatorSpec, Scenario

#: The tilt margin (rad) both planners always kept below ``max_tilt`` on exact ground.
TILT_MARGIN = 0.01


def noise_sigma(z: np.ndarray) -> float:
    """σ (m) of independent per-cell noise on the heightmap ``z``, estimated robustly.

    The 3 × 3 mask ``[1 −2 1]ᵀ[1 −2 1]`` (Immerkær, "Fast noise variance estimation", 1996) is
    zero on any ground that varies along one axis only (a plane, an axis-aligned face or edge)
    and nearly zero on smooth mounds, and turns independent noise of σ into a spread of 6σ; the
    median absolute response (÷ 0.6745 for a Gaussian) ignores the few cells on edges and corners.
    """
    z = np.asarray(z, dtype=float)
    if z.shape[0] < 3 or z.shape[1] < 3:
        return 0.0
    d2x = z[:, :-2] - 2 * z[:, 1:-1] + z[:, 2:]
    m = d2x[:-2] - 2 * d2x[1:-1] + d2x[2:]
    return float(np.median(np.abs(m)) / 0.6745 / 6.0)


@dataclass(frozen=True)
class Margins:
    """What a planner keeps clear of the referee's limits: metres above the undermining line,
    radians below ``max_tilt``."""

    undermining: float
    tilt: float


def margins(sc: Scenario, setting: float | None = None) -> Margins:
    """The margins for the observation ``sc``; ``setting`` (m) overrides the undermining one.

    Undermining: ``(√(2 ln N) + 2)·σ`` — the least of the ``N`` scanned cells under the tracks
    lies that first term below the truth, the planned cut level up to 2σ (the interpolated
    contact height) — plus ``undermine_slope × r / 2`` for the scan's cells of size ``r``, whose
    centres can lie half a cell farther from the tracks than the true cells they average.
    Tilt: :data:`TILT_MARGIN` plus three standard errors of the slope of a plane fitted to the
    ``N`` noisy cells. Both are 0 and :data:`TILT_MARGIN` on the exact track (no soil).
    """
    e: ExcavatorSpec = sc.machines.excavator  # type: ignore[assignment]
    r = sc.terrain.resolution
    n = max(int(round(e.track_length / r)) * int(round(e.track_width / r)), 2)
    sigma = noise_sigma(sc.terrain.z) if sc.soil is not None else 0.0
    if setting is not None:
        under = max(float(setting), 0.0)
    elif sc.soil is None:
        under = 0.0
    else:
        under = (math.sqrt(2 * math.log(n)) + 2.0) * sigma + e.undermine_slope * r / 2
    # the slope of a least-squares plane over a rectangle of side L sampled n times: σ·√12 / (√n·L)
    slope_se = sigma * math.sqrt(12.0) / (math.sqrt(n) * min(e.track_length, e.track_width))
    return Margins(under, TILT_MARGIN + 3.0 * slope_se)


#: Scan cells by which a scan may misplace a steep face (:func:`face_blur`; 0.4 m on a cab's 0.1 m cells).
FACE_CELLS = 4


def face_blur(sc: Scenario) -> float:
    """Metres by which the observation ``sc`` may misplace a steep face (a bank, a cut's wall):
    :data:`FACE_CELLS` of its own cells on a scanned site, 0 on the exact track (no soil).

    A scan averages the ground over its cells and fills an occluded face's foot from the nearest
    ground it saw (``earthbench.sensing``), so a face can stand cells away from where the scan
    shows it, whatever the noise σ. A truck's ground checked on the scan's envelope over this
    distance (:func:`envelope`) keeps its wheels off such a face: on the 15 `bench-realistic` cab
    scans of the public and the four published sealed draws, 3 cells still let through truck
    poses the true map forbids on 3 scans, 4 cells none (planners/stl_tamp/NOTES.md, "0.12.0").
    """
    return FACE_CELLS * sc.terrain.resolution if sc.soil is not None else 0.0


def envelope(z: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """The lowest and the highest height of the grid ``z`` within ``radius`` cells of each cell
    (a disc; the grid's edge repeated beyond it)."""
    from scipy import ndimage

    r = int(math.ceil(radius))
    dy, dx = np.mgrid[-r:r + 1, -r:r + 1]
    disc = dx * dx + dy * dy <= radius * radius + 1e-9
    return ndimage.grey_erosion(z, footprint=disc, mode="nearest"), ndimage.grey_dilation(z, footprint=disc, mode="nearest")
