"""Publishing: the store → ``leaderboard/`` (DESIGN §6).

:func:`publish` writes, for every suite in the store (or the ones asked for):

* ``README.md`` — one table per suite and track, ranked by the rule stated above it
  (:data:`metrics.aggregate.RANKING_RULE`), with a reproducibility stamp (project commits,
  suite digest, CPU models and cores, run dates, generation date), what each figure rests on
  (referee figures re-judgeable from the stored plans; solve times from the machine named for
  each planner, † on solve-time columns that mix machines; the latest ``earthbench verify``
  spot re-timing of each planner version) and the figures;
* ``runs.csv`` — one row per run and suite it is published under (a run of ``paper-switch``
  also counts for ``standard``, which includes it), every column of
  :func:`earthbench.store.load_runs`;
* ``summary.csv`` — :func:`metrics.aggregate.aggregate` of those runs;
* ``index.html`` — one self-contained page: inline CSS, a small inline script (allowed by a
  content-security policy hash, so no other script can run), tables that sort on a click
  and the figures as ``data:`` URIs; no network resource. Every string from the store (and
  so from a plugin) is escaped with :func:`html.escape`;
* ``figures/`` (PNG and SVG, matplotlib) per suite and track: ``*-volume-time`` (loaded volume
  against the plan's total execution time, one colour per planner, as the STL-TAMP paper's
  Fig. 7a), ``*-profiles`` (Dolan–Moré performance profiles over time per m³ and over solve
  time; solve-time profiles are drawn per CPU model when the runs come from several), and
  ``*-terrain-PLANNER`` (terrain before and after, with machine paths and digs, for one case
  per planner: the scenario most planners have a plan for; its stored plan is judged again
  with :func:`earthbench.referee.judge` on the scenario the store keeps under the run's digest.
  That copy is checked to reproduce the digest, so it is exactly the scenario the suite
  generates; regenerating the suite instead would cost seconds per suite (7 s for
  ``standard``) and fail on a machine without the suite's plugins).
"""

from __future__ import annotations

import base64
import hashlib
import html
import io
import math
import re
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from metrics.aggregate import REASONS, RANKING_RULE, aggregate
from metrics.profiles import cost_matrix, profile

from .scaling import SCALE_CAPTION, cost_growth_figure, scale_section
from .store import Store, load_runs
from .verify import latest_spot_checks, machine_label

#: Termination reasons shown as columns of the tables (``ok`` is in the success rate).
FAILURE_COLUMNS = ("invalid", "timeout", "memory", "error", "crashed")


@dataclass
class Published:
    """What :func:`publish` wrote."""

    out: Path
    files: list[Path] = field(default_factory=list)
    runs: pd.DataFrame | None = None
    summary: pd.DataFrame | None = None


# -- loading ---------------------------------------------------------------------------------------


def published_runs(db: str | Path | Store, suites: Sequence[str] | None = None) -> pd.DataFrame:
    """The runs of each suite (all suites that ran when ``suites`` is empty), with a ``solver`` label.

    Each suite's frame comes from ``load_runs(db, suite)``, so a suite counts every stored run
    of its scenarios, whichever suite ran them.
    """
    store = db if isinstance(db, Store) else Store(db, create=False)
    try:
        if not suites:
            suites = sorted(load_runs(store)["suite"].dropna().unique().tolist())
        frames = [load_runs(store, suite=s) for s in suites]
    finally:
        if not isinstance(db, Store):
            store.close()
    frames = [f for f in frames if len(f)]
    if not frames:
        return load_runs_empty()
    runs = pd.concat(frames, ignore_index=True)
    runs["solver"] = solver_labels(runs)
    return runs


def suite_sizes(store: Store, names: Iterable[str]) -> dict[str, int]:
    """Suite name → scenario count of its most recently registered version (as ``load_runs`` uses)."""
    out = {}
    for name in names:
        ver = store.suite_version(name)
        if ver is not None:
            out[name] = store.db.execute("SELECT COUNT(*) FROM suite_scenarios WHERE suite_id=?", (ver["id"],)).fetchone()[0]
    return out


def load_runs_empty() -> pd.DataFrame:
    return pd.DataFrame(columns=["id", "suite", "suite_digest", "scenario_id", "scenario_digest", "track", "planner",
                                 "planner_version", "config_hash", "reason", "success", "solver"])


def solver_labels(runs: pd.DataFrame) -> pd.Series:
    """``planner version``, plus ``[config hash]`` where one planner version ran several configs."""
    n_cfg = runs.groupby(["planner", "planner_version"])["config_hash"].transform("nunique")
    base = runs["planner"].astype(str) + " " + runs["planner_version"].astype(str)
    return base.where(n_cfg <= 1, base + " [" + runs["config_hash"].astype(str).str[:8] + "]")


# -- formatting ------------------------------------------------------------------------------------


def _f(v: Any, spec: str = ".2f") -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "–"
    if isinstance(v, float) and math.isinf(v):
        return "∞"
    return format(v, spec)


_MD_SPECIAL = re.compile(r"([\\`*_\[\]|<>~])")


def md_escape(text: Any) -> str:
    """Text safe in a Markdown table cell: markup characters backslash-escaped, no newlines."""
    s = str(text).replace("\r", " ").replace("\n", " ")
    return _MD_SPECIAL.sub(r"\\\1", s)


def mpl_text(text: Any) -> str:
    """Text matplotlib draws literally (``$`` would start mathtext)."""
    return str(text).replace("$", r"\$")


def slug(text: str) -> str:
    s = re.sub(r"[^A-Za-z0-9_-]+", "-", text).strip("-")[:40]
    return (s or "x") + "-" + hashlib.sha1(text.encode()).hexdigest()[:6]


def table_rows(summary: pd.DataFrame) -> list[dict[str, Any]]:
    """Display values (text) and sort keys (numbers) of one table's rows, in rank order."""
    rows = []
    for _, r in summary.iterrows():
        vr = _f(r["volume_ratio_mean"]) + ("" if pd.isna(r["volume_ratio_sd"]) else f" ± {_f(r['volume_ratio_sd'])}")
        tpm = _f(r["time_per_m3_median"], ".1f") + (
            "" if pd.isna(r["time_per_m3_q1"]) else f" ({_f(r['time_per_m3_q1'], '.1f')}–{_f(r['time_per_m3_q3'], '.1f')})")
        rows.append({
            "cells": [
                ("Rank", str(r["rank"]), r["rank"]),
                ("Planner", str(r["planner"]), None),
                ("Version", str(r["planner_version"]), None),
                ("Config", str(r["config_hash"])[:8], None),
                ("Runs", f"{r['runs']}/{r['of']}", r["runs"]),
                ("Success", f"{100 * r['success_rate']:.0f}%", r["success_rate"]),
                ("Volume ratio (mean ± SD)", vr, r["volume_ratio_mean"]),
                ("Time per m³, s (median, IQR)", tpm, r["time_per_m3_median"]),
                ("× lower bound", _f(r["time_per_m3_ratio_median"], ".2f"), r["time_per_m3_ratio_median"]),
                ("Solve s (median)", _f(r["solve_time_median"], ".2f"), r["solve_time_median"]),
                ("Solve s (p90)", _f(r["solve_time_p90"], ".2f"), r["solve_time_p90"]),
                *((reason, str(r[f"n_{reason}"]), r[f"n_{reason}"]) for reason in FAILURE_COLUMNS),
            ]
        })
    return rows


@dataclass
class Stamp:
    """Where a table's numbers come from."""

    suite: str
    track: str
    suite_digest: str
    threshold: float
    commits: list[str]
    cpus: list[str]
    first: str
    last: str
    generated: str
    n_models: int = 1
    solve_machines: list[str] = field(default_factory=list)  #: per planner: the machines its solve times come from
    spot_checks: list[str] = field(default_factory=list)     #: ``earthbench verify`` re-timings of these planners
    n_machines: int = 1

    @property
    def mixed(self) -> bool:
        """Whether the table's solve times were measured on more than one machine."""
        return self.n_machines > 1

    def lines(self) -> list[str]:
        commits = ", ".join(self.commits[:3]) + (f" and {len(self.commits) - 3} more" if len(self.commits) > 3 else "")
        return [
            f"suite digest: {self.suite_digest}",
            f"success threshold: volume ratio ≥ {self.threshold:g} with a valid plan",
            f"project commit: {commits or 'unknown'}",
            f"CPU: {'; '.join(self.cpus) or 'unknown'}" + (" (solve times mixed from several CPU models)" if self.n_models > 1 else ""),
            f"runs: {self.first or '?'} to {self.last or '?'}; generated {self.generated}",
            PROVENANCE,
            *(["† solve-time columns mix machines: compare those figures only between rows from the same machine"] if self.mixed else []),
        ]

    def planner_lines(self) -> list[str]:
        """Per planner: where its solve times come from, and its spot re-timings (text from the store)."""
        return [*self.solve_machines, *(f"spot re-timing: {line}" for line in self.spot_checks)]


#: What each figure of a table rests on (stated in every stamp).
PROVENANCE = ("provenance: success, volume and time-per-m³ figures are the referee's, recomputed from the stored plans "
              "when stores are merged (`earthbench merge` re-judges every plan); solve times, CPU times and memory are "
              "as measured on the machine that ran each case (below), and can only be spot-checked by rerunning "
              "(`earthbench verify`)")


def _machine_of(runs: pd.DataFrame) -> pd.Series:
    """Each run's machine, labelled as :func:`earthbench.verify.machine_label` does."""
    cols = {"hostname": "hostname", "cpu_model": "cpu_model", "cores": "cpu_cores"}
    get = {k: (runs[c] if c in runs else pd.Series(None, index=runs.index)) for k, c in cols.items()}
    return pd.Series([machine_label({k: (None if pd.isna(get[k].iloc[i]) else get[k].iloc[i]) for k in cols})
                      for i in range(len(runs))], index=runs.index, dtype=object)


def stamp(runs: pd.DataFrame, suite: str, track: str, generated: str, spot_checks: Sequence[Any] = ()) -> Stamp:
    """The stamp of one table; ``spot_checks`` (:class:`earthbench.verify.SpotCheck`) of its planners are listed."""
    def uniq(col: str) -> list[str]:
        return sorted({str(v) for v in runs[col].dropna()}) if col in runs else []

    cpus = []
    if "cpu_model" in runs:
        for (model, cores), _ in runs.groupby([runs["cpu_model"].fillna("unknown"), runs["cpu_cores"].fillna(-1)]):
            cpus.append(f"{model}, {int(cores)} cores" if cores >= 0 else str(model))
    digests = uniq("suite_digest")
    started, finished = uniq("started_at"), uniq("finished_at")
    thr = runs["threshold"].dropna()
    timed = runs[runs["solve_time_s"].notna()] if "solve_time_s" in runs else runs.iloc[:0]
    machine = _machine_of(timed)
    solve_machines = []
    for solver, g in machine.groupby(timed["solver"] if "solver" in timed else timed["planner"], sort=True):
        where = "; ".join(f"{m} ({n} run{'s' if n != 1 else ''})" for m, n in g.value_counts().sort_index().items())
        solve_machines.append(f"solve times of {solver}: {where}")
    versions = set(zip(runs["planner"], runs["planner_version"])) if len(runs) else set()
    spots = [c.line() for c in spot_checks if (c.planner, c.version) in versions]
    return Stamp(suite, track, ", ".join(digests), float(thr.iloc[0]) if len(thr) else float("nan"), uniq("project_commit"),
                 cpus, started[0] if started else "", finished[-1] if finished else "", generated,
                 max(1, len(uniq("cpu_model"))), solve_machines, spots, max(1, machine.nunique()))


def mark_mixed_solve_columns(rows: list[dict[str, Any]], mixed: bool) -> list[dict[str, Any]]:
    """Headings of solve-time columns get a † when the table's solve times come from several machines."""
    if not mixed:
        return rows
    return [{**r, "cells": [((h + " †") if h.startswith("Solve") else h, text, key) for h, text, key in r["cells"]]} for r in rows]


# -- figures ---------------------------------------------------------------------------------------


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _colours(solvers: Iterable[str]) -> dict[str, Any]:
    plt = _plt()
    cmap = plt.get_cmap("tab10")
    return {s: cmap(i % 10) for i, s in enumerate(sorted(solvers))}


def volume_time_figure(runs: pd.DataFrame, title: str):
    """Loaded volume against total execution time (the plan's makespan) per run and planner."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4.8), constrained_layout=True)
    have = runs[runs["reason"].isin(["ok", "invalid"]) & runs["makespan_s"].notna()] if "makespan_s" in runs else runs.iloc[:0]
    colours = _colours(runs["solver"].unique())
    for solver, g in have.groupby("solver"):
        c = colours[solver]
        ok = g["reason"] == "ok"
        succ = ok & g["success"].astype(bool)
        ax.scatter(g.loc[succ, "makespan_s"], g.loc[succ, "loaded_volume"], s=18, color=c, label=mpl_text(solver))
        ax.scatter(g.loc[ok & ~succ, "makespan_s"], g.loc[ok & ~succ, "loaded_volume"], s=18, facecolors="none", edgecolors=c)
        ax.scatter(g.loc[~ok, "makespan_s"], g.loc[~ok, "loaded_volume"], s=18, color=c, marker="x")
    ax.set_xlabel("total time of the plan (makespan), s")
    ax.set_ylabel("loaded volume, m³")
    ax.set_title(mpl_text(title) + "\nfilled: success; hollow: valid, below threshold; ×: invalid", fontsize=9)
    ax.grid(alpha=0.3)
    if len(have):
        ax.legend(fontsize=7, loc="best")
    else:
        ax.text(0.5, 0.5, "no plans stored", ha="center", va="center", transform=ax.transAxes)
    return fig


def _draw_profile(ax, rho: pd.DataFrame, colours: dict[str, Any], xlabel: str, title: str) -> None:
    taus = rho.index.to_numpy()
    right = max(2.0, float(taus.max()) * 1.5) if len(taus) else 2.0
    for solver in rho.columns:
        x = np.append(taus, right)
        y = np.append(rho[solver].to_numpy(), rho[solver].to_numpy()[-1] if len(taus) else 0.0)
        ax.step(x, y, where="post", color=colours.get(solver), label=mpl_text(solver))
    ax.set_xscale("log", base=2)
    ax.set_xlim(1, right)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("fraction of scenarios ρ(τ)")
    ax.set_title(mpl_text(title), fontsize=9)
    ax.grid(alpha=0.3)


def profiles_figure(runs: pd.DataFrame, title: str):
    """Performance profiles over time per m³ and over solve time (one panel per CPU model)."""
    plt = _plt()
    colours = _colours(runs["solver"].unique())
    models = sorted(runs["cpu_model"].fillna("unknown CPU").unique()) if "cpu_model" in runs else ["unknown CPU"]
    fig, axes = plt.subplots(1, 1 + len(models), figsize=(5.2 * (1 + len(models)), 4.2), constrained_layout=True, squeeze=False)
    axes = axes[0]
    solvers = sorted(runs["solver"].unique())
    c = cost_matrix(runs, "time_per_m3").reindex(columns=solvers, fill_value=np.inf)
    _draw_profile(axes[0], profile(c), colours, "τ (time per m³ within τ × the best)", "time per m³")
    cpu = runs["cpu_model"].fillna("unknown CPU") if "cpu_model" in runs else pd.Series("unknown CPU", index=runs.index)
    for ax, model in zip(axes[1:], models):
        sub = runs[cpu == model]  # only the planners that ran on this CPU model are compared here
        c = cost_matrix(sub, "solve_time_s").reindex(columns=sorted(sub["solver"].unique()), fill_value=np.inf)
        label = "solve time" + (f" — only runs on {model}" if len(models) > 1 else "")
        _draw_profile(ax, profile(c), colours, "τ (solve time within τ × the best)", label)
    axes[0].legend(fontsize=7, loc="lower right")
    fig.suptitle(mpl_text(title) + " — failures count as never solved", fontsize=10)
    return fig


def sample_runs(runs: pd.DataFrame) -> pd.DataFrame:
    """One run with a plan per solver: on the scenario most solvers have a plan for."""
    have = runs[runs["reason"].isin(["ok", "invalid"])]
    if have.empty:
        return have
    counts = have.groupby("scenario_digest")["solver"].nunique()
    first_id = have.groupby("scenario_digest")["scenario_id"].min()
    order = sorted(counts.index, key=lambda d: (-counts[d], first_id[d]))
    best = order[0]
    picks = []
    for solver, g in have.groupby("solver"):
        on = g[g["scenario_digest"] == best]
        if len(on):
            picks.append(on.iloc[0])
        else:  # this solver has no plan there: its first scenario in the preferred order
            rank = {d: i for i, d in enumerate(order)}
            picks.append(g.loc[g["scenario_digest"].map(rank).idxmin()])
    return pd.DataFrame(picks)


def terrain_figure(scenario_json: str, plan_json: str, title: str):
    """Judge a stored plan again on its scenario and draw :func:`earthbench.figures.terrain_before_after`."""
    from .figures import terrain_before_after
    from .plan import Plan
    from .referee import judge
    from .world import Scenario

    scenario = Scenario.from_json(scenario_json)
    plan = Plan.from_json(plan_json)
    verdict = judge(scenario, plan)
    fig = terrain_before_after(scenario, plan, verdict)
    fig.suptitle(mpl_text(title), fontsize=10)
    return fig


#: Columns the run figures read (the frame shipped to a figure worker).
FIGURE_COLUMNS = ["scenario_digest", "solver", "reason", "success", "makespan_s", "loaded_volume", "time_per_m3",
                  "solve_time_s", "cpu_model"]


def _render(job: tuple[str, str, tuple[Any, ...]]) -> bytes:
    """Draw one figure and save it as PNG and SVG; return the PNG (runs in a worker process)."""
    kind, base, args = job
    maker = {"volume-time": volume_time_figure, "profiles": profiles_figure, "terrain": terrain_figure,
             "cost-growth": cost_growth_figure}[kind]
    return _save(maker(*args), Path(base))[2]


def render_all(jobs: list[tuple[str, str, tuple[Any, ...]]], workers: int | None = None) -> list[bytes]:
    """Render figure jobs, in parallel worker processes when there are several cores (fork on Linux)."""
    import multiprocessing as mp
    import os

    n = min(len(jobs), workers if workers else len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1)
    if n <= 1 or "fork" not in mp.get_all_start_methods():
        return [_render(j) for j in jobs]
    from concurrent.futures import ProcessPoolExecutor

    plt = _plt()  # load fonts and the mathtext parser once, before the workers fork
    warm = plt.figure()
    warm.text(0.5, 0.5, "m³ τ ρ")
    warm.canvas.draw()
    plt.close(warm)
    with ProcessPoolExecutor(max_workers=n, mp_context=mp.get_context("fork")) as pool:
        return list(pool.map(_render, jobs))


def _save(fig, base: Path) -> tuple[Path, Path, bytes]:
    """Write ``base.png`` and ``base.svg``; return the paths and the PNG bytes."""
    plt = _plt()
    engine = fig.get_layout_engine()
    if engine is not None:  # lay out once, not once per format (the same pixels, a fifth less time)
        engine.execute(fig)
        fig.set_layout_engine("none")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    png = buf.getvalue()
    png_path, svg_path = base.parent / (base.name + ".png"), base.parent / (base.name + ".svg")
    png_path.write_bytes(png)
    fig.savefig(svg_path, format="svg", metadata={"Date": None})
    plt.close(fig)
    return png_path, svg_path, png


# -- Markdown and HTML -------------------------------------------------------------------------------


def markdown_table(rows: list[dict[str, Any]]) -> str:
    if not rows:
        return "(no runs)\n"
    head = [c[0] for c in rows[0]["cells"]]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---:" if i not in (1, 2, 3) else "---" for i in range(len(head))) + "|"]
    for r in rows:
        lines.append("| " + " | ".join(md_escape(c[1]) for c in r["cells"]) + " |")
    return "\n".join(lines) + "\n"


def _sortkey(v: Any) -> str:
    if v is None:
        return ""
    try:
        x = float(v)
    except (TypeError, ValueError):
        return ""
    if math.isnan(x):
        return ""
    return "Infinity" if x == math.inf else ("-Infinity" if x == -math.inf else repr(x))


def html_table(rows: list[dict[str, Any]], caption: str = "", cls: str = "sortable") -> str:
    e = html.escape
    if not rows:
        return "<p>(no runs)</p>"
    head = "".join(f'<th scope="col" title="click to sort">{e(c[0])}</th>' for c in rows[0]["cells"])
    body = []
    for r in rows:
        tds = []
        for _, text, key in r["cells"]:
            k = _sortkey(key)
            tds.append(f'<td data-v="{e(k)}">{e(text)}</td>' if key is not None else f"<td>{e(text)}</td>")
        body.append("<tr>" + "".join(tds) + "</tr>")
    cap = f"<caption>{e(caption)}</caption>" if caption else ""
    return (f'<div class="wrap"><table class="{cls}">{cap}<thead><tr>{head}</tr></thead><tbody>\n' + "\n".join(body)
            + "\n</tbody></table></div>")


RUN_COLUMNS = [("id", "Run"), ("scenario_id", "Scenario"), ("solver", "Planner"), ("reason", "Reason"),
               ("success", "Success"), ("volume_ratio", "Volume ratio"), ("time_per_m3", "Time per m³, s"),
               ("time_per_m3_ratio", "× bound"), ("solve_time_s", "Solve s"), ("violation_rules", "Violations"),
               ("cpu_model", "CPU"), ("hostname", "Host")]
_NUMERIC_RUN = {"id", "volume_ratio", "time_per_m3", "time_per_m3_ratio", "solve_time_s"}


def run_rows(runs: pd.DataFrame) -> list[dict[str, Any]]:
    cols = [(c, h) for c, h in RUN_COLUMNS if c in runs]
    out = []
    data = {c: runs[c].tolist() for c, _ in cols}
    for i in range(len(runs)):
        cells = []
        for c, h in cols:
            v = data[c][i]
            if c in _NUMERIC_RUN:
                x = None if v is None or (isinstance(v, float) and math.isnan(v)) else float(v)
                cells.append((h, _f(x, ".0f" if c == "id" else ".3g"), x if x is not None else float("nan")))
            elif c == "success":
                cells.append((h, "yes" if bool(v) else "no", 1.0 if bool(v) else 0.0))
            else:
                cells.append((h, "" if v is None or (isinstance(v, float) and math.isnan(v)) else str(v), None))
        out.append({"cells": cells})
    return out


_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:2rem auto;max-width:1200px;padding:0 1rem;color:#222}
h1{font-size:1.6rem}h2{font-size:1.25rem;margin-top:2.5rem;border-bottom:1px solid #ccc}
table{border-collapse:collapse;margin:1rem 0;font-size:.85rem}
th,td{border:1px solid #ddd;padding:.25rem .5rem;text-align:right;white-space:nowrap}
td:nth-child(2),td:nth-child(3),th:nth-child(2),th:nth-child(3){text-align:left}
th{background:#f3f3f3;cursor:pointer;user-select:none}
th[aria-sort=ascending]::after{content:" ▲"}th[aria-sort=descending]::after{content:" ▼"}
tbody tr:nth-child(even){background:#fafafa}
.stamp{font-family:ui-monospace,monospace;font-size:.8rem;background:#f7f7f7;padding:.5rem;white-space:pre-wrap}
.rule{font-style:italic}
figure{margin:1rem 0}figure img{max-width:min(100%,1000px);border:1px solid #eee}
details{margin:1rem 0}.wrap{overflow-x:auto}details .wrap{max-height:30rem;overflow:auto}
"""

_JS = """
(function () {
  function key(row, i) {
    var c = row.cells[i];
    if (c.hasAttribute('data-v')) {
      var s = c.getAttribute('data-v');
      return s === '' ? null : parseFloat(s);
    }
    return c.textContent.trim().toLowerCase();
  }
  function sortBy(th) {
    var table = th.closest('table');
    var i = Array.prototype.indexOf.call(th.parentNode.children, th);
    var asc = th.getAttribute('aria-sort') !== 'ascending';
    table.querySelectorAll('th').forEach(function (h) { h.removeAttribute('aria-sort'); });
    th.setAttribute('aria-sort', asc ? 'ascending' : 'descending');
    var body = table.tBodies[0];
    var rows = Array.prototype.slice.call(body.rows);
    var keyed = rows.map(function (r, n) { return [key(r, i), n, r]; });
    keyed.sort(function (a, b) {
      var x = a[0], y = b[0];
      if (x === null && y === null) return a[1] - b[1];
      if (x === null) return 1;
      if (y === null) return -1;
      var d = typeof x === 'number' && typeof y === 'number' ? (x < y ? -1 : x > y ? 1 : 0)
                                                          : String(x).localeCompare(String(y));
      return (asc ? d : -d) || a[1] - b[1];
    });
    var frag = document.createDocumentFragment();
    keyed.forEach(function (k) { frag.appendChild(k[2]); });
    body.appendChild(frag);
  }
  document.querySelectorAll('table.sortable th').forEach(function (th) {
    th.addEventListener('click', function () { sortBy(th); });
  });
})();
"""


def html_page(sections: list[dict[str, Any]], generated: str) -> str:
    e = html.escape
    script_hash = base64.b64encode(hashlib.sha256(_JS.encode()).digest()).decode()
    csp = (f"default-src 'none'; img-src data:; style-src 'unsafe-inline'; script-src 'sha256-{script_hash}'; "
           "base-uri 'none'; form-action 'none'")
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f'<meta http-equiv="Content-Security-Policy" content="{e(csp)}">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        "<title>earthbench leaderboard</title>",
        f"<style>{_CSS}</style></head><body>",
        "<h1>earthbench leaderboard</h1>",
        f"<p>Generated {e(generated)} by <code>earthbench leaderboard</code>. Click a column heading to sort. "
        "Invalid plans are counted, never ranked. Tables: <code>summary.csv</code>; every run: <code>runs.csv</code>.</p>",
    ]
    if not sections:
        parts.append("<p>No runs in the store.</p>")
    for s in sections:
        anchor = "s-" + slug(f"{s['suite']}-{s['track']}")
        parts.append(f'<section id="{e(anchor)}"><h2>Suite {e(s["suite"])} — track {e(s["track"])}</h2>')
        parts.append(f'<p class="rule">Ranking: {e(RANKING_RULE)}.</p>')
        parts.append(f'<div class="stamp">{e(chr(10).join(s["stamp"].lines() + s["stamp"].planner_lines()))}</div>')
        parts.append(html_table(s["rows"]))
        if s.get("scale_rows"):
            parts.append(html_table(s["scale_rows"], caption="scale: cost against target volume (median [IQR] over seeds)"))
        for cap, png in s["figures"]:
            data = base64.b64encode(png).decode()
            parts.append(f'<figure><img alt="{e(cap)}" src="data:image/png;base64,{data}"><figcaption>{e(cap)}</figcaption></figure>')
        parts.append(f"<details><summary>All {len(s['run_rows'])} runs of this table</summary>")
        parts.append(html_table(s["run_rows"], cls="sortable runs"))
        parts.append("</details></section>")
    parts.append(f"<script>{_JS}</script></body></html>")
    return "\n".join(parts) + "\n"


# -- the whole leaderboard ---------------------------------------------------------------------------


#: Leading characters that make a spreadsheet read a text cell as a formula (or a DDE call).
FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")


def spreadsheet_safe(df: pd.DataFrame) -> pd.DataFrame:
    """A copy whose text cells cannot run as formulas: a leading ``=``, ``+``, ``-``, ``@``, tab or
    carriage return gets a ``'`` before it (a planner's error text or name is not ours to trust)."""
    out = df.copy()
    for col in out.columns:
        if not (pd.api.types.is_numeric_dtype(out[col]) or pd.api.types.is_datetime64_any_dtype(out[col])):
            out[col] = out[col].astype(object).map(lambda v: "'" + v if isinstance(v, str) and v.startswith(FORMULA_STARTS) else v)
    return out


def publish(db: str | Path, out: str | Path = "leaderboard", suites: Sequence[str] | None = None, *,
            figures: bool = True, terrain: bool = True, generated: str | None = None,
            workers: int | None = None) -> Published:
    """Write the leaderboard of ``db`` (the suites in ``suites``, default all) into ``out``.

    ``workers``: processes drawing the figures (default: one per core this process may use).
    """
    out = Path(out)
    fig_dir = out / "figures"
    generated = generated or datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    result = Published(out)
    jobs: list[tuple[str, str, tuple[Any, ...]]] = []
    captions: list[tuple[dict[str, Any], str, Path]] = []
    with Store(db, create=False) as store:
        runs = published_runs(store, suites)
        summary = aggregate(runs, suite_sizes(store, runs["suite"].unique()))
        spot_checks = latest_spot_checks(store)
        result.runs, result.summary = runs, summary
        sections = []
        scenarios: dict[str, str] = {}
        for (suite, track), srun in runs.groupby(["suite", "track"], sort=True):
            ssum = summary[(summary["suite"] == suite) & (summary["track"] == track)]
            st = stamp(srun, suite, track, generated, spot_checks)
            sec: dict[str, Any] = {
                "suite": suite, "track": track, "rows": mark_mixed_solve_columns(table_rows(ssum), st.mixed), "stamp": st,
                "figures": [], "md_figures": [], "run_rows": run_rows(srun.sort_values("id")),
            }
            sections.append(sec)
            base = slug(f"{suite}-{track}")
            title = f"suite {suite}, {track}"
            scale_rows, job = scale_section(srun, str(fig_dir / f"{base}-cost-growth"), title)
            sec["scale_rows"] = mark_mixed_solve_columns(scale_rows, st.mixed) if scale_rows else scale_rows
            if not figures:
                continue
            if job is not None:
                jobs.append(job)
                captions.append((sec, SCALE_CAPTION, Path(job[1])))
            cols = srun[[c for c in FIGURE_COLUMNS if c in srun]]
            for kind, cap in (("volume-time", "Loaded volume against total time per run (as in the STL-TAMP paper, Fig. 7a)"),
                              ("profiles", "Performance profiles: time per m³ and solve time (failures never solved)")):
                path = fig_dir / f"{base}-{kind}"
                jobs.append((kind, str(path), (cols, title)))
                captions.append((sec, cap, path))
            if terrain:
                for _, run in sample_runs(srun).iterrows():
                    digest = run["scenario_digest"]
                    if digest not in scenarios:
                        sc = store.scenario(digest)
                        if sc.digest != digest:  # never draw a plan on a terrain it was not made for
                            warnings.warn(f"stored scenario {run['scenario_id']} does not reproduce its digest; "
                                          "no terrain figure for it", stacklevel=2)
                            continue
                        scenarios[digest] = sc.to_json()
                    plan = store.plan_json(int(run["id"]))
                    path = fig_dir / f"{base}-terrain-{slug(str(run['solver']))}"
                    jobs.append(("terrain", str(path), (scenarios[digest], plan, f"{run['solver']} on {run['scenario_id']}")))
                    captions.append((sec, f"Terrain before and after: {run['solver']} on {run['scenario_id']} (run {run['id']})", path))
    fig_dir.mkdir(parents=True, exist_ok=True)  # only now: a refused leaderboard writes nothing
    for (sec, cap, path), png in zip(captions, render_all(jobs, workers)):
        png_path, svg_path = path.parent / (path.name + ".png"), path.parent / (path.name + ".svg")
        result.files += [png_path, svg_path]
        sec["figures"].append((cap, png))
        sec["md_figures"].append((cap, png_path.relative_to(out), svg_path.relative_to(out)))
    runs_csv = runs.drop(columns=[c for c in ("packages",) if c in runs])
    spreadsheet_safe(runs_csv).to_csv(out / "runs.csv", index=False)
    spreadsheet_safe(summary).to_csv(out / "summary.csv", index=False)
    (out / "README.md").write_text(markdown_page(sections, generated))
    (out / "index.html").write_text(html_page(sections, generated))
    result.files += [out / "README.md", out / "runs.csv", out / "summary.csv", out / "index.html"]
    return result


def markdown_page(sections: list[dict[str, Any]], generated: str) -> str:
    lines = ["# earthbench leaderboard", "",
             f"Generated {generated} by `earthbench leaderboard`. Invalid plans are counted, never ranked; "
             "`–` means no value (no valid run). Columns: runs stored / scenarios in the suite; success rate over the "
             "suite's scenarios (a scenario without a run is a failure); volume ratio over valid runs; "
             "time per m³ over valid runs that loaded something, with its ratio to the scenario's lower bound; "
             "solve time over all runs; counts of each failure. Every run: [runs.csv](runs.csv); "
             "these tables: [summary.csv](summary.csv); sortable page: [index.html](index.html).", ""]
    if not sections:
        lines.append("No runs in the store.")
    for s in sections:
        lines += [f"## Suite {md_escape(s['suite'])} — track {md_escape(s['track'])}", "",
                  f"Ranking: {RANKING_RULE}.", "", "```", *(line.replace("`", "'") for line in s["stamp"].lines()), "```", "",
                  *(f"- {md_escape(line)}" for line in s["stamp"].planner_lines()), "", markdown_table(s["rows"])]
        if s.get("scale_rows"):
            lines += ["", "scale: cost against target volume, median [interquartile range] over seeds of the valid runs "
                      "(growth: solve s/m³ over the smallest target's).", "", markdown_table(s["scale_rows"])]
        for cap, png, svg in s["md_figures"]:
            lines += [f"![{md_escape(cap)}]({png.as_posix()})", "", f"*{md_escape(cap)}* ([SVG]({svg.as_posix()}))", ""]
    return "\n".join(lines) + "\n"


__all__ = ["FAILURE_COLUMNS", "REASONS", "Published", "publish", "published_runs", "solver_labels"]
