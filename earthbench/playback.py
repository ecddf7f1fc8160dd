"""Playback: a plan's effect step by step, for the page's replay viewer, the figures and ``earthbench show --animate``.

:func:`replay` asks the referee itself how the heightmap and the truck's load stand after
each action (it judges the plan's prefixes in the referee's time order, so the frames are
exactly what :func:`earthbench.referee.judge` computes, never a second cut model).
:func:`replay_data` packs one replay compactly for the page: the first heightmap quantised
and zlib-compressed, then per changed action only the quantised height deltas inside the
changed cells' bounding box, the machines' paths, the bucket footprints and the violations
at their action. :func:`viewer_html` is the page's replay section (a ``<select>``, a timeline
and a canvas; the data as an inert JSON block in which ``<``, ``>`` and ``&`` are escaped, so
no stored string can end it); :data:`SCRIPT` draws it and is part of the page's one hashed
script.
"""

from __future__ import annotations

import base64
import html
import json
import math
import zlib
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from . import assets
from .errors import PlanFormatError
from .plan import Charge, Dig, Move, Plan
from .cut import footprint, path_window
from .referee import Verdict, judge
from .world import Scenario

if TYPE_CHECKING:
    import pandas as pd

    from .store import Store

#: Height quantum of the packed heightmaps (m); terrains are generated to 0.1 mm.
QUANTUM = 1e-3


@dataclass(frozen=True)
class Step:
    """The state after one action (``action``: its index in the plan), in the referee's order."""

    action: int
    z: np.ndarray  # the heightmap after the action
    loaded: float  # m³ in the truck after the action


@dataclass(frozen=True)
class Change:
    """What one action did, in the referee's order: the m³ in the truck after it and, if it
    changed the ground, the smallest window ``(rows, cols)`` holding every changed cell with
    the heights there after it (``z``)."""

    action: int
    loaded: float
    window: tuple[slice, slice] | None = None
    z: np.ndarray | None = None


def changes(scenario: Scenario, plan: Plan) -> tuple[Verdict, list[Change]]:
    """The referee's verdict and, from the same judgement, what each action changed.

    Only a dig or a charge cuts, and only inside its bucket's path window
    (:func:`earthbench.cut.path_window`), so a step costs that window, not the whole map: a
    plan of thousands of digs on a 96 × 48 m map replays in about one judgement's time and
    keeps only the windows.
    """
    before = np.array(scenario.terrain.z, dtype=np.float64)  # the ground as the last step left it
    out: list[Change] = []

    def observe(n: int, z: np.ndarray, loaded: float) -> None:
        path = bucket_path(scenario, plan.actions[n])
        if path is not None:
            rows, cols = path_window(scenario.terrain, z.shape, *path)
            diff = z[rows, cols] != before[rows, cols]
            if diff.any():
                jj, ii = np.nonzero(diff)
                window = (slice(rows.start + int(jj.min()), rows.start + int(jj.max()) + 1),
                          slice(cols.start + int(ii.min()), cols.start + int(ii.max()) + 1))
                before[window] = z[window]
                out.append(Change(n, loaded, window, before[window].copy()))
                return
        out.append(Change(n, loaded))

    verdict = judge(scenario, plan, observe)
    if len(out) != len(plan.actions):  # a malformed plan: nothing happened
        order = sorted(range(len(plan.actions)), key=lambda n: (plan.actions[n].t_start, n))
        out = [Change(n, 0.0) for n in order]
    return verdict, out


def replay(scenario: Scenario, plan: Plan) -> tuple[Verdict, list[Step]]:
    """The referee's verdict on the whole plan and the state after each action, in time order
    (:func:`changes` made into whole heightmaps; an action that cut nothing shares the one before)."""
    verdict, steps = changes(scenario, plan), []
    z = scenario.terrain.z
    for c in verdict[1]:
        if c.window is not None:
            z = z.copy()
            z[c.window] = c.z
        steps.append(Step(c.action, z, c.loaded))
    return verdict[0], steps


def machine_paths(scenario: Scenario, plan: Plan) -> dict[str, list[np.ndarray]]:
    """Per machine, its moves (and a loader's charges) in time order, each an array of ``(t, x, y, yaw)`` rows.

    Kept apart, not joined: a move that starts away from where the machine stands is a jump,
    never an ordinary piece of path.
    """
    out: dict[str, list[np.ndarray]] = {mid: [] for mid in scenario.machines.ids}
    for a in sorted(plan.actions, key=lambda a: a.t_start):
        if a.machine not in out:
            continue
        if isinstance(a, Move):
            out[a.machine].append(np.array(a.path, dtype=float))
        elif isinstance(a, Charge):
            (x, y, yaw), (ex, ey, _) = a.entry, a.end
            out[a.machine].append(np.array([[a.t_start, x, y, yaw], [a.t_end, ex, ey, yaw]]))
    return out


def pose_at(start: tuple[float, float, float], segments: list[np.ndarray], t: float) -> tuple[float, float, float]:
    """Where a machine is at time ``t``: on the move running then (linear between samples), else where the last one ended."""
    p = start
    for seg in segments:
        if seg[0, 0] > t:
            break
        if seg[-1, 0] > t:
            return tuple(float(np.interp(t, seg[:, 0], seg[:, k])) for k in (1, 2, 3))  # type: ignore[return-value]
        p = (float(seg[-1, 1]), float(seg[-1, 2]), float(seg[-1, 3]))
    return p


def _pack(values: np.ndarray) -> str:
    """Integers as ``"i2:"`` or ``"i4:"`` (little-endian 16 or 32 bits, the smaller that holds them) + base64 of zlib."""
    dtype = "<i2" if values.size == 0 or int(np.abs(values).max()) < 2**15 else "<i4"
    data = zlib.compress(np.ascontiguousarray(values, dtype=dtype).tobytes(), 6)
    return dtype[1:] + ":" + base64.b64encode(data).decode("ascii")


def _r(v: float, nd: int = 3) -> float | None:
    """Rounded; ``None`` (JSON null) for an infinite or undefined number, e.g. a violation's magnitude."""
    v = float(v)
    return round(v, nd) if math.isfinite(v) else None


def bucket_path(scenario: Scenario, a: Any) -> tuple[tuple[float, float], float, float, float] | None:
    """The bucket's path of a dig or a charge as the referee cuts it: start of the cutting edge,
    heading, width and length (``None`` for other actions, or without the machine)."""
    m = scenario.machines
    if isinstance(a, Dig) and m.excavator is not None:
        return a.contact, a.heading, m.excavator.bucket_width, a.drag_length
    if isinstance(a, Charge) and m.loader is not None:
        (x, y, yaw), spec = a.entry, m.loader
        return (x + spec.bucket_offset * math.cos(yaw), y + spec.bucket_offset * math.sin(yaw)), yaw, spec.bucket_width, a.penetration
    return None


def bucket_footprint(scenario: Scenario, a: Any) -> list[tuple[float, float]] | None:
    """The referee's bucket rectangle of a dig or a charge (``None`` for other actions, or without the machine)."""
    path = bucket_path(scenario, a)
    return None if path is None else list(footprint(*path).exterior.coords)


def _poly(points: Any) -> list[list[float | None]]:
    return [[_r(x), _r(y)] for x, y in points]


def replay_data(scenario: Scenario, plan: Plan, label: str, run_id: int | None = None) -> dict[str, Any]:
    """One replay as the page's script reads it (numbers rounded to mm, heights quantised to :data:`QUANTUM`)."""
    verdict, steps = changes(scenario, plan)
    t = scenario.terrain
    z0 = np.asarray(t.z, dtype=np.float64)
    cut = [c.z for c in steps if c.z is not None]  # every height any frame has that the first lacks
    lo = float(min([z0.min(), *(z.min() for z in cut)]))  # a list: a plan may change no cell
    hi = float(max([z0.max(), *(z.max() for z in cut)]))
    q = max(QUANTUM, (hi - lo) / 60000.0)

    def quant(z: np.ndarray) -> np.ndarray:
        return np.rint((z - lo) / q).astype(np.int32)

    zq = quant(z0)
    # differences along each row (the first column: down it, from zq[0, 0]) are small on a smooth terrain:
    # 16 bits and far better compression than the heights themselves
    base = int(zq[0, 0])
    rows = np.diff(zq, axis=1, prepend=0)
    rows[:, 0] = np.diff(zq[:, 0], prepend=base)
    by_action: dict[int, list[dict[str, Any]]] = {}
    for v in verdict.violations:
        by_action.setdefault(-1 if v.action is None else v.action, []).append(
            {"rule": v.rule, "magnitude": _r(v.magnitude, 4), "message": v.message})
    m = scenario.machines
    events = []
    shown = zq.copy()  # the quantised ground as the events so far leave it
    for s in steps:
        a = plan.actions[s.action]
        ev: dict[str, Any] = {"a": s.action, "type": a.kind, "machine": a.machine, "t0": _r(a.t_start), "t1": _r(a.t_end),
                              "loaded": _r(s.loaded, 4)}
        if s.window is not None and s.z is not None:
            cur, prev = quant(s.z), shown[s.window]
            if not np.array_equal(cur, prev):
                changed = np.argwhere(cur != prev)
                (j0, i0), (j1, i1) = changed.min(axis=0), changed.max(axis=0) + 1
                j, i = s.window[0].start, s.window[1].start
                ev["delta"] = {"i": int(i + i0), "j": int(j + j0), "w": int(i1 - i0), "h": int(j1 - j0),
                               "d": _pack(cur[j0:j1, i0:i1] - prev[j0:j1, i0:i1])}
                shown[s.window] = cur
        fp = bucket_footprint(scenario, a)
        if fp is not None:
            ev["fp"] = _poly(fp[:-1])
        if s.action in by_action:
            ev["violations"] = by_action[s.action]
        events.append(ev)
    machines = {}
    for mid, segs in machine_paths(scenario, plan).items():
        p = m.pose(mid)
        machines[mid] = {"start": [_r(p.x), _r(p.y), _r(p.yaw)],
                         "segments": [[[_r(v) for v in smp] for smp in seg] for seg in segs]}
    exc = m.excavator
    return {
        "run": run_id, "label": label, "scenario": scenario.id, "verdict": verdict.summary(),
        "grid": {"nx": int(z0.shape[1]), "ny": int(z0.shape[0]), "x0": t.origin[0], "y0": t.origin[1], "r": t.resolution,
                 "lo": lo, "q": q, "hi": hi, "base": base, "rows": _pack(rows)},
        "dig_area": _poly(scenario.site.dig_area), "keep_outs": [_poly(k) for k in scenario.site.keep_outs],
        "reach": [exc.reach_min, exc.reach_max] if exc is not None else None,
        "target": scenario.task.target_volume, "makespan": _r(plan.makespan), "machines": machines,
        "events": events, "plan_violations": by_action.get(-1, []),
    }


def pick_runs(runs: pd.DataFrame, limit: int) -> pd.DataFrame:
    """Up to ``limit`` runs with a plan worth replaying: per planner in turn, a success, an invalid run, then more,
    spread over the scenario families. A run published under several suites is picked once.
    """
    have = runs[runs["reason"].isin(["ok", "invalid"])].drop_duplicates("id").sort_values("id")
    if have.empty or limit <= 0:
        return have.iloc[:0]
    if "family" in have:  # spread each planner's picks over the families: the first of each, then the second, …
        have = have.assign(_nth=have.groupby(["solver", "family"]).cumcount()).sort_values(["_nth", "family", "id"])
    queues = []
    for _, g in have.groupby("solver", sort=True):
        succ, bad = g[g["success"].astype(bool)], g[g["reason"] == "invalid"]
        rest = g.drop(index=succ.index[:1].union(bad.index[:1]))
        queues.append(list(succ.index[:1]) + list(bad.index[:1]) + list(rest.index))
    picked: list[Any] = []
    while len(picked) < limit and any(queues):
        for q in queues:
            if q and len(picked) < limit:
                picked.append(q.pop(0))
    return have.loc[picked].drop(columns=["_nth"], errors="ignore")


def viewer_section(store: Store, runs: pd.DataFrame, limit: int = 20) -> str:
    """The page's replay section for up to ``limit`` of ``runs`` (their stored plans judged again).

    A stored scenario that does not reproduce its digest is skipped: a plan is never replayed on
    a terrain it was not made for.
    """
    docs = []
    for _, run in pick_runs(runs, limit).iterrows():
        scenario = store.scenario(run["scenario_digest"])
        plan_json = store.plan_json(int(run["id"]))
        if scenario.digest != run["scenario_digest"] or plan_json is None:
            continue
        try:
            plan = Plan.from_json(plan_json)
        except PlanFormatError:  # a malformed stored plan has nothing to replay
            continue
        docs.append(replay_data(scenario, plan, f"run {int(run['id'])}: {run['solver']} on {run['scenario_id']}", int(run["id"])))
    return viewer_html(docs)


def _json_block(doc: Any) -> str:
    """JSON that cannot end its ``<script>`` element nor open markup."""
    text = json.dumps(doc, separators=(",", ":"), ensure_ascii=True, allow_nan=False)
    return text.replace("&", "\\u0026").replace("<", "\\u003c").replace(">", "\\u003e")


def viewer_html(replays: list[dict[str, Any]]) -> str:
    """The page's replay section, with its data; empty when there is nothing to replay."""
    if not replays:
        return ""
    e = html.escape
    return (
        '<section id="replay"><h2>Replay</h2>'
        f"<p>{len(replays)} published runs can be replayed as the referee judged them: pick one (or ▶ in a runs table), "
        "then play or drag the timeline. The heightmap changes dig by dig; the machines move along their paths; "
        "bucket footprints (black outline) and dumps (■) appear at their action; the excavator's reach annulus "
        "follows its base; violations are marked in red at their action. The bar beside the map is its height scale "
        "(m, the run's lowest to highest ground, as on the terrain figures).</p>"
        '<div class="rp-controls"><label>Run <select id="rp-run"></select></label> '
        '<button type="button" id="rp-play">▶ Play</button> '
        '<button type="button" id="rp-prev" title="previous action">◀|</button>'
        '<button type="button" id="rp-next" title="next action">|▶</button> '
        '<input type="range" id="rp-time" min="0" max="1000" value="0" step="1" aria-label="time"> '
        '<label><input type="checkbox" id="rp-overlays" checked> paths and marks</label> '
        '<span id="rp-clock"></span></div>'
        '<div class="rp-body"><canvas id="rp-canvas" width="900" height="450"></canvas>'
        '<canvas id="rp-scale" width="84" height="450" role="img" aria-label="height scale (m)"></canvas>'
        '<div class="rp-side"><p id="rp-verdict"></p><p id="rp-now"></p><ol id="rp-log"></ol></div></div>'
        f'<script type="application/json" id="rp-data">{_json_block(replays)}</script>'
        f"<noscript>{e('The replay viewer needs JavaScript.')}</noscript></section>"
    )


#: The viewer's script (part of the page's one script, allowed by its content-security-policy hash)
#: and style, files in :mod:`earthbench.assets`.
SCRIPT = assets.text("replay.js")
CSS = assets.text("replay.css")


__all__ = [
    "CSS",
    "QUANTUM",
    "SCRIPT",
    "Change",
    "Step",
    "bucket_footprint",
    "bucket_path",
    "changes",
    "machine_paths",
    "pick_runs",
    "pose_at",
    "replay",
    "replay_data",
    "viewer_html",
    "viewer_section",
]
