"""Publishing: the store → ``leaderboard/`` (docs/DESIGN.md §9).

:func:`publish` writes, for every suite in the store (or the ones asked for):

* ``README.md`` — one table per suite and track, ranked by the rule stated above it
  (:data:`earthbench.results.aggregate.RANKING_RULE`: the latest version of each planner, shared ranks
  where paired tests cannot separate neighbours), with a reproducibility stamp (project
  commits, suite digest, CPU models and cores, run dates, generation date), what each figure
  rests on (referee figures re-judgeable from the stored plans; solve times from the machine
  named for each planner, † on solve-time columns that mix machines; the latest
  ``earthbench verify`` spot re-timing of each planner version); under it one table per family
  and per target, a history table of older versions, and the figures;
* ``runs.csv`` — one row per run and suite it is published under (a run of ``paper-switch``
  also counts for ``standard``, which includes it), every column of
  :func:`earthbench.results.store.load_runs`;
* ``best.csv`` — with a folder of best known plans (``best``, :mod:`earthbench.publishing.best`): each kept
  scenario's bracket [target bound, best known time per target m³] and who produced the plan; the
  runs and tables then carry each run's ratio to its scenario's best known time (``× best known``);
* ``summary.csv`` — :func:`earthbench.results.aggregate.aggregate` of those runs, every table (columns
  ``scope`` = suite | family | target and ``group``), medians and rates with their 95 % intervals
  (:data:`earthbench.stats.INTERVAL_NOTE`); a table with too few scenarios for any paired test to
  separate two planners has ``‡`` on its Rank heading and the stamp says so (:func:`earthbench.stats.separation_note`);
* ``index.html`` — one self-contained page: inline CSS, a small inline script (allowed by a
  content-security policy hash, so no other script can run), tables that sort on a click,
  filter by family, planner and version (``data-*`` attributes of each row, :data:`FILTERS`)
  and wrap their headings to fit the window, links to the CSVs, the figures as ``data:`` URIs
  and the replay viewer of :mod:`earthbench.running.playback`; no network resource. Every string from
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

The work is split by job (``earthbench.publishing.board``): :mod:`~earthbench.publishing.board.selection` (which runs and
versions a board shows), :mod:`~earthbench.publishing.board.tables` (rows, stamps, Markdown and CSV),
:mod:`~earthbench.publishing.board.figures` (the figures and the worker pool that draws them) and
:mod:`~earthbench.publishing.board.page` (the HTML page); :func:`publish` runs them in turn, the figures
first so the workers draw while the tables are made. The names they define are importable from
here too, as before the split.
"""


from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime, UTC
from pathlib import Path
from typing import Any

import pandas as pd

from .. import compat
from ..results.aggregate import SCOPES, aggregate, latest_versions
from .best import bracket_lines, bracket_markdown, bracket_table, with_best_known
from .board.figures import Renderer, figure_jobs
from .board.page import html_page, replay_runs, run_rows
from .board.selection import closed_configs, histories, limit_to_seeds, published_runs, shown_runs
from .board.tables import (mark_mixed_solve_columns, markdown_page, production_note, slug, spreadsheet_safe, stamp, table_sections,
                           write_csv)
from ..results.generalisation import gap_table, markdown as gap_markdown, with_sealed_draws, write as write_gaps
from ..results.labels import latest_spot_checks
from ..running.scaling import SCALE_CAPTION, scale_section
from ..results.store import Store, suite_members


@dataclass
class Published:
    """What :func:`publish` wrote."""

    out: Path
    files: list[Path] = field(default_factory=list)
    removed: list[Path] = field(default_factory=list)  #: figures of an earlier board in ``figures/``, deleted
    runs: pd.DataFrame | None = None
    summary: pd.DataFrame | None = None


#: (section, caption, file path without its suffix) of each figure, in the order the page shows them.
Captions = list[tuple[dict[str, Any], str, Path]]


def publish(db: str | Path, out: str | Path = "leaderboard", suites: Sequence[str] | None = None, *,
            figures: bool = True, terrain: bool = True, generated: str | None = None,
            workers: int | None = None, replays: int = 20, all_versions: bool = False,
            seeds: Sequence[int] | None = None, best: str | Path | None = None) -> Published:
    """Write the leaderboard of ``db`` (the suites in ``suites``, default all) into ``out``.

    ``seeds``: limit the board to the suite's scenarios of these seeds (runs and denominators
    alike, so a planner run on those seeds only is not charged failures for the others);
    every table's stamp says so.

    ``workers``: processes drawing the figures (default: one per core this process may use);
    ``replays``: how many runs the page's replay viewer embeds (0: none);
    ``all_versions``: rank every stored version, not only each planner's latest;
    ``best``: the folder of best known plans (:mod:`earthbench.publishing.best`): each run's ratio to its
    scenario's best known time per target m³ (a "× best known" column) and ``best.csv`` (the brackets).
    """
    from ..running.playback import pick_runs, viewer_section

    out = Path(out)
    generated = generated or datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    result = Published(out)
    captions: Captions = []
    with Store(db, create=False) as store:
        suites = with_sealed_draws(store, suites)  # a suite's sealed draws are published beside it
        runs = published_runs(store, suites)
        runs, members, seed_note = limit_to_seeds(runs, suite_members(store, runs["suite"].unique()), seeds)
        runs = with_best_known(runs, best)
        (out / "figures").mkdir(parents=True, exist_ok=True)  # only now: a refused leaderboard writes nothing
        groups = list(runs.groupby(["suite", "track"], sort=True))
        sections: list[dict[str, Any]] = [{"suite": suite, "track": track, "figures": [], "md_figures": []}
                                          for (suite, track), _ in groups]
        renderer = Renderer(workers) if figures else None
        # the figures first, so the workers draw while this process makes the tables
        _queue_run_figures(renderer, captions, store, sections, groups, out / "figures", latest_versions(runs), terrain,
                           all_versions)
        spot_checks = latest_spot_checks(store)
        for sec, ((suite, track), srun) in zip(sections, groups):
            st = sec["stamp"] = stamp(srun, suite, track, generated, spot_checks, seed_note)
            sec["classes"] = {store.scenario(d).machines.machine_class for d in srun["scenario_digest"].unique()}
            st.classes = ", ".join(sorted(sec["classes"]))
            sec["run_rows"] = run_rows(srun.sort_values("id"))
            sec["scale_rows"] = mark_mixed_solve_columns(sec["scale_rows"], st.mixed) if sec["scale_rows"] else sec["scale_rows"]
        viewer = viewer_section(store, runs, replays)
        picked = set(pick_runs(runs, replays)["id"].astype(int)) if viewer else set()
        # the tables (intervals, paired tests) while the workers draw
        summary = aggregate(runs, members=members, scopes=SCOPES, all_versions=all_versions)
        result.runs, result.summary = runs, summary
        gaps = gap_table(runs, members)  # sealed draws against the public suite (earthbench.results.generalisation)
        closed = closed_configs(runs)
        for sec in sections:
            ssum = summary[(summary["suite"] == sec["suite"]) & (summary["track"] == sec["track"])]
            whole = ssum.loc[ssum["scope"] == "suite", "production_m3h_median"]
            sec["stamp"].production = production_note(sec["classes"], sec["track"], best=whole.max() if len(whole) else None)
            sec["replay_runs"] = replay_runs(runs, sec["suite"], sec["track"], picked)
            sec.update(table_sections(ssum, all_versions, closed, sec["stamp"].mixed))
            if renderer is not None:
                base = out / "figures" / slug(f"{sec['suite']}-{sec['track']}")
                for planner, hist in histories(ssum):
                    path = base.parent / f"{base.name}-history-{slug(planner)}"
                    renderer.add(("history", str(path), (hist, f"{planner} on suite {sec['suite']}")))
                    captions.append((sec, f"History of {planner}: success rate and median time per target m³ by version", path))
    # the brackets of the board's scenarios (a --seeds board: those seeds only)
    brackets = bracket_table(best, members if len(members) else runs)
    sizes = {str(k): int(v) for k, v in members.groupby("suite").size().items()} if len(members) else {}
    lines = bracket_lines(brackets, sizes)
    for sec in sections:
        sec["best"] = lines.get(str(sec["suite"]), "")
    _write(result, runs, summary, sections, captions, renderer, generated, bracket_markdown(brackets, sizes) + gap_markdown(gaps),
           viewer)
    result.files += write_gaps(gaps, out)
    if len(brackets):
        write_csv(out / "best.csv", spreadsheet_safe(brackets).to_csv(index=False))
        result.files.append(out / "best.csv")
    result.files += [out / "README.md", out / "runs.csv", out / "summary.csv", out / "index.html"]
    result.removed = _remove_stale_figures(out / "figures", result.files)
    return result


def _queue_run_figures(renderer: Renderer | None, captions: Captions, store: Store, sections: list[dict[str, Any]],
                       groups: list[Any], fig_dir: Path, latest: set[tuple[str, str, str, str]], terrain: bool,
                       all_versions: bool) -> None:
    """Each table's scale rows, and its figures handed to the workers (history figures wait for the tables)."""
    scenarios: dict[str, str] = {}
    for sec, ((suite, track), srun) in zip(sections, groups):
        base = fig_dir / slug(f"{suite}-{track}")
        title = f"suite {suite}, {track}"
        sec["scale_rows"], job = scale_section(srun, str(base.parent / f"{base.name}-cost-growth"), title)
        if renderer is None:
            continue
        jobs = [(SCALE_CAPTION, job)] if job is not None else []
        jobs += figure_jobs(store, shown_runs(srun, latest, all_versions), base, title, terrain, scenarios)
        for caption, job in jobs:
            renderer.add(job)
            captions.append((sec, caption, Path(job[1])))
    if renderer is not None:
        renderer.start()


def _write(result: Published, runs: pd.DataFrame, summary: pd.DataFrame, sections: list[dict[str, Any]],
           captions: Captions, renderer: Renderer | None, generated: str, gaps_md: str, viewer: str) -> None:
    """Every file but the generalisation table: the texts while the workers finish, then the page with their PNGs."""
    out = result.out
    for sec, cap, path in captions:
        png_path, svg_path = path.parent / (path.name + ".png"), path.parent / (path.name + ".svg")
        result.files += [png_path, svg_path]
        sec["md_figures"].append((cap, png_path.relative_to(out), svg_path.relative_to(out)))
    runs_csv = spreadsheet_safe(runs.drop(columns=[c for c in ("packages",) if c in runs])).to_csv(index=False)
    summary_csv = spreadsheet_safe(summary).to_csv(index=False)
    readme = markdown_page(sections, generated) + gaps_md
    for (sec, cap, _), png in zip(captions, renderer.results() if renderer else []):
        sec["figures"].append((cap, png))
    write_csv(out / "runs.csv", runs_csv)
    write_csv(out / "summary.csv", summary_csv)
    (out / "README.md").write_text(readme)
    (out / "index.html").write_text(html_page(sections, generated, viewer))


def _remove_stale_figures(fig_dir: Path, files: list[Path]) -> list[Path]:
    """Delete the figures of an earlier board (another suite, planner or version would mislead); return them."""
    written = {f.resolve() for f in files}
    removed = []
    for old in fig_dir.glob("*"):
        if old.suffix in (".png", ".svg") and old.is_file() and old.resolve() not in written:
            old.unlink()
            removed.append(old)
    return removed


__all__ = ["Published", "publish"]
#: The names of earthbench.publishing.board's modules that were defined here before the split (0.3.0) still
#: import from here, with a warning (earthbench.compat).
__getattr__ = compat.forward(__name__)
