"""Publishing: the store → ``leaderboard/`` (docs/DESIGN.md §9).

:func:`publish` writes, for every suite in the store (or the ones asked for):

* ``README.md`` — one table per suite and track, ranked by the rule stated above it
  (:data:`earthbench.aggregate.RANKING_RULE`: the latest version of each planner, shared ranks
  where paired tests cannot separate neighbours), with a reproducibility stamp (project
  commits, suite digest, CPU models and cores, run dates, generation date), what each figure
  rests on (referee figures re-judgeable from the stored plans; solve times from the machine
  named for each planner, † on solve-time columns that mix machines; the latest
  ``earthbench verify`` spot re-timing of each planner version); under it one table per family
  and per target, a history table of older versions, and the figures;
* ``runs.csv`` — one row per run and suite it is published under (a run of ``paper-switch``
  also counts for ``standard``, which includes it), every column of
  :func:`earthbench.store.load_runs`;
* ``summary.csv`` — :func:`earthbench.aggregate.aggregate` of those runs, every table (columns
  ``scope`` = suite | family | target and ``group``), medians and rates with their 95 % intervals
  (:data:`earthbench.stats.INTERVAL_NOTE`); a table with too few scenarios for any paired test to
  separate two planners has ``‡`` on its Rank heading and the stamp says so (:func:`earthbench.stats.separation_note`);
* ``index.html`` — one self-contained page: inline CSS, a small inline script (allowed by a
  content-security policy hash, so no other script can run), tables that sort on a click,
  filter by family, planner and version (``data-*`` attributes of each row, :data:`FILTERS`)
  and wrap their headings to fit the window, links to the CSVs, the figures as ``data:`` URIs
  and the replay viewer of :mod:`earthbench.replay`; no network resource. Every string from
  the store (and so from a plugin) is escaped with :func:`html.escape`;
* ``figures/`` (PNG and SVG, matplotlib) per suite and track: ``*-volume-time`` (loaded volume
  against the plan's total execution time, one colour per planner, as the STL-TAMP paper's
  Fig. 7a), ``*-profiles`` (Dolan–Moré performance profiles over time per target m³ and over
  solve time; solve-time profiles are drawn per CPU model when the runs come from several),
  ``*-families`` (the time-per-target-m³ profile of each family), ``*-history-PLANNER`` (for a
  planner with several versions: success rate and median time per target m³ by version), and
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
import json
import math
import re
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import datetime, UTC
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .aggregate import PRIMARY, RANKING_RULE, RANK_ALPHA, REASONS, SCOPES, aggregate, ci_text, latest_versions
from .provenance import build_text
from .stats import INTERVAL_NOTE, min_separating_n, separation_note
from .profiles import cost_matrix, profile

from .plotting import mpl_text, planner_colours, pyplot
from .scaling import SCALE_CAPTION, cost_growth_figure, scale_section
from .generalisation import gap_table, markdown as gap_markdown, with_sealed_draws, write as write_gaps
from .store import Store, load_runs, suite_members
from .verify import latest_spot_checks, machine_label

#: Termination reasons shown as columns of the tables (``ok`` is in the success rate).
FAILURE_COLUMNS = ("invalid", "timeout", "memory", "error", "crashed")


@dataclass
class Published:
    """What :func:`publish` wrote."""

    out: Path
    files: list[Path] = field(default_factory=list)
    removed: list[Path] = field(default_factory=list)  #: figures of an earlier board in ``figures/``, deleted
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
            suites = store.run_suites()
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


def load_runs_empty() -> pd.DataFrame:
    return pd.DataFrame(columns=["id", "suite", "suite_digest", "scenario_id", "scenario_digest", "track", "planner",
                                 "planner_version", "config_hash", "reason", "success", "solver"])


def solver_labels(runs: pd.DataFrame) -> pd.Series:
    """``planner version``, `` closed-loop`` for a closed-loop configuration (docs/DESIGN.md §6),
    plus ``[config hash]`` where one label still covers several configs."""
    closed = runs["config"].map(_closed_loop) if "config" in runs else pd.Series(False, index=runs.index)
    base = runs["planner"].astype(str) + " " + runs["planner_version"].astype(str) + closed.map({True: " closed-loop", False: ""})
    n_cfg = runs.groupby(base)["config_hash"].transform("nunique")
    return base.where(n_cfg <= 1, base + " [" + runs["config_hash"].astype(str).str[:8] + "]")


def _closed_loop(config: Any) -> bool:
    try:
        return bool(json.loads(config).get("closed_loop")) if isinstance(config, str) else False
    except (ValueError, AttributeError):
        return False


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


def slug(text: str) -> str:
    s = re.sub(r"[^A-Za-z0-9_-]+", "-", text).strip("-")[:40]
    return (s or "x") + "-" + hashlib.sha1(text.encode()).hexdigest()[:6]


def table_rows(summary: pd.DataFrame, closed: frozenset[str] = frozenset()) -> list[dict[str, Any]]:
    """Display values (text) and sort keys (numbers) of one table's rows, in rank order.

    Medians and the success rate carry their 95 % interval in brackets (none where n is too small);
    a configuration shows its label (:mod:`earthbench.labels`) and hash; one in ``closed`` (closed
    loop, docs/DESIGN.md §6) is labelled so where the label does not say it already.
    A "Prepare s" column (the longest preparation a row's runs used) appears when a row has one.
    """
    rows = []
    # the preparation's wall seconds (docs/DESIGN.md §6), in a column of their own when a row has one
    prepared = "prepare_max" in summary and bool(summary["prepare_max"].notna().any())
    for _, r in summary.iterrows():
        vr = _f(r["volume_ratio_mean"]) + ("" if pd.isna(r["volume_ratio_sd"]) else f" ± {_f(r['volume_ratio_sd'])}")
        rows.append({
            "attrs": {"planner": str(r["planner"]), "version": str(r["planner_version"])},
            "cells": [
                ("Rank", str(r["rank_label"]), r["rank"]),
                ("Planner", str(r["planner"]), None),
                ("Version", str(r["planner_version"]), None),
                ("Config", _config_cell(r, closed), None),
                ("Runs", f"{r['runs']}/{r['of']}", r["runs"]),
                ("Success", ci_text(r["success_rate"], r["success_rate_lo"], r["success_rate_hi"], ".0f", 100, "%"),
                 r["success_rate"]),
                ("Volume ratio (mean ± SD)", vr, r["volume_ratio_mean"]),
                ("Overshoot m³ (mean)", _f(r["overshoot_m3_mean"], ".2f"), r["overshoot_m3_mean"]),
                ("Time per target m³, s (median)",
                 ci_text(r["time_per_target_m3_median"], r["time_per_target_m3_lo"], r["time_per_target_m3_hi"])
                 + (f"; {r['short_of_target']} short" if r["short_of_target"] else ""), r["time_per_target_m3_median"]),
                ("× lower bound", ci_text(r["time_per_target_m3_ratio_median"], r["time_per_target_m3_ratio_lo"],
                                          r["time_per_target_m3_ratio_hi"], ".2f"), r["time_per_target_m3_ratio_median"]),
                ("Time per m³, s (median)", _f(r["time_per_m3_median"], ".1f"), r["time_per_m3_median"]),
                ("Solve CPU s (median)", ci_text(r["solve_cpu_median"], r["solve_cpu_lo"], r["solve_cpu_hi"], ".2f"),
                 r["solve_cpu_median"]),
                ("Solve wall s (median)", ci_text(r["solve_time_median"], r["solve_time_lo"], r["solve_time_hi"], ".2f"),
                 r["solve_time_median"]),
                ("Solve wall s (p90)", _f(r["solve_time_p90"], ".2f"), r["solve_time_p90"]),
                *((("Prepare s", _f(r["prepare_max"], ".0f"), r["prepare_max"]),) if prepared else ()),
                *((reason, str(r[f"n_{reason}"]), r[f"n_{reason}"]) for reason in FAILURE_COLUMNS),
            ]
        })
    return rows


def _config_cell(r: Any, closed: frozenset[str]) -> str:
    """The configuration's settings off the defaults (its label without the planner's name, which has its own column) and hash."""
    label = str(r.get("config_label") or r["planner"])
    settings = label[len(str(r["planner"])):] if label.startswith(str(r["planner"])) else label
    text = (f"{settings} " if settings and not settings.startswith("#") else "") + str(r["config_hash"])[:8]
    return text + (" closed-loop" if str(r["config_hash"]) in closed and "closed_loop" not in label else "")


#: The marker on the Rank heading of a table whose scenarios are too few for any paired test to separate two planners.
UNSEPARABLE = "‡"


def mark_unseparable(rows: list[dict[str, Any]], table: pd.DataFrame) -> list[dict[str, Any]]:
    """``Rank ‡`` on a table that has fewer scenarios than a paired test needs to reach α (every shared rank is then moot)."""
    if not len(table) or bool(table["separable"].astype(bool).all()):
        return rows
    return [{**r, "cells": [((h + " " + UNSEPARABLE) if h == "Rank" else h, text, key) for h, text, key in r["cells"]]}
            for r in rows]


def section_tables(summary: pd.DataFrame, all_versions: bool = False, closed: frozenset[str] = frozenset()) -> dict[str, Any]:
    """One suite and track's tables: the main rows, one table per family and per target (the same
    configurations), and the history (older versions) unless ``all_versions`` ranks them all."""
    shown = summary if all_versions else summary[summary["latest"].astype(bool)]
    main = shown[shown["scope"] == "suite"]
    keep = set(zip(main["planner"], main["planner_version"].astype(str), main["config_hash"]))
    def mine(df: pd.DataFrame) -> pd.DataFrame:
        mask = [k in keep for k in zip(df["planner"], df["planner_version"].astype(str), df["config_hash"])]
        return df.loc[np.array(mask, dtype=bool)]
    breakdowns = []
    for scope, word in (("family", "Family"), ("target", "Target")):
        parts = mine(shown[shown["scope"] == scope])
        if parts["group"].nunique() > 1:  # one family (or target) would repeat the suite's table
            for group, g in parts.groupby("group", sort=True):
                breakdowns.append((f"{word} {group}", mark_unseparable(table_rows(g, closed), g)))
    history = summary[(summary["scope"] == "suite") & ~summary["latest"].astype(bool)] if not all_versions else summary.iloc[:0]
    return {"rows": mark_unseparable(table_rows(main, closed), main), "breakdowns": breakdowns,
            "history": table_rows(history.sort_values(["planner", "planner_version", "config_hash"], kind="mergesort"), closed)}


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
    seeds: str = ""  #: the seeds the table covers when the board was limited to some (``--seeds``): "seed 0", "seeds 0–2"
    isolation: str = ""  #: the fences the table's runs had (docs/isolation.md), with the count of those without
    builds: list[str] = field(default_factory=list)  #: the builds of earthbench the runs came from (:func:`build_text`)
    load: str = ""  #: the machine's load around the runs' cases
    scenarios: int = 0  #: scenarios of the suite's table (for the separation note)

    @property
    def mixed(self) -> bool:
        """Whether the table's solve times were measured on more than one machine."""
        return self.n_machines > 1

    def lines(self) -> list[str]:
        commits = ", ".join(self.commits[:3]) + (f" and {len(self.commits) - 3} more" if len(self.commits) > 3 else "")
        return [
            f"suite digest: {self.suite_digest}",
            f"success threshold: volume ratio ≥ {self.threshold:g} with a valid plan",
            *([f"scenarios: {self.seeds} of the suite only (every rate and median is over those)"] if self.seeds else []),
            *([f"code: {'; '.join(self.builds)}"] if self.builds else [f"project commit: {commits or 'unknown'}"]),
            f"CPU: {'; '.join(self.cpus) or 'unknown'}" + (" (solve times mixed from several CPU models)" if self.n_models > 1 else ""),
            f"runs: {self.first or '?'} to {self.last or '?'}; generated {self.generated}",
            *([f"machine load: {self.load}"] if self.load else []),
            PROVENANCE,
            *([f"isolation: {self.isolation}"] if self.isolation else []),
            *([f"{UNSEPARABLE} {separation_note(self.scenarios, RANK_ALPHA)}"]
              if 0 < self.scenarios < min_separating_n(RANK_ALPHA) else []),
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
    values = [runs[c].tolist() if c in runs else [None] * len(runs) for c in cols.values()]
    labels: dict[tuple[Any, ...], str] = {}  # a store holds a few machines: label each once
    out = []
    for row in zip(*values):
        key = tuple(None if pd.isna(v) else v for v in row)
        if key not in labels:
            labels[key] = machine_label(dict(zip(cols, key)))
        out.append(labels[key])
    return pd.Series(out, index=runs.index, dtype=object)


def stamp(runs: pd.DataFrame, suite: str, track: str, generated: str, spot_checks: Sequence[Any] = (),
          seeds: str = "") -> Stamp:
    """The stamp of one table; ``spot_checks`` (:class:`earthbench.verify.SpotCheck`) of its planners are listed;
    ``seeds`` names the seed selection the board was limited to."""
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
    prepared = runs[runs["prepare_s"].notna()] if "prepare_s" in runs else runs.iloc[:0]
    for solver, g in prepared.groupby(prepared["solver"] if "solver" in prepared else prepared["planner"], sort=True):
        solve_machines.append(f"preparation of {solver} (once per machine, before its first case, not in its solve times): "
                              f"{g['prepare_s'].max():.0f} s wall, {g['prepare_cpu_s'].max():.0f} s CPU")
    versions = set(zip(runs["planner"], runs["planner_version"])) if len(runs) else set()
    spots = [c.line() for c in spot_checks if (c.planner, c.version) in versions]
    return Stamp(suite, track, ", ".join(digests), float(thr.iloc[0]) if len(thr) else float("nan"), uniq("project_commit"),
                 cpus, started[0] if started else "", finished[-1] if finished else "", generated,
                 max(1, len(uniq("cpu_model"))), solve_machines, spots, max(1, machine.nunique()), seeds,
                 _isolation(runs), builds_of(runs), load_text(runs), int(runs["scenario_digest"].nunique()) if len(runs) else 0)


def builds_of(runs: pd.DataFrame) -> list[str]:
    """Every build of earthbench the runs came from, with the machines that ran it: a board merged from
    two machines' stores names both builds."""
    if not len(runs) or "project_commit" not in runs:
        return []
    version = runs["earthbench_version"] if "earthbench_version" in runs else pd.Series(None, index=runs.index)
    key = pd.Series([build_text(v, c) for v, c in zip(version, runs["project_commit"])], index=runs.index)
    machine = _machine_of(runs)
    out = []
    for text, idx in key.groupby(key, sort=True).groups.items():
        hosts = sorted(set(machine.loc[idx]))
        out.append(f"{text} on {', '.join(hosts)} ({len(idx)} run{'s' if len(idx) != 1 else ''})")
    return out


def load_text(runs: pd.DataFrame) -> str:
    """The 1-minute load average around the runs' cases and the most CPU stolen, or "" when none was recorded."""
    cols = [c for c in ("load_before", "load_after") if c in runs]
    if not cols:
        return ""
    load = pd.concat([pd.to_numeric(runs[c], errors="coerce") for c in cols]).dropna()
    if not len(load):
        return "not recorded (runs stored before schema 5)"
    steal = pd.to_numeric(runs["steal_share"], errors="coerce").dropna() if "steal_share" in runs else pd.Series(dtype=float)
    n_missing = int(pd.to_numeric(runs[cols[0]], errors="coerce").isna().sum())
    text = (f"1-minute load average {load.min():.2f}–{load.max():.2f} around the cases (before and after each)"
            + (f", CPU steal up to {100 * steal.max():.1f} %" if len(steal) else ""))
    return text + (f"; {n_missing} run(s) without a record" if n_missing else "")


def _isolation(runs: pd.DataFrame) -> str:
    """The fences of a table's runs; runs without them (``none``) are counted, as they could be gamed."""
    if "isolation" not in runs or not len(runs):
        return ""
    labels = runs["isolation"].fillna("none")
    bare = int((labels == "none").sum())
    kinds = ", ".join(sorted(set(labels) - {"none"}))
    if not bare:
        return kinds
    what = "per-process fences only: a planner there could reach past its budget (docs/isolation.md)"
    return f"{kinds + '; ' if kinds else ''}none for {bare} of {len(runs)} runs ({what})"


def seed_list(seeds: Sequence[int]) -> str:
    """``0–2, 5`` for seeds 0, 1, 2, 5: runs of consecutive seeds as ranges."""
    out: list[str] = []
    for s in sorted(set(seeds)):
        if out and out[-1].rsplit("–", 1)[-1] == str(s - 1):
            out[-1] = f"{out[-1].split('–')[0]}–{s}"
        else:
            out.append(str(s))
    return ", ".join(out)


def mark_mixed_solve_columns(rows: list[dict[str, Any]], mixed: bool) -> list[dict[str, Any]]:
    """Headings of solve-time columns get a † when the table's solve times come from several machines."""
    if not mixed:
        return rows
    return [{**r, "cells": [((h + " †") if h.startswith("Solve") else h, text, key) for h, text, key in r["cells"]]} for r in rows]


# -- figures ---------------------------------------------------------------------------------------


def volume_time_figure(runs: pd.DataFrame, title: str):
    """Loaded volume against total execution time (the plan's makespan) per run and planner."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.8), constrained_layout=True)
    have = runs[runs["reason"].isin(["ok", "invalid"]) & runs["makespan_s"].notna()] if "makespan_s" in runs else runs.iloc[:0]
    colours = planner_colours(runs["solver"].unique())
    from matplotlib.lines import Line2D

    handles = []
    for solver, g in have.groupby("solver"):
        c = colours[solver]
        ok = g["reason"] == "ok"
        succ = ok & g["success"].astype(bool)
        ax.scatter(g.loc[succ, "makespan_s"], g.loc[succ, "loaded_volume"], s=18, color=c, zorder=2)
        ax.scatter(g.loc[ok & ~succ, "makespan_s"], g.loc[ok & ~succ, "loaded_volume"], s=18, facecolors="none", edgecolors=c, zorder=2)
        # invalid runs: large, drawn over every valid point so none hides under them
        ax.scatter(g.loc[~ok, "makespan_s"], g.loc[~ok, "loaded_volume"], s=70, color=c, marker="X", edgecolors="k",
                   linewidths=0.6, zorder=4)
        # the legend marker says what the planner has: a filled dot only when some run succeeded
        counts = {"success": int(succ.sum()), "below threshold": int((ok & ~succ).sum()), "invalid": int((~ok).sum())}
        kinds = [k for k, n in counts.items() if n]
        marker = {"success": dict(marker="o", color=c), "below threshold": dict(marker="o", mfc="none", mec=c, color=c),
                  "invalid": dict(marker="X", color=c, mec="k")}[kinds[0]]
        handles.append(Line2D([], [], ls="none", ms=7, **marker,
                              label=mpl_text(f"{solver} ({', '.join(f'{counts[k]} {k}' for k in kinds)})")))
    ax.set_xlabel("total time of the plan (makespan), s")
    ax.set_ylabel("loaded volume, m³")
    ax.set_title(mpl_text(title) + "\nfilled: success; hollow: valid, below threshold; ✕: invalid (drawn on top)", fontsize=9)
    ax.grid(alpha=0.3)
    if len(have):
        ax.legend(handles=handles, fontsize=7, loc="best")
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
    from matplotlib.ticker import FuncFormatter

    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))  # τ = 1, 2, 4, … rather than 2⁰, 2¹, 2²
    ax.set_xlim(1, right)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("fraction of scenarios ρ(τ)")
    ax.set_title(mpl_text(title), fontsize=9)
    ax.grid(alpha=0.3)


def profiles_figure(runs: pd.DataFrame, title: str):
    """Performance profiles over time per target m³ and over solve time (one panel per CPU model)."""
    plt = pyplot()
    colours = planner_colours(runs["solver"].unique())
    models = sorted(runs["cpu_model"].fillna("unknown CPU").unique()) if "cpu_model" in runs else ["unknown CPU"]
    fig, axes = plt.subplots(1, 1 + len(models), figsize=(5.2 * (1 + len(models)), 4.2), constrained_layout=True, squeeze=False)
    axes = axes[0]
    solvers = sorted(runs["solver"].unique())
    c = cost_matrix(runs, PRIMARY).reindex(columns=solvers, fill_value=np.inf)
    _draw_profile(axes[0], profile(c), colours, "τ (time per target m³ within τ × the best)", "time per target m³")
    cpu = runs["cpu_model"].fillna("unknown CPU") if "cpu_model" in runs else pd.Series("unknown CPU", index=runs.index)
    for ax, model in zip(axes[1:], models):
        sub = runs[cpu == model]  # only the planners that ran on this CPU model are compared here
        # the ranked solve-time figure, CPU time, where the runs have it (wall time in stores without it)
        col = "solve_cpu_s" if "solve_cpu_s" in sub and sub["solve_cpu_s"].notna().any() else "solve_time_s"
        word = "solve CPU time" if col == "solve_cpu_s" else "solve time"
        c = cost_matrix(sub, col).reindex(columns=sorted(sub["solver"].unique()), fill_value=np.inf)
        label = word + (f" — only runs on {model}" if len(models) > 1 else "")
        _draw_profile(ax, profile(c), colours, f"τ ({word} within τ × the best)", label)
    axes[0].legend(fontsize=7, loc="lower right")
    fig.suptitle(mpl_text(title) + " — failures count as never solved", fontsize=10)
    return fig


def families_figure(runs: pd.DataFrame, title: str):
    """One performance-profile panel per family over time per target m³ (families differ twofold in scale)."""
    plt = pyplot()
    colours = planner_colours(runs["solver"].unique())
    solvers = sorted(runs["solver"].unique())
    families = sorted(runs["family"].fillna("?").astype(str).unique())
    fig, axes = plt.subplots(1, len(families), figsize=(4.6 * len(families), 4.0), constrained_layout=True, squeeze=False)
    for ax, fam in zip(axes[0], families):
        sub = runs[runs["family"].fillna("?").astype(str) == fam]
        c = cost_matrix(sub, PRIMARY).reindex(columns=solvers, fill_value=np.inf)
        _draw_profile(ax, profile(c), colours, "τ (within τ × the best)", f"{fam} ({sub['scenario_digest'].nunique()} scenarios)")
    axes[0][0].legend(fontsize=7, loc="lower right")
    fig.suptitle(mpl_text(title) + " — time per target m³ by family; failures count as never solved", fontsize=10)
    return fig


def history_figure(rows: pd.DataFrame, title: str):
    """Success rate and median time per target m³ (95 % intervals) across one planner's versions."""
    from .aggregate import version_key

    plt = pyplot()
    rows = rows.assign(_k=rows["planner_version"].map(version_key)).sort_values(["_k", "config_hash"], kind="mergesort")
    labels = [f"{v}" + (f"\n[{str(h)[:8]}]" if (rows["planner_version"] == v).sum() > 1 else "")
              for v, h in zip(rows["planner_version"], rows["config_hash"])]
    x = np.arange(len(rows))
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.8), constrained_layout=True)
    for ax, (col, lo, hi, scale, ylabel) in zip(axes, (
            ("success_rate", "success_rate_lo", "success_rate_hi", 100.0, "success rate, %"),
            ("time_per_target_m3_median", "time_per_target_m3_lo", "time_per_target_m3_hi", 1.0, "time per target m³, s (median)"))):
        y = rows[col].to_numpy(dtype=float) * scale
        with np.errstate(invalid="ignore"):
            err = np.vstack([y - rows[lo].to_numpy(dtype=float) * scale, rows[hi].to_numpy(dtype=float) * scale - y])
        y = np.where(np.isfinite(y), y, np.nan)  # a median short of the target (∞) is not drawn
        err = np.where(np.isfinite(err), np.abs(err), 0.0)  # nor an interval without an end (none at small n, or ∞)
        ax.errorbar(x, y, yerr=err, fmt="o-", capsize=3)
        ax.set_xticks(x, [mpl_text(t) for t in labels], fontsize=8)
        ax.set_xlabel("version")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    fig.suptitle(mpl_text(title) + " — by version, 95 % intervals (exact for rates, order statistics for medians)", fontsize=10)
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
    for _, g in have.groupby("solver"):
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

    scenario = Scenario.from_text(scenario_json)
    plan = Plan.from_json(plan_json)
    verdict = judge(scenario, plan)
    fig = terrain_before_after(scenario, plan, verdict)
    fig.suptitle(mpl_text(title), fontsize=10)
    return fig


#: Columns the run figures read (the frame shipped to a figure worker).
FIGURE_COLUMNS = ["scenario_digest", "family", "solver", "reason", "success", "makespan_s", "loaded_volume", "time_per_m3",
                  PRIMARY, "solve_time_s", "solve_cpu_s", "cpu_model"]


def _render(job: tuple[str, str, tuple[Any, ...]]) -> bytes:
    """Draw one figure and save it as PNG and SVG; return the PNG (runs in a worker process)."""
    kind, base, args = job
    makers: dict[str, Callable[..., Any]] = {
        "volume-time": volume_time_figure, "profiles": profiles_figure, "families": families_figure,
        "history": history_figure, "terrain": terrain_figure, "cost-growth": cost_growth_figure}
    return _save(makers[kind](*args), Path(base))[2]


#: The figure kinds in the order the workers take them: the costliest first (a terrain figure holds two
#: heightmaps, a colour bar and every action of a plan), so no long job is left to run alone at the end.
_HEAVY_FIRST = {"terrain": 0, "profiles": 1, "families": 1, "volume-time": 2, "cost-growth": 3, "history": 4}


class Renderer:
    """Figure jobs drawn in parallel worker processes (fork on Linux) while the caller goes on, e.g.
    computing the tables' intervals and paired tests; in this process when there is one core.

    :meth:`add` queues a job, :meth:`start` hands the queued ones to the workers (heaviest first);
    :meth:`results` draws in this process every job no worker has taken yet, so the caller's core
    is not idle while the workers finish."""

    def __init__(self, workers: int | None = None):
        import multiprocessing as mp
        import os

        n = workers if workers else len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1
        self._jobs: list[tuple[str, str, tuple[Any, ...]]] = []
        self._futures: dict[int, Any] = {}
        self._pool = None
        if n > 1 and "fork" in mp.get_all_start_methods():
            from concurrent.futures import ProcessPoolExecutor

            plt = pyplot()  # load fonts and the mathtext parser once, before the workers fork
            warm = plt.figure()
            warm.text(0.5, 0.5, "m³ τ ρ")
            warm.canvas.draw()
            plt.close(warm)
            self._pool = ProcessPoolExecutor(max_workers=n, mp_context=mp.get_context("fork"))

    def add(self, job: tuple[str, str, tuple[Any, ...]]) -> None:
        self._jobs.append(job)

    def start(self) -> None:
        """Give the workers every job queued since the last call, the costliest kinds first."""
        if self._pool is None:
            return
        waiting = [i for i in range(len(self._jobs)) if i not in self._futures]
        for i in sorted(waiting, key=lambda i: _HEAVY_FIRST.get(self._jobs[i][0], 9)):
            self._futures[i] = self._pool.submit(_render, self._jobs[i])

    def results(self) -> list[bytes]:
        """The PNG of every job, in the order added (waits for the workers, then shuts them down)."""
        if self._pool is None:
            return [_render(j) for j in self._jobs]
        self.start()
        try:
            done: dict[int, bytes] = {}
            # one at a time, the last job handed out that no worker has taken yet is drawn here
            while (i := next((i for i, f in reversed(self._futures.items()) if i not in done and f.cancel()), None)) is not None:
                done[i] = _render(self._jobs[i])
            return [done[i] if i in done else self._futures[i].result() for i in range(len(self._jobs))]
        finally:
            self._pool.shutdown()


def _save(fig, base: Path) -> tuple[Path, Path, bytes]:
    """Write ``base.png`` and ``base.svg``; return the paths and the PNG bytes."""
    plt = pyplot()
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
        attrs = "".join(f' data-{k}="{e(v)}"' for k, v in r.get("attrs", {}).items())
        body.append(f"<tr{attrs}>" + "".join(tds) + "</tr>")
    cap = f"<caption>{e(caption)}</caption>" if caption else ""
    return (f'<div class="wrap"><table class="{cls}">{cap}<thead><tr>{head}</tr></thead><tbody>\n' + "\n".join(body)
            + "\n</tbody></table></div>")


#: Row attributes the page's filters match (``data-KEY`` on each row) → the runs column they come from.
FILTERS = {"family": "family", "planner": "planner", "version": "planner_version"}

RUN_COLUMNS = [("id", "Run"), ("scenario_id", "Scenario"), ("solver", "Planner"), ("reason", "Reason"),
               ("success", "Success"), ("volume_ratio", "Volume ratio"),
               ("time_per_target_m3", "Time per target m³, s"), ("time_per_m3", "Time per m³, s"),
               ("time_per_target_m3_ratio", "× bound"), ("solve_cpu_s", "Solve CPU s"), ("solve_time_s", "Solve wall s"),
               ("load_before", "Load before"), ("violation_rules", "Violations"), ("cpu_model", "CPU"), ("hostname", "Host"),
               ("isolation", "Isolation")]
_NUMERIC_RUN = {"id", "volume_ratio", "time_per_target_m3", "time_per_m3", "time_per_target_m3_ratio", "solve_cpu_s", "solve_time_s",
                "load_before"}


def run_rows(runs: pd.DataFrame) -> list[dict[str, Any]]:
    cols = [(c, h) for c, h in RUN_COLUMNS if c in runs]
    out = []
    data = {c: runs[c].tolist() for c, _ in cols}
    filters = {k: runs[c].astype(str).tolist() for k, c in FILTERS.items() if c in runs}
    for i in range(len(runs)):
        cells: list[tuple[str, str, float | None]] = []
        for c, h in cols:
            v = data[c][i]
            if c in _NUMERIC_RUN:
                x = None if v is None or (isinstance(v, float) and math.isnan(v)) else float(v)
                cells.append((h, _f(x, ".0f" if c == "id" else ".3g"), x if x is not None else float("nan")))
            elif c == "success":
                cells.append((h, "yes" if bool(v) else "no", 1.0 if bool(v) else 0.0))
            else:
                cells.append((h, "" if v is None or (isinstance(v, float) and math.isnan(v)) else str(v), None))
        out.append({"cells": cells, "attrs": {k: v[i] for k, v in filters.items()}})
    return out


_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:1.5rem auto;max-width:1800px;padding:0 1rem;color:#222}
h1{font-size:1.6rem}h2{font-size:1.25rem;margin-top:2.5rem;border-bottom:1px solid #ccc}
table{border-collapse:collapse;margin:1rem 0;font-size:.8rem}
th,td{border:1px solid #ddd;padding:.2rem .35rem;text-align:right}
th{white-space:normal;vertical-align:bottom;min-width:3.2em}td{white-space:normal}
td:nth-child(2),td:nth-child(3){white-space:normal;overflow-wrap:anywhere;min-width:6em}
.filters{display:flex;flex-wrap:wrap;gap:.3rem 1rem;font-size:.85rem;margin:.6rem 0}
tr.hidden{display:none}
@media (max-width:900px){body{margin:.5rem;padding:0 .25rem}table{font-size:.72rem}th,td{padding:.15rem .2rem}}
td:nth-child(2),td:nth-child(3),th:nth-child(2),th:nth-child(3){text-align:left}
th{background:#f3f3f3;cursor:pointer;user-select:none}
th[aria-sort=ascending]::after{content:" ▲"}th[aria-sort=descending]::after{content:" ▼"}
tbody tr:nth-child(even){background:#fafafa}
.stamp{font-family:ui-monospace,monospace;font-size:.8rem;background:#f7f7f7;padding:.5rem;white-space:pre-wrap}
.rule{font-style:italic}
nav.contents{font-size:.9rem;margin:.4rem 0 1rem}.replays{font-size:.85rem}
details.stamp-box summary{font-size:.85rem;color:#555;cursor:pointer}
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
  // filters: a row shows when every chosen value matches its data-KEY attribute
  document.querySelectorAll('.filters').forEach(function (bar) {
    var section = bar.closest('section');
    function apply() {
      var want = {};
      bar.querySelectorAll('select').forEach(function (s) { if (s.value) want[s.getAttribute('data-key')] = s.value; });
      section.querySelectorAll('table.sortable tbody tr').forEach(function (tr) {
        var show = Object.keys(want).every(function (k) {
          return !tr.hasAttribute('data-' + k) || tr.getAttribute('data-' + k) === want[k];
        });
        tr.classList.toggle('hidden', !show);
      });
    }
    bar.querySelectorAll('select').forEach(function (s) { s.addEventListener('change', apply); });
  });
})();
"""


_BREAKDOWN_NOTE = ("the same configurations on one family or one target of the suite, ranked by the same rule "
                   "within it (the success rate is over that part's scenarios)")
_HISTORY_NOTE = "older versions of the ranked planners, not ranked (`--all-versions` ranks every version)"


def markdown_more_tables(sec: dict[str, Any]) -> list[str]:
    """The breakdowns (one table per family and per target) and the history table under a suite's table."""
    lines: list[str] = []
    if sec.get("breakdowns"):
        lines += [f"### Breakdowns: {_BREAKDOWN_NOTE}", ""]
        for heading, rows in sec["breakdowns"]:
            lines += [f"#### {md_escape(heading)}", "", markdown_table(rows)]
    if sec.get("history"):
        lines += [f"### History: {_HISTORY_NOTE}", "", markdown_table(sec["history"])]
    return lines


def html_more_tables(sec: dict[str, Any]) -> str:
    """:func:`markdown_more_tables` for the page."""
    e = html.escape
    parts = []
    if sec.get("breakdowns"):
        parts.append(f"<h3>Breakdowns</h3><p class=\"rule\">{e(_BREAKDOWN_NOTE)}.</p>")
        for heading, rows in sec["breakdowns"]:
            parts.append(f"<h4>{e(heading)}</h4>" + html_table(fold_zero_failures(rows)))
    if sec.get("history"):
        parts.append(f"<h3>History</h3><p class=\"rule\">{e(_HISTORY_NOTE.replace('`', ''))}.</p>"
                     + html_table(fold_zero_failures(sec["history"])))
    return "\n".join(parts)


def filter_bar(sec: dict[str, Any]) -> str:
    """Selects for the values of each filter key seen in a section's rows."""
    e = html.escape
    values: dict[str, set[str]] = {k: set() for k in FILTERS}
    for r in sec["rows"] + sec["run_rows"]:
        for k, v in r.get("attrs", {}).items():
            values.setdefault(k, set()).add(v)
    parts = []
    for k, vs in values.items():
        if len(vs) > 1:
            opts = "".join(f'<option value="{e(v)}">{e(v)}</option>' for v in sorted(vs))
            parts.append(f'<label>{e(k.capitalize())} <select data-key="{e(k)}"><option value="">all</option>{opts}</select></label>')
    return f'<div class="filters">Filter: {"".join(parts)}</div>' if parts else ""


def fold_zero_failures(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The failure-count columns that are 0 in every row, folded into one column (the page's tables stay narrow)."""
    if not rows:
        return rows
    names = [c[0] for c in rows[0]["cells"]]
    zero = [n for n in FAILURE_COLUMNS if n in names and all(str(dict((c[0], c[1]) for c in r["cells"])[n]) == "0" for r in rows)]
    if len(zero) < 2:
        return rows
    head = " · ".join(zero)
    out = []
    for r in rows:
        cells = [c for c in r["cells"] if c[0] not in zero]
        out.append({**r, "cells": [*cells, (head, "0", 0)]})
    return out


def _anchor(sec: dict[str, Any]) -> str:
    return "s-" + slug(f"{sec['suite']}-{sec['track']}")


def replay_links(runs: list[dict[str, Any]]) -> str:
    """Links from a table to the replays of its runs that the page embeds (the viewer is at the page's end)."""
    if not runs:
        return ""
    e = html.escape
    by_solver: dict[str, list[str]] = {}
    for r in runs:
        by_solver.setdefault(str(r["solver"]), []).append(
            f'<a href="#replay" class="rp-link" data-run="{int(r["id"])}">run {int(r["id"])}</a> ({e(str(r["what"]))})')
    return ('<p class="replays">Replay a run: '
            + "; ".join(f"{e(solver)}: {', '.join(links)}" for solver, links in by_solver.items()) + "</p>")


def html_page(sections: list[dict[str, Any]], generated: str, viewer: str = "") -> str:
    """The self-contained page; ``viewer`` is the replay section (:func:`earthbench.replay.viewer_section`)."""
    from .replay import CSS as REPLAY_CSS, SCRIPT as REPLAY_SCRIPT

    e = html.escape
    script = _JS + REPLAY_SCRIPT
    script_hash = base64.b64encode(hashlib.sha256(script.encode()).digest()).decode()
    csp = (f"default-src 'none'; img-src data:; style-src 'unsafe-inline'; script-src 'sha256-{script_hash}'; "
           "base-uri 'none'; form-action 'none'")
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f'<meta http-equiv="Content-Security-Policy" content="{e(csp)}">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        "<title>earthbench leaderboard</title>",
        f"<style>{_CSS}{REPLAY_CSS}</style></head><body>",
        "<h1>earthbench leaderboard</h1>",
        f'<p class="intro">Generated {e(generated)} by <code>earthbench leaderboard</code>. Click a column heading to sort. '
        f"{e(INTERVAL_NOTE)}. {UNSEPARABLE} on a Rank heading: too few scenarios for any paired test to separate two planners. "
        "Invalid plans are counted, never ranked. "
        'Tables: <a href="summary.csv">summary.csv</a>; every run: <a href="runs.csv">runs.csv</a>.</p>',
    ]
    if len(sections) > 1 or (sections and viewer):
        links = [f'<a href="#{e(_anchor(s))}">{e(s["suite"])} ({e(s["track"])})</a>' for s in sections]
        parts.append('<nav class="contents">' + " · ".join(links + (['<a href="#replay">replays</a>'] if viewer else [])) + "</nav>")
    if not sections:
        parts.append("<p>No runs in the store.</p>")
    for s in sections:
        # the ranking first; what it rests on (stamp, rule's fine print) folded under it
        parts.append(f'<section id="{e(_anchor(s))}"><h2>Suite {e(s["suite"])} — track {e(s["track"])}</h2>')
        parts.append(filter_bar(s))
        parts.append(html_table(fold_zero_failures(s["rows"])))
        parts.append(replay_links(s.get("replay_runs", [])))
        parts.append(f'<details class="stamp-box"><summary>How this table is ranked, and what it rests on: suite digest, '
                     f'machines, spot checks</summary><p class="rule">Ranking: {e(RANKING_RULE)}.</p>'
                     f'<div class="stamp">{e(chr(10).join(s["stamp"].lines() + s["stamp"].planner_lines()))}</div></details>')
        parts.append(html_more_tables(s))
        if s.get("scale_rows"):
            parts.append(html_table(s["scale_rows"], caption="scale: cost against target volume (median [IQR] over seeds)"))
        for cap, png in s["figures"]:
            data = base64.b64encode(png).decode()
            parts.append(f'<figure><img alt="{e(cap)}" src="data:image/png;base64,{data}"><figcaption>{e(cap)}</figcaption></figure>')
        parts.append(f"<details><summary>All {len(s['run_rows'])} runs of this table</summary>")
        parts.append(html_table(s["run_rows"], cls="sortable runs"))
        parts.append("</details></section>")
    parts.append(viewer)
    parts.append(f"<script>{script}</script></body></html>")
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
            workers: int | None = None, replays: int = 20, all_versions: bool = False,
            seeds: Sequence[int] | None = None) -> Published:
    """Write the leaderboard of ``db`` (the suites in ``suites``, default all) into ``out``.

    ``seeds``: limit the board to the suite's scenarios of these seeds (runs and denominators
    alike, so a planner run on those seeds only is not charged failures for the others);
    every table's stamp says so.

    ``workers``: processes drawing the figures (default: one per core this process may use);
    ``replays``: how many runs the page's replay viewer embeds (0: none);
    ``all_versions``: rank every stored version, not only each planner's latest.
    """
    from .replay import pick_runs, viewer_section

    out = Path(out)
    fig_dir = out / "figures"
    generated = generated or datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    result = Published(out)
    captions: list[tuple[dict[str, Any], str, Path]] = []
    with Store(db, create=False) as store:
        suites = with_sealed_draws(store, suites)  # a suite's sealed draws are published beside it
        runs = published_runs(store, suites)
        members = suite_members(store, runs["suite"].unique())
        seed_note = ""
        if seeds is not None:
            runs = runs[runs["seed"].isin(seeds)].reset_index(drop=True)
            members = members[members["seed"].isin(seeds)].reset_index(drop=True)
            seed_note = f"{'seed' if len(set(seeds)) == 1 else 'seeds'} {seed_list(seeds)}"
        fig_dir.mkdir(parents=True, exist_ok=True)  # only now: a refused leaderboard writes nothing
        latest = latest_versions(runs)
        groups = list(runs.groupby(["suite", "track"], sort=True))
        sections: list[dict[str, Any]] = [{"suite": suite, "track": track, "figures": [], "md_figures": []}
                                          for (suite, track), _ in groups]
        renderer = Renderer(workers) if figures else None
        scenarios: dict[str, str] = {}
        # the figures first, so the workers draw while this process makes the tables
        for sec, ((suite, track), srun) in zip(sections, groups):
            base = slug(f"{suite}-{track}")
            title = f"suite {suite}, {track}"
            sec["scale_rows"], job = scale_section(srun, str(fig_dir / f"{base}-cost-growth"), title)
            if renderer is None:
                continue
            if job is not None:
                renderer.add(job)
                captions.append((sec, SCALE_CAPTION, Path(job[1])))
            keep = [(suite, track, p, str(v)) in latest for p, v in zip(srun["planner"], srun["planner_version"])]
            shown = srun if all_versions else srun[keep]
            cols = shown[[c for c in FIGURE_COLUMNS if c in shown]]
            kinds = [("volume-time", "Loaded volume against total time per run (as in the STL-TAMP paper, Fig. 7a)"),
                     ("profiles", "Performance profiles: time per target m³ and solve time (failures never solved)")]
            if shown["family"].nunique() > 1:
                kinds.append(("families", "Performance profiles of time per target m³, one panel per family"))
            for kind, cap in kinds:
                path = fig_dir / f"{base}-{kind}"
                renderer.add((kind, str(path), (cols, title)))
                captions.append((sec, cap, path))
            if terrain:
                for _, run in sample_runs(shown).iterrows():
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
                    renderer.add(("terrain", str(path), (scenarios[digest], plan, f"{run['solver']} on {run['scenario_id']}")))
                    captions.append((sec, f"Terrain before and after: {run['solver']} on {run['scenario_id']} (run {run['id']})", path))
        if renderer is not None:
            renderer.start()
        spot_checks = latest_spot_checks(store)
        for sec, ((suite, track), srun) in zip(sections, groups):
            st = sec["stamp"] = stamp(srun, suite, track, generated, spot_checks, seed_note)
            sec["run_rows"] = run_rows(srun.sort_values("id"))
            if sec["scale_rows"]:
                sec["scale_rows"] = mark_mixed_solve_columns(sec["scale_rows"], st.mixed)
        viewer = viewer_section(store, runs, replays)
        picked = set(pick_runs(runs, replays)["id"].astype(int)) if viewer else set()
        for sec in sections:
            mine = runs[(runs["suite"] == sec["suite"]) & (runs["track"] == sec["track"]) & runs["id"].astype(int).isin(picked)]
            sec["replay_runs"] = [{"id": int(r["id"]), "solver": r["solver"],
                                   "what": "success" if bool(r["success"]) else ("valid" if r["reason"] == "ok" else str(r["reason"]))}
                                  for _, r in mine.sort_values(["solver", "id"]).iterrows()]
        # the tables (intervals, paired tests) while the workers draw
        summary = aggregate(runs, members=members, scopes=SCOPES,
                            all_versions=all_versions)
        result.runs, result.summary = runs, summary
        gaps = gap_table(runs, members)  # sealed draws against the public suite (earthbench.generalisation)
        closed = (
            frozenset(runs.loc[runs["config"].map(_closed_loop).astype(bool), "config_hash"].astype(str))
            if "config" in runs
            else frozenset()
        )
        for sec in sections:
            ssum = summary[(summary["suite"] == sec["suite"]) & (summary["track"] == sec["track"])]
            tables = section_tables(ssum, all_versions, closed)
            mixed = sec["stamp"].mixed
            sec.update(rows=mark_mixed_solve_columns(tables["rows"], mixed),
                       breakdowns=[(h, mark_mixed_solve_columns(r, mixed)) for h, r in tables["breakdowns"]],
                       history=mark_mixed_solve_columns(tables["history"], mixed))
            if renderer is None:
                continue
            base = slug(f"{sec['suite']}-{sec['track']}")
            for planner, hist in _histories(ssum):
                path = fig_dir / f"{base}-history-{slug(planner)}"
                renderer.add(("history", str(path), (hist, f"{planner} on suite {sec['suite']}")))
                captions.append((sec, f"History of {planner}: success rate and median time per target m³ by version", path))
    for sec, cap, path in captions:
        png_path, svg_path = path.parent / (path.name + ".png"), path.parent / (path.name + ".svg")
        result.files += [png_path, svg_path]
        sec["md_figures"].append((cap, png_path.relative_to(out), svg_path.relative_to(out)))
    # every text but the page (which embeds the PNGs) while the workers finish
    runs_csv = spreadsheet_safe(runs.drop(columns=[c for c in ("packages",) if c in runs])).to_csv(index=False)
    summary_csv = spreadsheet_safe(summary).to_csv(index=False)
    readme = markdown_page(sections, generated) + gap_markdown(gaps)
    for (sec, cap, _), png in zip(captions, renderer.results() if renderer else []):
        sec["figures"].append((cap, png))
    _write_csv(out / "runs.csv", runs_csv)
    _write_csv(out / "summary.csv", summary_csv)
    (out / "README.md").write_text(readme)
    result.files += write_gaps(gaps, out)
    (out / "index.html").write_text(html_page(sections, generated, viewer))
    result.files += [out / "README.md", out / "runs.csv", out / "summary.csv", out / "index.html"]
    written = {f.resolve() for f in result.files}
    for old in fig_dir.glob("*"):  # figures of an earlier board (another suite, planner or version) would mislead
        if old.suffix in (".png", ".svg") and old.is_file() and old.resolve() not in written:
            old.unlink()
            result.removed.append(old)
    return result


def _write_csv(path: Path, text: str) -> None:
    """Write what ``DataFrame.to_csv()`` returned as ``to_csv(path)`` would have written it."""
    with open(path, "w", encoding="utf-8", newline="") as f:
        f.write(text)


def _histories(summary: pd.DataFrame) -> list[tuple[str, pd.DataFrame]]:
    """(planner, its suite-scope rows) for every planner of a table with more than one version."""
    rows = summary[summary["scope"] == "suite"]
    return [(str(p), g) for p, g in rows.groupby("planner", sort=True) if g["planner_version"].nunique() > 1]


def markdown_page(sections: list[dict[str, Any]], generated: str) -> str:
    lines = [
        "# earthbench leaderboard",
        "",
        f"Generated {generated} by `earthbench leaderboard`. Invalid plans are counted, never ranked; "
        f"`–` means no value (no valid run). {INTERVAL_NOTE}. {UNSEPARABLE} on a Rank heading: too few scenarios for "
        "any paired test to separate two planners. Columns: runs "
        "stored / scenarios in the suite; success rate over the suite's scenarios (a scenario without a run is a "
        "failure); volume ratio and overshoot beyond the target over valid runs; time per target m³ (the end of "
        "the dump that reached the target, divided by the target; ∞ for a run short of it, and \"N short\" counts "
        "those) over valid runs, with its ratio to the scenario's lower bound; time per m³ (makespan / loaded volume); "
        "solve CPU time (ranked) and wall time over all runs; counts of each failure. Every run: [runs.csv](runs.csv); "
        "these tables: [summary.csv](summary.csv); sortable page: [index.html](index.html).",
        "",
    ]
    if not sections:
        lines.append("No runs in the store.")
    for s in sections:
        lines += [f"## Suite {md_escape(s['suite'])} — track {md_escape(s['track'])}", "",
                  f"Ranking: {RANKING_RULE}.", "", "```", *(line.replace("`", "'") for line in s["stamp"].lines()), "```", "",
                  *(f"- {md_escape(line)}" for line in s["stamp"].planner_lines()), "", markdown_table(s["rows"]),
                  *markdown_more_tables(s)]
        if s.get("scale_rows"):
            lines += ["", "scale: cost against target volume, median [interquartile range] over seeds of the valid runs "
                      "(growth: solve s/m³ over the smallest target's).", "", markdown_table(s["scale_rows"])]
        for cap, png, svg in s["md_figures"]:
            lines += [f"![{md_escape(cap)}]({png.as_posix()})", "", f"*{md_escape(cap)}* ([SVG]({svg.as_posix()}))", ""]
    return "\n".join(lines) + "\n"


__all__ = ["FAILURE_COLUMNS", "REASONS", "Published", "publish", "published_runs", "solver_labels"]
