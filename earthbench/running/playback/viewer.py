"""The page's replay viewer: one replay packed compactly (:func:`replay_data`: the first heightmap
quantised and zlib-compressed, then per changed action only the quantised height deltas inside
the changed cells' bounding box, the machines' paths, the bucket footprints and the violations at
their action), and the section that shows them (:func:`viewer_section`, :func:`viewer_html`: a
``<select>``, a timeline and a canvas; the data as an inert JSON block in which ``<``, ``>`` and
``&`` are escaped, so no stored string can end it); :data:`SCRIPT` draws it and is part of the
page's one hashed script."""

from __future__ import annotations

import base64
import html
import json
import math
import zlib
from typing import TYPE_CHECKING, Any

import numpy as np

from ... import assets
from ...errors import PlanFormatError
from ...plan import Plan
from ...world import Scenario

from .frames import changes
from .geometry import bucket_footprint, machine_paths
from .selection import pick_runs

if TYPE_CHECKING:  # pragma: no cover
    import pandas as pd

    from ...results.store import Store


#: Height quantum of the packed heightmaps (m); terrains are generated to 0.1 mm.
QUANTUM = 1e-3

def _pack(values: np.ndarray) -> str:
    """Integers as ``"i2:"`` or ``"i4:"`` (little-endian 16 or 32 bits, the smaller that holds them) + base64 of zlib."""
    dtype = "<i2" if values.size == 0 or int(np.abs(values).max()) < 2**15 else "<i4"
    data = zlib.compress(np.ascontiguousarray(values, dtype=dtype).tobytes(), 6)
    return dtype[1:] + ":" + base64.b64encode(data).decode("ascii")


def _r(v: float, nd: int = 3) -> float | None:
    """Rounded; ``None`` (JSON null) for an infinite or undefined number, e.g. a violation's magnitude."""
    v = float(v)
    return round(v, nd) if math.isfinite(v) else None

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
