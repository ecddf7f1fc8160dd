"""Replays: a plan's effect step by step, for the page's replay viewer and ``earthbench show --animate``.

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
        "follows its base; violations are marked in red at their action.</p>"
        '<div class="rp-controls"><label>Run <select id="rp-run"></select></label> '
        '<button type="button" id="rp-play">▶ Play</button> '
        '<button type="button" id="rp-prev" title="previous action">◀|</button>'
        '<button type="button" id="rp-next" title="next action">|▶</button> '
        '<input type="range" id="rp-time" min="0" max="1000" value="0" step="1" aria-label="time"> '
        '<label><input type="checkbox" id="rp-overlays" checked> paths and marks</label> '
        '<span id="rp-clock"></span></div>'
        '<div class="rp-body"><canvas id="rp-canvas" width="900" height="450"></canvas>'
        '<div class="rp-side"><p id="rp-verdict"></p><p id="rp-now"></p><ol id="rp-log"></ol></div></div>'
        f'<script type="application/json" id="rp-data">{_json_block(replays)}</script>'
        f"<noscript>{e('The replay viewer needs JavaScript.')}</noscript></section>"
    )


#: The viewer's script (part of the page's one script, allowed by its content-security-policy hash).
SCRIPT = r"""
(function () {
  var dataEl = document.getElementById('rp-data');
  if (!dataEl) return;
  var replays = JSON.parse(dataEl.textContent);
  var sel = document.getElementById('rp-run'), canvas = document.getElementById('rp-canvas');
  var slider = document.getElementById('rp-time'), clock = document.getElementById('rp-clock');
  var playBtn = document.getElementById('rp-play'), logEl = document.getElementById('rp-log');
  var nowEl = document.getElementById('rp-now'), verdictEl = document.getElementById('rp-verdict');
  var ctx = canvas.getContext('2d'), overlays = document.getElementById('rp-overlays');
  var COLOURS = {excavator: '#e67e00', truck: '#1f66c2', loader: '#2a9d2a'};
  var TERRAIN = [[0, [51, 51, 153]], [0.15, [0, 153, 255]], [0.25, [0, 204, 102]], [0.5, [255, 255, 153]],
                 [0.75, [128, 92, 84]], [1, [255, 255, 255]]];
  var cur = null;  // the loaded replay: {doc, z (Float64Array), applied (events applied), t, image canvas}
  var playing = false, lastFrame = 0;

  function bytes(b64) {
    var s = atob(b64), out = new Uint8Array(s.length);
    for (var i = 0; i < s.length; i++) out[i] = s.charCodeAt(i);
    return out;
  }
  function inflate(packed) {  // "i2:BASE64" or "i4:BASE64" of zlib-compressed little-endian integers
    var stream = new Blob([bytes(packed.slice(3))]).stream().pipeThrough(new DecompressionStream('deflate'));
    return new Response(stream).arrayBuffer().then(function (buf) {
      return packed.slice(0, 2) === 'i2' ? new Int16Array(buf) : new Int32Array(buf);
    });
  }
  function colour(f) {
    f = Math.max(0, Math.min(1, f));
    for (var k = 1; k < TERRAIN.length; k++) {
      if (f <= TERRAIN[k][0]) {
        var a = TERRAIN[k - 1], b = TERRAIN[k], u = (f - a[0]) / (b[0] - a[0]);
        return [0, 1, 2].map(function (c) { return Math.round(a[1][c] + u * (b[1][c] - a[1][c])); });
      }
    }
    return TERRAIN[TERRAIN.length - 1][1];
  }
  function option(doc, n) {
    var o = document.createElement('option');
    o.value = String(n);
    o.textContent = doc.label + ' — ' + doc.verdict;
    return o;
  }
  replays.forEach(function (doc, n) { sel.appendChild(option(doc, n)); });

  function load(n) {
    var doc = replays[n], g = doc.grid;
    sel.value = String(n);
    var deltas = doc.events.map(function (ev) { return ev.delta ? inflate(ev.delta.d) : Promise.resolve(null); });
    return Promise.all([inflate(g.rows)].concat(deltas)).then(function (arr) {
      var rows = arr[0], z = new Int32Array(g.nx * g.ny), first = g.base;
      for (var j = 0; j < g.ny; j++) {
        first += rows[j * g.nx];
        var acc = first;
        z[j * g.nx] = acc;
        for (var i = 1; i < g.nx; i++) { acc += rows[j * g.nx + i]; z[j * g.nx + i] = acc; }
      }
      var img = document.createElement('canvas');
      img.width = g.nx; img.height = g.ny;
      cur = {doc: doc, z: z, deltas: arr.slice(1), applied: 0, t: 0, img: img, imgDirty: true};
      fit();
      slider.value = 0;
      buildLog();
      seek(0);
    });
  }
  function apply(k, sign) {
    var ev = cur.doc.events[k], d = cur.deltas[k], g = cur.doc.grid;
    if (!d) return;
    for (var jj = 0; jj < ev.delta.h; jj++)
      for (var ii = 0; ii < ev.delta.w; ii++)
        cur.z[(ev.delta.j + jj) * g.nx + ev.delta.i + ii] += sign * d[jj * ev.delta.w + ii];
    cur.imgDirty = true;
  }
  function seek(t) {
    var evs = cur.doc.events;
    cur.t = t;
    while (cur.applied < evs.length && evs[cur.applied].t1 <= t + 1e-9) { apply(cur.applied, 1); cur.applied++; }
    while (cur.applied > 0 && evs[cur.applied - 1].t1 > t + 1e-9) { cur.applied--; apply(cur.applied, -1); }
    draw();
  }
  function fit() {
    var g = cur.doc.grid, room = canvas.parentNode.clientWidth - 4;
    var w = Math.max(room < 900 ? room : Math.min(room * 0.72, 1100), 240);  // narrow windows: the log goes below
    w = Math.max(Math.min(w, 0.8 * window.innerHeight * g.nx / g.ny), 240);  // a tall map fits the window's height
    canvas.width = Math.round(w);
    canvas.height = Math.round(w * g.ny / g.nx);
  }
  function toPx(x, y) {
    var g = cur.doc.grid, s = canvas.width / (g.nx * g.r);
    return [(x - g.x0) * s, canvas.height - (y - g.y0) * s];
  }
  function scale() { var g = cur.doc.grid; return canvas.width / (g.nx * g.r); }
  function poly(pts, stroke, fill, dash, width) {
    ctx.beginPath();
    pts.forEach(function (p, k) { var q = toPx(p[0], p[1]); if (k) ctx.lineTo(q[0], q[1]); else ctx.moveTo(q[0], q[1]); });
    ctx.closePath();
    if (fill) { ctx.fillStyle = fill; ctx.fill(); }
    if (stroke) { ctx.setLineDash(dash || []); ctx.lineWidth = width || 1.5; ctx.strokeStyle = stroke; ctx.stroke(); ctx.setLineDash([]); }
  }
  function pose(mid, t) {
    var m = cur.doc.machines[mid], p = m.start.slice();
    for (var s = 0; s < m.segments.length; s++) {
      var seg = m.segments[s];
      if (seg[0][0] > t) break;
      for (var k = 0; k < seg.length; k++) {
        if (seg[k][0] > t) {
          var a = seg[k - 1], b = seg[k], u = (t - a[0]) / Math.max(b[0] - a[0], 1e-9);
          return [a[1] + u * (b[1] - a[1]), a[2] + u * (b[2] - a[2]), a[3] + u * (b[3] - a[3])];
        }
      }
      var last = seg[seg.length - 1];
      p = [last[1], last[2], last[3]];
    }
    return p;
  }
  function badMoves() {
    var out = {};
    cur.doc.events.forEach(function (ev) { if (ev.violations && ev.type === 'move') out[ev.t0 + ':' + ev.machine] = ev; });
    return out;
  }
  function drawPaths(t) {
    var bad = badMoves();
    Object.keys(cur.doc.machines).forEach(function (mid) {
      var m = cur.doc.machines[mid], at = [m.start[0], m.start[1]];
      m.segments.forEach(function (seg) {
        var red = bad[seg[0][0] + ':' + mid];
        var first = toPx(seg[0][1], seg[0][2]), from = toPx(at[0], at[1]);
        if (Math.hypot(first[0] - from[0], first[1] - from[1]) > 0.5 * scale() * 0.05 + 0.5) {
          ctx.beginPath(); ctx.moveTo(from[0], from[1]); ctx.lineTo(first[0], first[1]);
          ctx.setLineDash([4, 4]); ctx.strokeStyle = '#d00'; ctx.lineWidth = 2; ctx.stroke(); ctx.setLineDash([]);
        }
        ctx.beginPath();
        seg.forEach(function (smp, k) { var q = toPx(smp[1], smp[2]); if (k) ctx.lineTo(q[0], q[1]); else ctx.moveTo(q[0], q[1]); });
        ctx.strokeStyle = red ? '#d00' : COLOURS[mid] || '#000';
        ctx.globalAlpha = seg[0][0] <= t ? 0.95 : 0.3;
        ctx.lineWidth = red ? 2.5 : 1.5;
        ctx.stroke();
        ctx.globalAlpha = 1;
        var last = seg[seg.length - 1];
        at = [last[1], last[2]];
      });
    });
  }
  function drawMachine(mid, p, red) {
    var q = toPx(p[0], p[1]), s = scale();
    var inside = q[0] >= 0 && q[0] <= canvas.width && q[1] >= 0 && q[1] <= canvas.height;
    if (!inside) {  // off the map: a marker at the edge, pointing to where the machine is
      var cx = Math.max(10, Math.min(canvas.width - 10, q[0])), cy = Math.max(10, Math.min(canvas.height - 10, q[1]));
      var ang = Math.atan2(q[1] - cy, q[0] - cx);
      ctx.beginPath();
      ctx.moveTo(cx + 9 * Math.cos(ang), cy + 9 * Math.sin(ang));
      ctx.lineTo(cx + 7 * Math.cos(ang + 2.4), cy + 7 * Math.sin(ang + 2.4));
      ctx.lineTo(cx + 7 * Math.cos(ang - 2.4), cy + 7 * Math.sin(ang - 2.4));
      ctx.closePath();
      ctx.fillStyle = COLOURS[mid] || '#000'; ctx.fill();
      ctx.lineWidth = red ? 3 : 1; ctx.strokeStyle = red ? '#d00' : '#000'; ctx.stroke();
      ctx.font = '12px sans-serif'; ctx.fillStyle = '#000';
      ctx.textAlign = cx > canvas.width / 2 ? 'right' : 'left';
      ctx.fillText(mid + ' (' + p[0].toFixed(1) + ', ' + p[1].toFixed(1) + ')',
                   cx + (cx > canvas.width / 2 ? -12 : 12), cy + (cy > canvas.height / 2 ? -10 : 16));
      ctx.textAlign = 'left';
      return;
    }
    ctx.beginPath(); ctx.arc(q[0], q[1], Math.max(4, 0.35 * s), 0, 2 * Math.PI);
    ctx.fillStyle = COLOURS[mid] || '#000'; ctx.fill();
    ctx.lineWidth = red ? 3 : 1.5; ctx.strokeStyle = red ? '#d00' : '#000'; ctx.stroke();
    ctx.beginPath(); ctx.moveTo(q[0], q[1]);
    ctx.lineTo(q[0] + Math.cos(p[2]) * Math.max(10, 0.8 * s), q[1] - Math.sin(p[2]) * Math.max(10, 0.8 * s));
    ctx.strokeStyle = '#000'; ctx.lineWidth = 2; ctx.stroke();
  }
  function terrainImage() {
    var g = cur.doc.grid, ictx = cur.img.getContext('2d'), im = ictx.createImageData(g.nx, g.ny);
    var span = Math.max(g.hi - g.lo, 1e-6);
    for (var j = 0; j < g.ny; j++) {
      for (var i = 0; i < g.nx; i++) {
        var c = colour(cur.z[j * g.nx + i] * g.q / span), o = ((g.ny - 1 - j) * g.nx + i) * 4;
        im.data[o] = c[0]; im.data[o + 1] = c[1]; im.data[o + 2] = c[2]; im.data[o + 3] = 255;
      }
    }
    ictx.putImageData(im, 0, 0);
    cur.imgDirty = false;
  }
  function draw() {
    var doc = cur.doc, t = cur.t;
    if (cur.imgDirty) terrainImage();
    ctx.imageSmoothingEnabled = false;
    ctx.drawImage(cur.img, 0, 0, canvas.width, canvas.height);
    var loaded = cur.applied ? doc.events[cur.applied - 1].loaded : 0;
    clock.textContent = 't = ' + t.toFixed(1) + ' / ' + doc.makespan.toFixed(1) + ' s · loaded ' + loaded.toFixed(2) +
      ' of ' + doc.target.toFixed(2) + ' m³';
    if (!overlays.checked) return;
    poly(doc.dig_area, '#000', null, [6, 4], 1.2);
    doc.keep_outs.forEach(function (k) { poly(k, '#d00', 'rgba(220,0,0,0.25)'); });
    drawPaths(t);
    var active = {}, now = [];
    doc.events.forEach(function (ev, k) {
      if (ev.t0 > t + 1e-9) return;
      var done = ev.t1 <= t + 1e-9, bad = !!ev.violations;
      if (!done) { active[ev.machine] = ev; now.push(ev); }
      if (ev.fp) poly(ev.fp, bad ? '#d00' : (done ? '#000' : '#fff'), bad ? 'rgba(220,0,0,0.3)' : null, null, bad ? 2.5 : 1.2);
      if (ev.type === 'dump') {
        var tr = doc.machines.truck ? pose('truck', ev.t0) : pose(ev.machine, ev.t0), q = toPx(tr[0], tr[1]);
        ctx.fillStyle = bad ? '#d00' : '#5b3a1a'; ctx.strokeStyle = '#fff'; ctx.lineWidth = 1;
        ctx.fillRect(q[0] + 8 + 9 * (k % 5), q[1] - 18, 8, 8); ctx.strokeRect(q[0] + 8 + 9 * (k % 5), q[1] - 18, 8, 8);
      }
      if (bad && ev.type !== 'move' && !ev.fp) {
        var p = pose(ev.machine, ev.t0), r = toPx(p[0], p[1]);
        ctx.beginPath(); ctx.arc(r[0], r[1], 14, 0, 2 * Math.PI); ctx.strokeStyle = '#d00'; ctx.lineWidth = 3; ctx.stroke();
      }
    });
    if (doc.reach && doc.machines.excavator) {
      var e = pose('excavator', t), c = toPx(e[0], e[1]), s = scale();
      ctx.setLineDash([3, 5]); ctx.strokeStyle = 'rgba(0,0,0,0.55)'; ctx.lineWidth = 1;
      doc.reach.forEach(function (r) { ctx.beginPath(); ctx.arc(c[0], c[1], r * s, 0, 2 * Math.PI); ctx.stroke(); });
      ctx.setLineDash([]);
    }
    Object.keys(doc.machines).forEach(function (mid) {
      var ev = active[mid];
      drawMachine(mid, pose(mid, t), !!(ev && ev.violations));
    });
    nowEl.textContent = now.length
      ? 'now: ' + now.map(function (ev) { return ev.machine + ' ' + ev.type + ' (action ' + ev.a + ')'; }).join(', ')
      : '';
    Array.prototype.forEach.call(logEl.children, function (li) {
      li.classList.toggle('rp-done', parseFloat(li.getAttribute('data-t')) <= t + 1e-9);
    });
  }
  function buildLog() {
    var doc = cur.doc;
    verdictEl.textContent = doc.label + ': ' + doc.verdict;
    verdictEl.className = doc.verdict === 'valid' ? '' : 'rp-bad';
    while (logEl.firstChild) logEl.removeChild(logEl.firstChild);
    doc.plan_violations.forEach(function (v) {
      var li = document.createElement('li');
      li.className = 'rp-bad'; li.setAttribute('data-t', '0');
      li.textContent = 'plan: ' + v.rule + ' — ' + v.message;
      logEl.appendChild(li);
    });
    doc.events.forEach(function (ev) {
      if (ev.type === 'move' && !ev.violations) return;
      var li = document.createElement('li');
      li.setAttribute('data-t', String(ev.t0));
      li.textContent = ev.t0.toFixed(1) + ' s: ' + ev.machine + ' ' + ev.type + ' (action ' + ev.a + ')' +
        (ev.violations ? ' — ' + ev.violations.map(function (v) { return v.rule + ': ' + v.message; }).join('; ') : '');
      if (ev.violations) li.className = 'rp-bad';
      li.addEventListener('click', function () { setTime(ev.t1); });
      logEl.appendChild(li);
    });
  }
  function setTime(t) {
    if (!cur) return;
    t = Math.max(0, Math.min(cur.doc.makespan, t));
    slider.value = String(Math.round(1000 * t / Math.max(cur.doc.makespan, 1e-9)));
    seek(t);
  }
  function step(dir) {
    if (!cur) return;
    var ts = cur.doc.events.map(function (ev) { return ev.t1; }), t = cur.t;
    var next = dir > 0 ? ts.filter(function (x) { return x > t + 1e-6; })[0]
                       : ts.filter(function (x) { return x < t - 1e-6; }).pop();
    setTime(next === undefined ? (dir > 0 ? cur.doc.makespan : 0) : next);
  }
  function tick(ts) {
    if (!playing || !cur) return;
    var dt = lastFrame ? (ts - lastFrame) / 1000 : 0;
    lastFrame = ts;
    var t = cur.t + dt * Math.max(cur.doc.makespan / 20, 1);  // a whole plan plays in about 20 s
    if (t >= cur.doc.makespan) { setTime(cur.doc.makespan); togglePlay(false); return; }
    setTime(t);
    requestAnimationFrame(tick);
  }
  function togglePlay(on) {
    playing = on === undefined ? !playing : on;
    playBtn.textContent = playing ? '❚❚ Pause' : '▶ Play';
    if (playing) {
      if (cur.t >= cur.doc.makespan) setTime(0);
      lastFrame = 0; requestAnimationFrame(tick);
    }
  }
  slider.addEventListener('input', function () {
    if (cur) seek(cur.doc.makespan * parseFloat(slider.value) / 1000);
  });
  sel.addEventListener('change', function () { togglePlay(false); load(parseInt(sel.value, 10)); });
  overlays.addEventListener('change', function () { if (cur) draw(); });
  playBtn.addEventListener('click', function () { if (cur) togglePlay(); });
  document.getElementById('rp-prev').addEventListener('click', function () { step(-1); });
  document.getElementById('rp-next').addEventListener('click', function () { step(1); });
  window.addEventListener('resize', function () { if (cur) { fit(); draw(); } });
  // a ▶ button next to every run of the runs tables that has a replay
  var byRun = {};
  replays.forEach(function (doc, n) { if (doc.run !== null) byRun[String(doc.run)] = n; });
  document.querySelectorAll('table.runs tbody tr').forEach(function (tr) {
    var n = byRun[tr.cells[0].textContent.trim()];
    if (n === undefined) return;
    var b = document.createElement('button');
    b.type = 'button'; b.className = 'rp-open'; b.textContent = '▶'; b.title = 'replay this run';
    b.addEventListener('click', function (ev) {
      ev.stopPropagation();
      sel.value = String(n); togglePlay(false);
      load(n).then(function () { document.getElementById('replay').scrollIntoView(); });
    });
    tr.cells[0].appendChild(b);
  });
  // the links under each ranking table ("Replay a run"): open that run in the viewer
  document.querySelectorAll('a.rp-link').forEach(function (a) {
    var n = byRun[a.getAttribute('data-run')];
    if (n === undefined) { a.removeAttribute('href'); return; }
    a.addEventListener('click', function () { sel.value = String(n); togglePlay(false); load(n); });
  });
  window.earthbenchReplay = {load: load, setTime: setTime, state: function () {
    return cur ? {run: cur.doc.run, t: cur.t, applied: cur.applied, makespan: cur.doc.makespan} : null; }};
  window.earthbenchReplayReady = load(0);
})();
"""

CSS = """
#replay .rp-controls{display:flex;flex-wrap:wrap;gap:.4rem;align-items:center;margin:.5rem 0}
#replay select{max-width:100%}#replay input[type=range]{flex:1 1 16rem}
.rp-body{display:flex;flex-wrap:wrap;gap:1rem;align-items:flex-start}
#rp-canvas{border:1px solid #ccc;max-width:100%}
.rp-side{flex:1 1 16rem;font-size:.85rem;max-height:32rem;overflow:auto}
.rp-side li{cursor:pointer;color:#888}.rp-side li.rp-done{color:#222}
.rp-bad,.rp-side li.rp-bad{color:#c00;font-weight:600}
.rp-open{margin-left:.3rem;font-size:.7rem;padding:0 .25rem;cursor:pointer}
"""


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
