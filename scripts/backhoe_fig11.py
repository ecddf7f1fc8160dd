"""Side profiles along one lane of a bench, after the paper's Fig. 11.

``python scripts/backhoe_fig11.py OUT.png [SEED]`` plans a long bench (the
scenario of the Fig. 11 test), then draws, for every dig of the busiest lane at the first
station (a fixed swing angle), the terrain profile along the lane before and after the dig, the
predicted bucket trajectory (dotted: entry at the contact, down to the cut level, drag toward
the machine) and the bounds of the coarse plan's region (``*``).
"""

from __future__ import annotations

import math
import sys
from collections import Counter

import numpy as np

from earthbench.cut import apply_cut
from earthbench.world import Scenario, Task
from earthbench_terrains.bench import bench

from earthbench_planners.singh_cannon.backhoe import SinghCannonBackhoe


def fig11_scenario(seed: int = 0) -> Scenario:
    """A 14 m long bench face and a target the first station cannot supply with full buckets."""
    sc = bench(seed, 4.0, size=(14.0, 16.0), face_length=14.0, excavator=(10.0, 8.0, math.pi),
               truck=(4.0, 5.0, math.pi / 2), truck_capacity=40.0)
    return sc.replace(task=Task(30.0))


def lane_profiles(sc: Scenario, plan, station: int = 0, lane: int | None = None) -> tuple[int, list[dict]]:
    """For each dig of ``lane`` (default: the busiest) at ``station``: the profiles along its line."""
    digs = plan.info["digs"]
    if lane is None:
        lane = Counter(d["lane"] for d in digs if d["station"] == station).most_common(1)[0][0]
    spec = sc.machines.excavator
    terrain = sc.terrain
    z = np.array(terrain.z, dtype=float)
    dig_actions = [a for a in plan.actions if a.kind == "dig"]
    s = np.linspace(spec.reach_min - 0.5, spec.reach_max + 0.5, 200)
    out = []
    for info, act in zip(digs, dig_actions):
        mine = info["station"] == station and info["lane"] == lane
        if mine:
            bx, by = info["base"]
            ux, uy = math.cos(info["bearing"]), math.sin(info["bearing"])
            before = np.array([terrain.height_at(bx + ux * v, by + uy * v, z) for v in s])
        level = terrain.height_at(act.contact[0], act.contact[1], z) - act.depth
        apply_cut(terrain, z, act.contact, act.heading, spec.bucket_width, act.drag_length, level, spec.bucket_capacity)
        if mine:
            after = np.array([terrain.height_at(bx + ux * v, by + uy * v, z) for v in s])
            out.append({"s": s, "before": before, "after": after, **info})
    return lane, out


def draw(sc: Scenario, plan, path: str, station: int = 0) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lane, rows = lane_profiles(sc, plan, station)
    fig, axes = plt.subplots(len(rows), 1, figsize=(6, 1.8 * len(rows)), sharex=True, squeeze=False)
    for ax, r in zip(axes[:, 0], rows):
        ax.plot(r["s"], r["before"], color="0.7", lw=1, label="before")
        ax.plot(r["s"], r["after"], color="k", lw=1.2, label="after")
        d, drag, level = r["d"], r["drag"], r["level"]
        top = level + r["depth"]
        ax.plot([d, d, d - drag], [top, level, level], "b:", lw=1.5, label="predicted bucket")
        ax.plot(r["region_d"], [r["level_min"]] * 2, "r*", label="coarse-plan bounds")
        ax.set_ylabel("z (m)")
        ax.set_title(f"band {r['band']}, dig at d = {d:.2f} m, α = {math.degrees(r['alpha']):.0f}°, {r['volume']:.3f} m³", fontsize=8)
    axes[-1, 0].set_xlabel("distance from the excavator along the lane (m)")
    axes[0, 0].legend(fontsize=6, loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    out = argv[0] if argv else "fig11.png"
    sc = fig11_scenario(int(argv[1]) if len(argv) > 1 else 0)
    plan = SinghCannonBackhoe().plan(sc)
    draw(sc, plan, out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
