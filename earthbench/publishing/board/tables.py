"""The board's tables as text (docs/DESIGN.md §9): each table's rows (display text and sort keys), its
breakdowns and history, the reproducibility stamp, Markdown (``README.md``) and spreadsheet-safe CSV."""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ...results.aggregate import RANKING_RULE, RANK_ALPHA, ci_text
from ...classes import machine_classes
from ...results.provenance import build_text
from ...stats import INTERVAL_NOTE, min_separating_n, separation_note
from ...results.store import rules_versions
from ...results.labels import machine_label


#: Termination reasons shown as columns of the tables (``ok`` is in the success rate).
FAILURE_COLUMNS = ("invalid", "timeout", "memory", "error", "crashed")


def number_text(v: Any, spec: str = ".2f") -> str:
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
    a configuration shows its label (:mod:`earthbench.results.labels`) and hash; one in ``closed`` (closed
    loop, docs/DESIGN.md §6) is labelled so where the label does not say it already.
    A "Prepare s" column (the longest preparation a row's runs used) appears when a row has one.
    """
    rows = []
    # the preparation's wall seconds (docs/DESIGN.md §6), in a column of their own when a row has one
    prepared = "prepare_max" in summary and bool(summary["prepare_max"].notna().any())
    # the ratio to each scenario's best known plan (earthbench.publishing.best), in a column when some scenario has one
    best = "time_per_target_m3_best_ratio_median" in summary and bool(summary["time_per_target_m3_best_ratio_median"].notna().any())
    for _, r in summary.iterrows():
        vr = number_text(r["volume_ratio_mean"]) + ("" if pd.isna(r["volume_ratio_sd"]) else f" ± {number_text(r['volume_ratio_sd'])}")
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
                ("Overshoot m³ (mean)", number_text(r["overshoot_m3_mean"], ".2f"), r["overshoot_m3_mean"]),
                ("Time per target m³, s (median)",
                 ci_text(r["time_per_target_m3_median"], r["time_per_target_m3_lo"], r["time_per_target_m3_hi"])
                 + (f"; {r['short_of_target']} short" if r["short_of_target"] else ""), r["time_per_target_m3_median"]),
                ("Production, bank m³/h (median)", ci_text(r["production_m3h_median"], r["production_m3h_lo"],
                                                           r["production_m3h_hi"], ".0f"), r["production_m3h_median"]),
                ("× lower bound", ci_text(r["time_per_target_m3_ratio_median"], r["time_per_target_m3_ratio_lo"],
                                          r["time_per_target_m3_ratio_hi"], ".2f"), r["time_per_target_m3_ratio_median"]),
                ("× target bound", ci_text(r["time_per_target_m3_bound_ratio_median"], r["time_per_target_m3_bound_ratio_lo"],
                                           r["time_per_target_m3_bound_ratio_hi"], ".2f"), r["time_per_target_m3_bound_ratio_median"]),
                *((("× best known", ci_text(r["time_per_target_m3_best_ratio_median"], r["time_per_target_m3_best_ratio_lo"],
                                            r["time_per_target_m3_best_ratio_hi"], ".2f"), r["time_per_target_m3_best_ratio_median"]),)
                  if best else ()),
                ("Time per m³, s (median)", number_text(r["time_per_m3_median"], ".1f"), r["time_per_m3_median"]),
                ("Solve CPU s (median)", ci_text(r["solve_cpu_median"], r["solve_cpu_lo"], r["solve_cpu_hi"], ".2f"),
                 r["solve_cpu_median"]),
                ("Solve wall s (median)", ci_text(r["solve_time_median"], r["solve_time_lo"], r["solve_time_hi"], ".2f"),
                 r["solve_time_median"]),
                ("Solve wall s (p90)", number_text(r["solve_time_p90"], ".2f"), r["solve_time_p90"]),
                *((("Prepare s", number_text(r["prepare_max"], ".0f"), r["prepare_max"]),) if prepared else ()),
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
            "history": table_rows(history.sort_values(["planner", "planner_version", "config_hash"], kind="mergesort"), closed),
            "partial": partial_note(main)}


def partial_note(table: pd.DataFrame) -> str:
    """What a table ranks on partial data says so: the rows with fewer runs than the suite has scenarios
    (an interrupted run, a planner added late), each such scenario counted as a failure. Empty when complete."""
    short = table[table["runs"] < table["of"]]
    if not len(short):
        return ""
    who = "; ".join(f"{r.get('config_label') or r['planner']} {r['planner_version']}: {r['runs']} of {r['of']}"
                    for _, r in short.iterrows())
    return (f"partial: not every scenario has a run ({who}); a scenario without a run counts as failed, so this "
            "ranking is on partial data until those runs are stored (the same earthbench run command resumes where it stopped)")


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
    rules: str = ""  #: the version of the referee's rules that judged the runs (docs/referee.md "Rules versions")
    production: str = ""  #: what the production column counts, and the handbook's band of a calibrated class
    classes: str = ""  #: the machine classes of the table's scenarios (docs/machine-classes.md)

    @property
    def mixed(self) -> bool:
        """Whether the table's solve times were measured on more than one machine."""
        return self.n_machines > 1

    def lines(self) -> list[str]:
        commits = ", ".join(self.commits[:3]) + (f" and {len(self.commits) - 3} more" if len(self.commits) > 3 else "")
        return [
            f"suite digest: {self.suite_digest}",
            f"success threshold: volume ratio ≥ {self.threshold:g} with a valid plan",
            *([f"referee rules: {self.rules}"] if self.rules else []),
            *([f"machine class: {self.classes}"] if self.classes else []),
            *([f"production: {self.production}"] if self.production else []),
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
    """Each run's machine, labelled as :func:`earthbench.results.labels.machine_label` does."""
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
    """The stamp of one table; ``spot_checks`` (:class:`earthbench.publishing.verify.SpotCheck`) of its planners are listed;
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
                 _isolation(runs), builds_of(runs), load_text(runs), int(runs["scenario_digest"].nunique()) if len(runs) else 0,
                 rules_text(runs))


def rules_text(runs: pd.DataFrame) -> str:
    """The version of the referee's rules a table's runs were judged under, and whether it is this earthbench's."""
    from ...referee import RULES_VERSION

    versions = rules_versions(runs)
    if not versions:
        return ""
    text = "version " + ", ".join(map(str, versions))
    return text if versions == [RULES_VERSION] else text + f" (this earthbench judges under {RULES_VERSION}: `earthbench rescore`)"


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


def mark_mixed_solve_columns(rows: list[dict[str, Any]], mixed: bool) -> list[dict[str, Any]]:
    """Headings of solve-time columns get a † when the table's solve times come from several machines."""
    if not mixed:
        return rows
    return [{**r, "cells": [((h + " †") if h.startswith("Solve") else h, text, key) for h, text, key in r["cells"]]} for r in rows]


def table_sections(summary: pd.DataFrame, all_versions: bool, closed: frozenset[str], mixed: bool) -> dict[str, Any]:
    """:func:`section_tables` with † on the solve-time headings of a table whose runs come from several machines."""
    tables = section_tables(summary, all_versions, closed)
    return {"rows": mark_mixed_solve_columns(tables["rows"], mixed), "partial": tables["partial"],
            "breakdowns": [(h, mark_mixed_solve_columns(r, mixed)) for h, r in tables["breakdowns"]],
            "history": mark_mixed_solve_columns(tables["history"], mixed)}


def markdown_table(rows: list[dict[str, Any]]) -> str:
    if not rows:
        return "(no runs)\n"
    head = [c[0] for c in rows[0]["cells"]]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---:" if i not in (1, 2, 3) else "---" for i in range(len(head))) + "|"]
    for r in rows:
        lines.append("| " + " | ".join(md_escape(c[1]) for c in r["cells"]) + " |")
    return "\n".join(lines) + "\n"


BREAKDOWN_NOTE = ("the same configurations on one family or one target of the suite, ranked by the same rule "
                   "within it (the success rate is over that part's scenarios)")
HISTORY_NOTE = "older versions of the ranked planners, not ranked (`--all-versions` ranks every version)"


def markdown_more_tables(sec: dict[str, Any]) -> list[str]:
    """The breakdowns (one table per family and per target) and the history table under a suite's table."""
    lines: list[str] = []
    if sec.get("breakdowns"):
        lines += [f"### Breakdowns: {BREAKDOWN_NOTE}", ""]
        for heading, rows in sec["breakdowns"]:
            lines += [f"#### {md_escape(heading)}", "", markdown_table(rows)]
    if sec.get("history"):
        lines += [f"### History: {HISTORY_NOTE}", "", markdown_table(sec["history"])]
    return lines


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
        "those) over valid runs, with its ratio to the scenario's lower bound per m³ (× lower bound) "
        "and to its lower bound per target m³ (× target bound: whole buckets and the travel before the first dump "
        "counted); time per m³ (makespan / loaded volume); "
        "solve CPU time (ranked) and wall time over all runs; counts of each failure. Every run: [runs.csv](runs.csv); "
        "these tables: [summary.csv](summary.csv); sortable page: [index.html](index.html).",
        "",
    ]
    if not sections:
        lines.append("No runs in the store.")
    for s in sections:
        lines += [f"## Suite {md_escape(s['suite'])} — track {md_escape(s['track'])}", "",
                  *([f"**{md_escape(s['partial'])}**", ""] if s.get("partial") else []),
                  f"Ranking: {RANKING_RULE}.", "", "```", *(line.replace("`", "'") for line in s["stamp"].lines()), "```", "",
                  *(f"- {md_escape(line)}" for line in s["stamp"].planner_lines()), "", markdown_table(s["rows"]),
                  *markdown_more_tables(s)]
        if s.get("scale_rows"):
            lines += ["", "scale: cost against target volume, median [interquartile range] over seeds of the valid runs "
                      "(growth: solve s/m³ over the smallest target's).", "", markdown_table(s["scale_rows"])]
        for cap, png, svg in s["md_figures"]:
            lines += [f"![{md_escape(cap)}]({png.as_posix()})", "", f"*{md_escape(cap)}* ([SVG]({svg.as_posix()}))", ""]
    return "\n".join(lines) + "\n"


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


def write_csv(path: Path, text: str) -> None:
    """Write what ``DataFrame.to_csv()`` returned as ``to_csv(path)`` would have written it."""
    with open(path, "w", encoding="utf-8", newline="") as f:
        f.write(text)


__all__ = ["BREAKDOWN_NOTE", "FAILURE_COLUMNS", "FORMULA_STARTS", "HISTORY_NOTE", "PROVENANCE", "UNSEPARABLE", "Stamp",
           "builds_of", "load_text", "mark_mixed_solve_columns", "mark_unseparable", "markdown_more_tables", "markdown_page",
           "markdown_table", "md_escape", "number_text", "partial_note", "rules_text", "section_tables", "slug", "spreadsheet_safe",
           "stamp", "table_rows", "table_sections", "write_csv"]


def production_note(classes: set[str], track: str, best: float | None = None) -> str:
    """The stamp's production line: bank m³ an hour from the time per target m³, and for each
    calibrated machine class of the table the handbook's production band of its digging machine
    (docs/machine-classes.md), with where the table's best median production (``best``) lies
    against it: a board says by how much it is outside a site's figures, not only that it is."""
    note = "bank m³ an hour = 3600 ÷ the median time per target m³ (the target is bank m³; the referee applies no job efficiency)"
    machine = "excavator" if track == "backhoe" else "loader"
    for name in sorted(classes):
        mc = machine_classes().get(name)
        band = None if mc is None or not mc.calibrated else mc.production_band(machine)
        if mc is not None and band is not None:
            src = next(b.source for b in mc.bands if b.what == "production" and b.machine == machine)
            note += (f"; the {name} class's {machine}: handbook {band[0]:g}–{band[1]:g} m³/h across materials and conditions "
                     f"({src}), which includes a job efficiency of about 0.6–0.8")
            if best is not None and best > 0 and math.isfinite(best):
                where = (f"{best / band[1]:.1f} × the band's top" if best > band[1] else
                         f"{band[0] / best:.1f} × below its bottom" if best < band[0] else "inside it")
                note += (f"; the best median here, {best:.0f} m³/h, lies {where} (why: docs/machine-classes.md, "
                         "\"Against the handbook\")")
        elif mc is not None and mc.calibrated:
            note += f"; the {name} class's {machine}: no handbook production band"
        else:
            note += f"; the {name} class is uncalibrated: no handbook band"
    return note
