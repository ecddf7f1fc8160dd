"""The board's page, ``index.html`` (docs/DESIGN.md §9): one self-contained file with its CSS and a small
script (allowed by a content-security-policy hash), sortable and filterable tables, the figures as
``data:`` URIs and the replay viewer; every string from the store escaped."""

from __future__ import annotations

import base64
import hashlib
import html
import math
from typing import Any

import pandas as pd

from ... import assets
from ...results.aggregate import RANKING_RULE
from ...stats import INTERVAL_NOTE
from .tables import BREAKDOWN_NOTE, FAILURE_COLUMNS, HISTORY_NOTE, UNSEPARABLE, number_text, slug


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
               ("time_per_target_m3_ratio", "× lower bound"), ("time_per_target_m3_bound_ratio", "× target bound"),
               ("time_per_target_m3_best_ratio", "× best known"),
               ("solve_cpu_s", "Solve CPU s"), ("solve_time_s", "Solve wall s"),
               ("load_before", "Load before"), ("violation_rules", "Violations"), ("cpu_model", "CPU"), ("hostname", "Host"),
               ("isolation", "Isolation")]
_NUMERIC_RUN = {"id", "volume_ratio", "time_per_target_m3", "time_per_m3", "time_per_target_m3_ratio",
                "time_per_target_m3_bound_ratio", "time_per_target_m3_best_ratio", "solve_cpu_s", "solve_time_s", "load_before"}


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
                cells.append((h, number_text(x, ".0f" if c == "id" else ".3g"), x if x is not None else float("nan")))
            elif c == "success":
                cells.append((h, "yes" if bool(v) else "no", 1.0 if bool(v) else 0.0))
            else:
                cells.append((h, "" if v is None or (isinstance(v, float) and math.isnan(v)) else str(v), None))
        out.append({"cells": cells, "attrs": {k: v[i] for k, v in filters.items()}})
    return out


#: The page's style sheet and its tables' sorting and filtering script (files in :mod:`earthbench.assets`).
_CSS = assets.text("page.css")
_JS = assets.text("page.js")


def html_more_tables(sec: dict[str, Any]) -> str:
    """:func:`markdown_more_tables` for the page."""
    e = html.escape
    parts = []
    if sec.get("breakdowns"):
        parts.append(f"<h3>Breakdowns</h3><p class=\"rule\">{e(BREAKDOWN_NOTE)}.</p>")
        for heading, rows in sec["breakdowns"]:
            parts.append(f"<h4>{e(heading)}</h4>" + html_table(fold_zero_failures(rows)))
    if sec.get("history"):
        parts.append(f"<h3>History</h3><p class=\"rule\">{e(HISTORY_NOTE.replace('`', ''))}.</p>"
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
    """The self-contained page; ``viewer`` is the replay section (:func:`earthbench.running.playback.viewer_section`)."""
    from ...running.playback import CSS as REPLAY_CSS, SCRIPT as REPLAY_SCRIPT

    e = html.escape
    script = f"\n{_JS}\n{REPLAY_SCRIPT}"  # the content-security-policy hash below is of exactly this text
    script_hash = base64.b64encode(hashlib.sha256(script.encode()).digest()).decode()
    csp = (f"default-src 'none'; img-src data:; style-src 'unsafe-inline'; script-src 'sha256-{script_hash}'; "
           "base-uri 'none'; form-action 'none'")
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f'<meta http-equiv="Content-Security-Policy" content="{e(csp)}">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        "<title>earthbench leaderboard</title>",
        f"<style>\n{_CSS}\n{REPLAY_CSS}</style></head><body>",
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
        if s.get("partial"):
            parts.append(f'<p class="partial"><strong>{e(s["partial"])}</strong></p>')
        parts.append(html_table(fold_zero_failures(s["rows"])))
        parts.append(replay_links(s.get("replay_runs", [])))
        if s.get("best"):
            parts.append(f'<p class="best">Best known plans: {e(s["best"])} (every bracket [target bound, best known]: '
                         '<a href="best.csv">best.csv</a>).</p>')
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


def replay_runs(runs: pd.DataFrame, suite: str, track: str, picked: set[int]) -> list[dict[str, Any]]:
    """The runs of one table that the page's viewer embeds (``picked``), for :func:`replay_links`."""
    mine = runs[(runs["suite"] == suite) & (runs["track"] == track) & runs["id"].astype(int).isin(picked)]
    return [{"id": int(r["id"]), "solver": r["solver"],
             "what": "success" if bool(r["success"]) else ("valid" if r["reason"] == "ok" else str(r["reason"]))}
            for _, r in mine.sort_values(["solver", "id"]).iterrows()]


__all__ = ["FILTERS", "RUN_COLUMNS", "filter_bar", "fold_zero_failures", "html_more_tables", "html_page", "html_table",
           "replay_links", "replay_runs", "run_rows"]
