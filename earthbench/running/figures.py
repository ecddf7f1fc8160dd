"""Figures drawn from a scenario, a plan and the referee's verdict (matplotlib, no display).

:func:`terrain_before_after` (``earthbench show`` and the leaderboard's terrain figures) and
:func:`animate` (``earthbench show --animate``) draw the same layers: the heightmap cropped to
the map (and the machines' end poses and dump positions, when they lie beyond it), the dig
area and keep-outs, each machine's moves as separate pieces (a jump between two moves is a
red dashed line, never an ordinary path), start poses (○) and end poses (▲ with the heading),
the excavator's reach annulus at every station it dug from (stations within 1.5 m drawn
once), bucket footprints, dumps (■ at the truck), and every violation in red at its action
with its rule. A machine beyond the crop is an arrow at the edge with its position.
"""

from __future__ import annotations

import math
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from ..plan import Charge, Dig, Dump, Move, Plan
from ..referee import Verdict
from .playback import bucket_footprint, machine_paths, pose_at, replay
from ..world import Scenario

_COLOURS = {"excavator": "tab:orange", "truck": "tab:blue", "loader": "tab:green"}
_RED = "#d00000"
_JUMP = 0.05  # m: a move starting farther than this from where the machine stands is a jump


def _fp(scenario: Scenario, a: Any) -> np.ndarray | None:
    fp = bucket_footprint(scenario, a)
    return None if fp is None else np.asarray(fp)


def view_box(scenario: Scenario, plan: Plan, pad: float = 0.5) -> tuple[float, float, float, float]:
    """The map's extent, grown to the machines' end poses and dump positions (where the work ends), plus ``pad``."""
    x0, x1, y0, y1 = scenario.terrain.extent
    paths = machine_paths(scenario, plan)
    pts = []
    for mid in scenario.machines.ids:
        p = scenario.machines.pose(mid)
        pts.append(pose_at((p.x, p.y, p.yaw), paths[mid], math.inf)[:2])
        for a in plan.actions:
            if isinstance(a, Dump) and "truck" in paths:
                t = scenario.machines.truck_pose
                pts.append(pose_at((t.x, t.y, t.yaw), paths["truck"], a.t_start)[:2])
    xs, ys = [x0, x1] + [p[0] for p in pts], [y0, y1] + [p[1] for p in pts]
    return min(xs) - pad, max(xs) + pad, min(ys) - pad, max(ys) + pad


def _edge_marker(ax, box, x: float, y: float, colour: Any, label: str) -> None:
    """A machine beyond the crop: an arrow at the edge pointing to it, with its position."""
    bx0, bx1, by0, by1 = box
    cx, cy = min(max(x, bx0), bx1), min(max(y, by0), by1)
    ang = math.atan2(y - cy, x - cx)
    ax.annotate("", xy=(cx, cy), xytext=(cx - 0.6 * math.cos(ang), cy - 0.6 * math.sin(ang)),
                arrowprops=dict(arrowstyle="-|>", color=colour, lw=2), annotation_clip=False, zorder=6)
    ax.text(cx - 0.8 * math.cos(ang), cy - 0.8 * math.sin(ang), f"{label} ({x:.1f}, {y:.1f})", fontsize=7, color=colour,
            ha="right" if cx > (bx0 + bx1) / 2 else "left", va="top" if cy > (by0 + by1) / 2 else "bottom", zorder=6)


def _inside(box, x: float, y: float) -> bool:
    return box[0] <= x <= box[1] and box[2] <= y <= box[3]


def draw_layers(ax, scenario: Scenario, plan: Plan, verdict: Verdict, t: float = math.inf, box=None) -> None:
    """Everything but the heightmap, as it stands at time ``t`` (``inf``: the whole plan)."""
    box = box or view_box(scenario, plan)
    _draw_site(ax, scenario)
    bad: dict[int, list[str]] = {}  # action index → the rules it broke
    for v in verdict.violations:
        if v.action is not None:
            bad.setdefault(v.action, []).append(v.rule)
    paths = machine_paths(scenario, plan)
    for mid in scenario.machines.ids:
        _draw_machine(ax, scenario, plan, mid, paths, bad, t, box)
    _draw_reach(ax, scenario, plan, paths, t)
    _draw_actions(ax, scenario, plan, verdict, paths, bad, t)
    ax.set_xlim(box[0], box[1])
    ax.set_ylim(box[2], box[3])
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def _draw_site(ax, scenario: Scenario) -> None:
    """The dig area (dashed) and the keep-outs (red)."""
    area = np.array(scenario.site.dig_area + (scenario.site.dig_area[0],))
    ax.plot(area[:, 0], area[:, 1], "k--", lw=1, label="dig area")
    for ko in scenario.site.keep_outs:
        k = np.array(ko + (ko[0],))
        ax.fill(k[:, 0], k[:, 1], color="red", alpha=0.3)


def _draw_machine(ax, scenario: Scenario, plan: Plan, mid: str, paths: dict[str, Any], bad: dict[int, list[str]],
                  t: float, box) -> None:
    """One machine's moves up to ``t`` (red where they broke a rule, a red dashed jump between two moves that do
    not meet), its start pose (○) and its pose at ``t`` (▲ with the heading, or an arrow at the edge beyond the crop)."""
    index = {id(a): n for n, a in enumerate(plan.actions)}
    p0 = scenario.machines.pose(mid)
    colour = _COLOURS.get(mid, "k")
    at = (p0.x, p0.y)
    moves = [a for a in sorted(plan.actions, key=lambda a: a.t_start) if a.machine == mid and isinstance(a, (Move, Charge))]
    ax.plot([], [], "-", color=colour, label=mid)  # the legend shows the machine's colour, red or not
    for seg, mv in zip(paths[mid], moves):
        if seg[0, 0] > t:
            break
        shown = seg[seg[:, 0] <= t] if seg[-1, 0] > t else seg
        if seg[-1, 0] > t:
            shown = np.vstack([shown, [t, *pose_at((p0.x, p0.y, p0.yaw), paths[mid], t)]])
        if math.hypot(seg[0, 1] - at[0], seg[0, 2] - at[1]) > _JUMP:  # a jump: never an ordinary path
            ax.plot([at[0], seg[0, 1]], [at[1], seg[0, 2]], ls=(0, (3, 2)), color=_RED, lw=1.8, zorder=4)
        rules = bad.get(index[id(mv)])
        ax.plot(shown[:, 1], shown[:, 2], "-", color=_RED if rules else colour, lw=2.4 if rules else 1.5, zorder=3)
        if rules:
            ax.text(shown[-1, 1], shown[-1, 2], " " + ", ".join(sorted(set(rules))), color=_RED, fontsize=7, zorder=6)
        at = (seg[-1, 1], seg[-1, 2])
    if _inside(box, p0.x, p0.y):
        ax.plot(p0.x, p0.y, "o", color=colour, mfc="white", mew=1.5, ms=7, zorder=5)
    end = pose_at((p0.x, p0.y, p0.yaw), paths[mid], t)
    if _inside(box, end[0], end[1]):
        ax.plot(end[0], end[1], marker=(3, 0, math.degrees(end[2]) - 90), color=colour, mec="k", ms=11, zorder=5)
        ax.plot([end[0], end[0] + 0.8 * math.cos(end[2])], [end[1], end[1] + 0.8 * math.sin(end[2])], "k-", lw=1.2, zorder=5)
    else:
        _edge_marker(ax, box, end[0], end[1], colour, mid)


def _draw_reach(ax, scenario: Scenario, plan: Plan, paths: dict[str, Any], t: float) -> None:
    """The excavator's reach annulus at every station it dug from up to ``t`` (stations within 1.5 m drawn once)."""
    m = scenario.machines
    exc, e0 = m.excavator, m.excavator_pose
    if exc is None or e0 is None or "excavator" not in paths:
        return
    bases = [pose_at((e0.x, e0.y, e0.yaw), paths["excavator"], a.t_start)[:2]
             for a in sorted(plan.actions, key=lambda a: a.t_start) if isinstance(a, Dig) and a.t_start <= t]
    stations: list[tuple[float, float]] = []
    for b in bases or [pose_at((e0.x, e0.y, e0.yaw), paths["excavator"], t)[:2]]:
        if all(math.hypot(b[0] - s[0], b[1] - s[1]) > 1.5 for s in stations):  # one ring per station, not per nudge
            stations.append(b)
    th = np.linspace(0, 2 * math.pi, 121)
    for ring, (sx, sy) in enumerate(stations):
        for r in (exc.reach_min, exc.reach_max):
            ax.plot(sx + r * np.cos(th), sy + r * np.sin(th), ":", color="0.25", lw=0.9,
                    label="reach annulus" if ring == 0 and r == exc.reach_min else None, zorder=2)


def _draw_actions(ax, scenario: Scenario, plan: Plan, verdict: Verdict, paths: dict[str, Any], bad: dict[int, list[str]],
                  t: float) -> None:
    """Every action started by ``t``: bucket footprints and drags, dumps (■ at the truck) and each violation in red
    at its action with its rule."""
    m = scenario.machines
    dumps = 0
    if any(isinstance(a, Dump) for a in plan.actions):
        ax.plot([], [], "s", color="#5b3a1a", ms=5, label="dump")
    if verdict.violations:
        ax.plot([], [], "o", ms=9, mfc="none", mec=_RED, mew=2, label="violation (action: rule)")
    for n, a in enumerate(plan.actions):
        if a.t_start > t:
            continue
        rules = bad.get(n)
        fp = _fp(scenario, a)
        if fp is not None:
            ax.plot(fp[:, 0], fp[:, 1], "-", color=_RED if rules else "k", lw=2 if rules else 0.8, zorder=4)
            if isinstance(a, Dig):
                ex, ey = a.contact[0] + math.cos(a.heading) * a.drag_length, a.contact[1] + math.sin(a.heading) * a.drag_length
                ax.plot([a.contact[0], ex], [a.contact[1], ey], "-", color=_RED if rules else "k", lw=1.2, zorder=4)
                ax.plot(*a.contact, "x", color=_RED if rules else "k", ms=6 if rules else 4, mew=2 if rules else 1, zorder=4)
        if isinstance(a, Dump) and "truck" in paths:
            tp = m.truck_pose
            x, y, _ = pose_at((tp.x, tp.y, tp.yaw), paths["truck"], a.t_start)
            ax.plot(x + 0.25 * (dumps % 4 - 1.5), y + 0.45, "s", color=_RED if rules else "#5b3a1a", ms=5, zorder=5)
            dumps += 1
        if rules and not isinstance(a, Move) and (isinstance(a, Dig) or a.machine in paths):
            if isinstance(a, Dig):
                where = a.contact
            else:
                p = m.pose(a.machine)
                where = pose_at((p.x, p.y, p.yaw), paths[a.machine], a.t_start)[:2]
            ax.plot(*where, "o", ms=16, mfc="none", mec=_RED, mew=2, zorder=6)
            ax.annotate(f"{n}: " + ", ".join(sorted(set(rules))), where, xytext=(6, 6), textcoords="offset points",
                        color=_RED, fontsize=7, zorder=6)


def _heights(ax, scenario: Scenario, z: np.ndarray, lo: float, hi: float):
    im = ax.imshow(z, origin="lower", extent=scenario.terrain.extent, cmap="terrain", vmin=lo, vmax=hi, zorder=1)
    ax.set_facecolor("0.92")  # beyond the map
    return im


def terrain_before_after(scenario: Scenario, plan: Plan, verdict: Verdict) -> Figure:
    """Two panels: the heightmap before and after, each with every layer of :func:`draw_layers`."""
    before, after = scenario.terrain.z, verdict.final_terrain.z
    lo, hi = float(min(before.min(), after.min())), float(max(before.max(), after.max()))
    box = view_box(scenario, plan)
    aspect = (box[3] - box[2]) / max(box[1] - box[0], 1e-9)
    fig, axes = plt.subplots(1, 2, figsize=(12, max(3.2, min(9.0, 5.2 * aspect + 1.4))), constrained_layout=True)
    for ax, z, title in ((axes[0], before, "before"), (axes[1], after, f"after\n{verdict.summary()}")):
        im = _heights(ax, scenario, z, lo, hi)
        draw_layers(ax, scenario, plan, verdict, box=box)
        ax.set_title(f"{scenario.id} — {title}", fontsize=9, wrap=True, color=_RED if ax is axes[1] and not verdict.valid else "k")
    plan_level = sorted({v.rule for v in verdict.violations if v.action is None})
    if plan_level:
        axes[1].text(0.01, 0.99, "plan: " + ", ".join(plan_level), transform=axes[1].transAxes, color=_RED, fontsize=8,
                     va="top", zorder=7)
    axes[0].legend(fontsize=7, loc="best")
    fig.colorbar(im, ax=axes, label="z (m)", shrink=0.8)
    return fig


def animation_writer(out: str, fps: int = 8) -> Any:
    """The writer for an animation file ``out`` (``.gif``: Pillow; ``.mp4``: ffmpeg), or a clear error before any work."""
    from matplotlib import animation

    from ..errors import EarthbenchError

    ext = out.rsplit(".", 1)[-1].lower()
    if ext == "gif":
        return animation.PillowWriter(fps=fps)
    if ext == "mp4":
        if not animation.FFMpegWriter.isAvailable():
            raise EarthbenchError("--animate out.mp4 needs ffmpeg on PATH (apt-get install ffmpeg); out.gif needs nothing more")
        return animation.FFMpegWriter(fps=fps)
    raise EarthbenchError(f"--animate {out!r}: the animation must end in .gif or .mp4")


def animate(scenario: Scenario, plan: Plan, out: str, frames: int = 80, fps: int = 8) -> int:
    """Write the plan replayed as ``out`` (``.gif``: Pillow; ``.mp4``: ffmpeg) and return the frame count.

    Frames are evenly spaced in time plus one at the end of every dig, dump and charge, so
    every change of the heightmap is shown.
    """
    from matplotlib import animation

    writer = animation_writer(out, fps)
    verdict, steps = replay(scenario, plan)
    span = max(plan.makespan, 1e-9)
    times = sorted(set(np.linspace(0.0, span, frames).round(6)) | {round(plan.actions[s.action].t_end, 6) for s in steps
                                                                   if not isinstance(plan.actions[s.action], Move)})
    ends = [plan.actions[s.action].t_end for s in steps]
    lo = float(min(scenario.terrain.z.min(), *(s.z.min() for s in steps))) if steps else float(scenario.terrain.z.min())
    hi = float(scenario.terrain.z.max())
    box = view_box(scenario, plan)
    aspect = (box[3] - box[2]) / max(box[1] - box[0], 1e-9)
    fig, ax = plt.subplots(figsize=(7.5, max(3.0, min(8.0, 6.0 * aspect + 1.0))), constrained_layout=True)

    def frame(t: float) -> None:
        ax.clear()
        done = [s for s, te in zip(steps, ends) if te <= t + 1e-9]
        z = done[-1].z if done else scenario.terrain.z
        _heights(ax, scenario, z, lo, hi)
        draw_layers(ax, scenario, plan, verdict, t=t, box=box)
        loaded = done[-1].loaded if done else 0.0
        ax.set_title(f"{scenario.id} — t = {t:.1f} / {span:.1f} s, loaded {loaded:.2f} m³ — {verdict.summary()}", fontsize=8)

    anim = animation.FuncAnimation(fig, frame, frames=times, repeat=False)
    anim.save(out, writer=writer)
    plt.close(fig)
    return len(times)
