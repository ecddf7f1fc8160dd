"""Figures drawn from a scenario, a plan and the referee's verdict (matplotlib, no display)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from .plan import Dig, Move, Plan  # noqa: E402
from .referee import Verdict  # noqa: E402
from .world import Scenario  # noqa: E402

_COLOURS = {"excavator": "tab:orange", "truck": "tab:blue", "loader": "tab:green"}


def terrain_before_after(scenario: Scenario, plan: Plan, verdict: Verdict) -> Figure:
    """Two panels: the heightmap before and after, with paths, digs, dig area and keep-outs."""
    before, after = scenario.terrain.z, verdict.final_terrain.z
    lo, hi = float(min(before.min(), after.min())), float(max(before.max(), after.max()))
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8), constrained_layout=True)
    extent = scenario.terrain.extent
    for ax, z, title in ((axes[0], before, "before"), (axes[1], after, f"after: {verdict.summary()}")):
        im = ax.imshow(z, origin="lower", extent=extent, cmap="terrain", vmin=lo, vmax=hi)
        area = np.array(scenario.site.dig_area + (scenario.site.dig_area[0],))
        ax.plot(area[:, 0], area[:, 1], "k--", lw=1, label="dig area")
        for ko in scenario.site.keep_outs:
            k = np.array(ko + (ko[0],))
            ax.fill(k[:, 0], k[:, 1], color="red", alpha=0.3)
        for mid in scenario.machines.ids:
            pose = scenario.machines.pose(mid)
            pts = [(pose.x, pose.y)] + [(s[1], s[2]) for a in plan.actions if isinstance(a, Move) and a.machine == mid for s in a.path]
            xy = np.array(pts)
            ax.plot(xy[:, 0], xy[:, 1], "-", color=_COLOURS.get(mid, "k"), lw=1.5, label=mid)
            ax.plot(xy[0, 0], xy[0, 1], "o", color=_COLOURS.get(mid, "k"))
        digs = np.array([a.contact for a in plan.actions if isinstance(a, Dig)]).reshape(-1, 2)
        if len(digs):
            ax.plot(digs[:, 0], digs[:, 1], "kx", ms=5, label="dig contacts")
        ax.set_title(f"{scenario.id} — {title}", fontsize=9)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_aspect("equal")
        ax.autoscale()
    axes[0].legend(fontsize=7, loc="best")
    fig.colorbar(im, ax=axes, label="z (m)", shrink=0.8)
    return fig
