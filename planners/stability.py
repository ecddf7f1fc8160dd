"""Margins for the scan's error in the stability rules a backhoe planner checks (undermining, tilt).

The referee judges ``undermining`` and ``tilt`` on the true ground (docs/DESIGN.md §5), while a
planner on the realistic track checks them on a scan. Trusting the scan as exact breaks them:
the lowest scanned cell under the tracks lies about ``√(2 ln N)·σ`` below the true lowest one
(the least of ``N`` noisy cells), so the planner's undermining line is too low, and the cut
level it plans from the scanned contact height is off by about σ as well. ``greedy`` and
``singh-cannon-backhoe`` keep the margins of :func:`margins` (their ``scan_margin`` setting).

The scan is not the only error. An open-loop plan cuts its own copy of the ground, and the truth
drifts from it: the cut faces slump (:func:`cut_and_slump` models it), and the harder layer and
the site's fill make a stroke stop elsewhere along its drag than the planner's model says, so a
cut planned to stop short of the tracks may reach on toward them (:func:`path_undermines` checks
the whole drag on the realistic track). A scan also misplaces faces (:func:`face_blur`): ``stl-tamp`` keeps the truck's ground on the
scan's envelope (:func:`envelope`) so that its wheels stay off a bank the scan shows elsewhere.

The scan's σ is not told to a planner (the observation has no ``sensing`` section), so it is
estimated from the scan itself (:func:`noise_sigma`). A scenario without soil is the exact
track, where the planner sees the truth: no margin, and its plans are what they were.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from earthbench.cut import apply_cut, cut_along, path_window
from earthbench.rules import undermining_excess
from earthbench.soil import MATERIALS, slump
from earthbench.world import ExcavatorSpec, Pose, Scenario

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


def cut_and_slump(sc: Scenario, z: np.ndarray, stroke: Stroke, slumps: bool) -> float:
    """Apply ``stroke``'s cut to the planner's grid ``z`` (the public cut model; returns its
    volume); with ``slumps`` (a cut below the tracks' ground) on the realistic track, the faces it
    leaves then slump to the class's gentlest angle of repose (:func:`earthbench.soil.slump`, the
    referee's model): the lowest the true ground can have settled to, so the next cut level read
    near it is not above the one the referee will read."""
    e: ExcavatorSpec = sc.machines.excavator  # type: ignore[assignment]
    rows, cols = path_window(sc.terrain, z.shape, stroke.contact, stroke.heading, e.bucket_width, stroke.drag)
    if not slumps or sc.soil is None:
        return apply_cut(sc.terrain, z, stroke.contact, stroke.heading, e.bucket_width, stroke.drag, stroke.level, stroke.capacity)
    repose = _least_repose(sc)
    pad = int(math.ceil((2 * e.max_cut_depth + e.max_drag_length) / math.tan(math.radians(repose)) / sc.terrain.resolution)) + 2
    box = (max(rows.start - pad, 0), min(rows.stop + pad, z.shape[0]), max(cols.start - pad, 0), min(cols.stop + pad, z.shape[1]))
    before = z[box[0]:box[1], box[2]:box[3]].copy()
    vol = apply_cut(sc.terrain, z, stroke.contact, stroke.heading, e.bucket_width, stroke.drag, stroke.level, stroke.capacity)
    slump(z, sc.terrain.resolution, repose, before, box)
    return vol


def _least_repose(sc: Scenario) -> float:
    assert sc.soil is not None
    known = MATERIALS.get(sc.soil.material)
    return known.repose_deg[0] if known is not None else sc.soil.repose_deg


def path_undermines(sc: Scenario, z: np.ndarray, base: Pose, track_level: float, stroke: Stroke, margin: float) -> bool:
    """Whether ``stroke`` may break the referee's undermining rule (by more than ``-margin``):
    on the exact track the cut the public model makes, on the realistic track every cell of the
    drag above the level cut to it — the true bucket may fill later along the drag than the
    planner's model (a harder layer cuts each cell less, the site's fill is not the model's).
    ``z`` is cut for the check and put back."""
    e: ExcavatorSpec = sc.machines.excavator  # type: ignore[assignment]
    jj, ii, _ = stroke.cells
    before = z[jj, ii].copy()
    if sc.soil is None:
        cut_along(sc.terrain, z, stroke.contact, stroke.heading, e.bucket_width, stroke.drag, stroke.level, stroke.capacity,
                  stroke.cells)
    else:
        z[jj, ii] = np.minimum(before, stroke.lowest)
    cut = z[jj, ii] < before
    excess = undermining_excess(sc.terrain, z, e, base, track_level, jj[cut], ii[cut])
    z[jj, ii] = before
    return excess > -max(1e-6, margin)


@dataclass(frozen=True)
class Stroke:
    """A stroke as :func:`path_undermines` checks it and :func:`cut_and_slump` cuts it: ``cells``
    are its :func:`earthbench.cut.path_cells` (rows, columns, distance along; only the check reads
    them), ``lowest`` the lowest level its cut may really reach (the floor: the grade control)."""

    contact: tuple[float, float]
    heading: float
    drag: float
    level: float
    capacity: float
    cells: tuple[np.ndarray, np.ndarray, np.ndarray]
    lowest: float


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
