"""How far a scan misplaces the ground, and the truck poses its ground check lets through that the
true map forbids (planners/stl_tamp/NOTES.md, "0.12.0"; ``planners/stability.face_blur``).

    python scripts/scan_stands_audit.py [KEYFILE]   # the public standard-realistic draw, or a sealed one

For each family of the draw (its first scenario): the scan's σ and cell, the quantiles over its
cells of the least radius (m) whose envelope of the scan (lowest and highest heights within it)
holds the true block's heights within 3σ; and, for the cab scans of ``bench-realistic``, the truck
poses on a 0.2 m grid (4 headings) that stl-tamp's conversion accepts on the scan but that break
the truck's limits on the truth, with 0 to 6 scan cells of margin (``FACE_CELLS``).
"""

from __future__ import annotations

import sys

import numpy as np

import earthbench_planners.stability as stability
from earthbench.results.suite import load_suite, open_sealed
from earthbench.rules import truck_ground
from earthbench.seal import SealKey
from earthbench.sensing import observe
from earthbench_planners.stl_tamp.convert import Converter, SimState


def needed_radius(truth, scan) -> np.ndarray:
    z, r = scan.terrain.z, scan.terrain.resolution
    k = int(round(r / truth.terrain.resolution))
    blocks = truth.terrain.z[: z.shape[0] * k, : z.shape[1] * k].reshape(z.shape[0], k, z.shape[1], k)
    hi_true, lo_true = blocks.max(axis=(1, 3)), blocks.min(axis=(1, 3))
    sigma = stability.noise_sigma(z)
    need = np.full(z.shape, np.inf)
    for cells in range(11):
        lo, hi = stability.envelope(z, cells)
        ok = (hi_true <= hi + 3 * sigma) & (lo_true >= lo - 3 * sigma)
        need = np.where(ok & np.isinf(need), cells * r, need)
    return need


def forbidden_poses(truth, scan, cells: int) -> tuple[int, int]:
    st = SimState.start(scan)
    x0, x1, y0, y1 = truth.terrain.extent
    xs, ys, yaws = np.meshgrid(np.arange(x0 - 2, x1 + 2, 0.2), np.arange(y0 - 2, y1 + 2, 0.2), np.radians([0, 45, 90, 135]))
    poses = np.column_stack([xs.ravel(), ys.ravel(), yaws.ravel()])
    t = truth.machines.truck
    grade, cross, step = truck_ground(truth, truth.terrain.z, t, poses)
    broken = (grade > t.max_grade) | (cross > t.max_cross_slope) | (step > t.max_step)
    stability.FACE_CELLS = cells
    kept = Converter(scan, eta_on=0.25, min_dig_volume=0.02, depth=0.4, keep_soil=True).stands(st).ground_ok(poses)
    return int(kept.sum()), int(np.sum(kept & broken))


def main() -> None:
    suite = load_suite("standard-realistic")
    if len(sys.argv) > 1:
        suite = open_sealed(suite, SealKey.read(sys.argv[1]))
    seen = set()
    default = stability.FACE_CELLS
    for truth in suite.scenarios:
        fam = truth.meta["family"]
        if fam in seen:
            continue
        seen.add(fam)
        scan = observe(truth)
        need = needed_radius(truth, scan)
        q = np.quantile(np.where(np.isinf(need), 99.0, need), [0.99, 0.999, 1.0])
        line = (f"{fam:45s} sigma {stability.noise_sigma(scan.terrain.z):.3f} cell {scan.terrain.resolution:.2f} "
                f"radius q99 {q[0]:.2f} q99.9 {q[1]:.2f} max {q[2]:.2f}")
        if fam.startswith("bench-realistic") and fam.endswith("cab"):
            line += " | forbidden poses let through: " + " ".join(f"{c} cells {forbidden_poses(truth, scan, c)[1]}" for c in range(7))
        stability.FACE_CELLS = default
        print(line, flush=True)


if __name__ == "__main__":
    main()
