"""Fig. 12 of Singh and Cannon, reproduced: the pile's zero contour over the first eight digs.

``python scripts/loader_fig12.py OUT.png [--seed N] [--target V]`` plans the
``singh-cannon-loader`` on ``pile(seed, target)`` (default: seed 3, enough target for eight
buckets), replays the plan with the referee and draws, for each of the first eight charges, a
top view of the zero contour just before it (grey), the bucket's cutting edge at the entry
(red bar) and the path it cuts (red outline), and the contour after it (black). The paper's
caption: "The wheel loader digs perpendicular to the wall, and the bucket is centered on
protrusions".
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from earthbench.plan import Charge, Plan
from earthbench.cut import charge_cut
from earthbench.referee import judge
from earthbench.world import Scenario
from earthbench_planners.loader_cycle import zero_contour
from earthbench_planners.singh_cannon.loader import SinghCannonLoader
from earthbench_terrains.pile import pile


def _contours(sc: Scenario, z: np.ndarray) -> list[np.ndarray]:
    floor = sc.site.floor or 0.0
    return zero_contour(sc.terrain, z, floor + 0.02, 0.05, 0.3)


def draw(sc: Scenario, plan: Plan, out: str, n: int = 8) -> None:
    """Write the n-panel figure of the first ``n`` charges of ``plan`` on ``sc`` to ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    spec = sc.machines.loader
    charges = [a for a in plan.actions if isinstance(a, Charge)][:n]
    z = np.array(sc.terrain.z)
    floor = sc.site.floor or 0.0
    cols = 4
    rows = max(1, math.ceil(len(charges) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 3.0 * rows), squeeze=False)
    xs = [c.entry[0] + spec.bucket_offset * math.cos(c.entry[2]) for c in charges]
    ys = [c.entry[1] + spec.bucket_offset * math.sin(c.entry[2]) for c in charges]
    x0, x1 = min(xs) - 3.0, max(xs) + 3.0
    y0, y1 = min(ys) - 1.5, max(ys) + 3.5
    for k, ax in enumerate(axes.ravel()):
        if k >= len(charges):
            ax.axis("off")
            continue
        c = charges[k]
        for line in _contours(sc, z):
            ax.plot(line[:, 0], line[:, 1], color="0.6", lw=1.0)
        vol = charge_cut(sc.terrain, z, spec, c.entry, c.penetration, floor, spec.bucket_capacity)
        for line in _contours(sc, z):
            ax.plot(line[:, 0], line[:, 1], color="k", lw=1.0)
        x, y, yaw = c.entry
        u = np.array([math.cos(yaw), math.sin(yaw)])
        v = np.array([-u[1], u[0]]) * spec.bucket_width / 2
        e = np.array([x, y]) + spec.bucket_offset * u
        f = e + c.penetration * u
        box = np.array([e + v, f + v, f - v, e - v, e + v])
        ax.plot(box[:, 0], box[:, 1], color="tab:red", lw=0.8)
        ax.plot([e[0] - v[0], e[0] + v[0]], [e[1] - v[1], e[1] + v[1]], color="tab:red", lw=3)
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_aspect("equal")
        ax.set_title(f"dig {k + 1}: {vol:.2f} m³, heading {math.degrees(yaw) % 360:.0f}°", fontsize=9)
        ax.tick_params(labelsize=7)
    fig.suptitle("singh-cannon-loader: zero contour before (grey) and after (black) each dig; bucket edge and path in red", fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", help="output image, e.g. fig12.png")
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--target", type=float, default=6.2)
    args = ap.parse_args(argv)
    sc = pile(args.seed, args.target)
    plan = SinghCannonLoader().plan(sc)
    verdict = judge(sc, plan)
    draw(sc, plan, args.out)
    print(f"wrote {args.out}: {verdict.summary()}, {len(verdict.digs)} digs, loaded {verdict.loaded_volume:.3f} m³")


if __name__ == "__main__":
    main()
