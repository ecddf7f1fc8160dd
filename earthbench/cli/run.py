"""``earthbench run SUITE``: run a suite's cases under the budget and store every result.

Cases already in the database are skipped, so the same command resumes a killed run;
``--rerun`` runs (and replaces) them again. Ctrl-C stops cleanly: finished cases stay stored.
"""

from __future__ import annotations

import argparse
import math
import os
import shlex
import signal
import sys
from typing import Any

from ..errors import EarthbenchError, SuiteError
from ..running.harness import REASONS, LocalExecutor, build_cases, run_cases
from ..running.harness.orchestrate import check_code
from ..results.store import DEFAULT_DB, Store, default_db, load_runs, suite_members
from ..results.suite import load_suite, parse_seed_range
from ._common import add_config_arg, add_plugin_arg, load_plugins, parse_config, plural
from .preparing import PrepareDisplay
from .runs import db_option, failure_filters

HELP = """Run every (planner, scenario) case of a suite, each in a fresh process pinned to its own
2-core slot under the suite's wall and memory budget, and store each result as it finishes.

Cases already in the database are skipped, so the same command resumes a killed run;
--rerun runs (and replaces) them again. Ctrl-C stops cleanly: finished cases stay stored.

Each finished case prints one line; an invalid or failed one names the broken rule (or
the error) and the command that shows it in full (earthbench runs --id N).

Exit status: 1 when no case of the command (run now or stored before) has a valid plan
(every one invalid, timed out, out of memory, an error or crashed); with --require-success,
1 unless at least one case succeeded (valid and at the success threshold). Otherwise 0;
2 for bad input, 130 when interrupted."""


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "run",
        help="run a suite and store the results (resumes: stored cases are skipped)",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("suite", help="suite name (see `earthbench suites`) or path of a suite TOML file")
    p.add_argument("--planner", action="append", default=[], metavar="NAME",
                   help="planner to run (repeatable; default: the suite's planners, else every planner of its track)")
    add_plugin_arg(p)
    add_config_arg(p)
    p.add_argument("--db", default=default_db(), metavar="PATH", help=f"results database (default: $EARTHBENCH_DB or {DEFAULT_DB})")
    p.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="cases at once (default and maximum: floor(cores / budget cores))")
    p.add_argument("--rerun", action="store_true", help="run cases again even if they are stored, replacing their rows")
    p.add_argument("--seeds", metavar="A-B", help="only scenarios with these seeds: a seed, a range or a comma-separated list,"
                   " e.g. 3, 0-4 or 0-2,7")
    p.add_argument("--sealed", metavar="KEYFILE",
                   help="run the suite's sealed draw of this key (`earthbench seal` made it; docs/sealed-evaluation.md)")
    p.add_argument("--quiet", action="store_true", help="no progress output, only the summary")
    p.add_argument("--require-success", action="store_true",
                   help="exit with status 1 unless at least one case succeeded (default: unless one has a valid plan)")
    p.add_argument("--executor", choices=("local", "dask"), default=None,
                   help="where cases run: local slots (default) or a Dask cluster (needs the `dask` extra)")
    p.add_argument("--scheduler", metavar="ADDR",
                   help="Dask scheduler address, e.g. tcp://HOST:8786 (implies --executor dask; "
                        "default: $DASK_SCHEDULER_ADDRESS); workers need --resources \"slots=K\"")
    return p


def _fmt(v: Any, spec: str = ".2f") -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "–"
    return format(v, spec)


def print_summary(store: Store, suite: str, planners: list[str] | None = None, file: Any = None,
                  seeds: tuple[int, ...] | None = None) -> None:
    """A row per planner configuration of everything stored for ``suite`` (only the scenarios of
    ``seeds`` when given: runs and denominators alike): the leaderboard's aggregates
    (:func:`earthbench.results.aggregate.aggregate`), its intervals in brackets and its wording."""
    import pandas as pd

    from ..results.aggregate import RANK_ALPHA, aggregate, ci_text
    from ..stats import INTERVAL_NOTE, min_separating_n, separation_note

    runs = load_runs(store, suite=suite)
    members = suite_members(store, [suite])
    if seeds is not None:
        members = members[members["seed"].isin(seeds)]
        runs = runs[runs["scenario_digest"].isin(set(members["scenario_digest"]))]
    if planners is not None:
        runs = runs[runs["planner"].isin(planners)]
    file = file or sys.stdout
    if runs.empty:
        print(f"no runs stored for suite {suite!r}" + (" on the selected seeds" if seeds is not None else ""), file=file)
        return
    rows = aggregate(runs, members=members, all_versions=True)
    head = ["configuration", "runs", "success", "vol.ratio mean±sd", "time/target m³ med", "short", "time/m³ med",
            "solve CPU s med", "wall s med", *REASONS]
    table = [head]
    for _, r in rows.iterrows():
        vr = _fmt(r["volume_ratio_mean"]) + ("" if pd.isna(r["volume_ratio_sd"]) else "±" + _fmt(r["volume_ratio_sd"]))
        table.append([
            f"{r['config_label']} {r['planner_version']}", f"{r['runs']}/{r['of']}",
            ci_text(r["success_rate"], r["success_rate_lo"], r["success_rate_hi"], ".0f", 100, "%"),
            vr, ci_text(r["time_per_target_m3_median"], r["time_per_target_m3_lo"], r["time_per_target_m3_hi"]),
            str(r["short_of_target"]), _fmt(r["time_per_m3_median"], ".1f"), _fmt(r["solve_cpu_median"], ".2f"),
            _fmt(r["solve_time_median"], ".2f"), *(str(r[f"n_{k}"]) for k in REASONS),
        ])
    widths = [max(len(row[i]) for row in table) for i in range(len(head))]
    what = f"{plural(int(rows['of'].max()), 'scenario')}" + (" of the selected seeds" if seeds is not None else "")
    print(f"\nsuite {suite}, {what} ({INTERVAL_NOTE}):", file=file)
    for n, row in enumerate(table):
        print("  " + "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths))), file=file)
        if n == 0:
            print("  " + "  ".join("-" * w for w in widths), file=file)
    print(LEGEND, file=file)
    missing = rows[rows["runs"] < rows["of"]]
    if len(missing):
        who = "; ".join(f"{r['config_label']} {r['planner_version']} {r['runs']} of {r['of']}" for _, r in missing.iterrows())
        print(f"  partial: not every scenario has a run ({who}); a scenario without one counts as failed, so these "
              "figures and the order are on partial data until the same command completes them", file=file)
    n_of = int(rows["of"].max())
    if len(rows) > 1 and n_of < min_separating_n(RANK_ALPHA):
        print(f"  note: {separation_note(n_of, RANK_ALPHA)}", file=file)


#: What the summary's columns mean (printed under it).
LEGEND = """  runs: stored / scenarios (selected); success: scenarios with a valid plan loading ≥ the threshold
  (a scenario without a run counts as failed); vol.ratio: loaded / target volume over valid runs;
  time/target m³: time to the target / the target, median over valid runs (∞: short of the target,
  counted in short); time/m³: plan time per loaded m³; solve CPU s: median CPU time of the case's
  processes (ranked), wall s: its wall time; ok … crashed: runs by termination reason (invalid: the
  referee found a broken rule)"""


def _sigterm(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


def run(args: argparse.Namespace) -> int:
    load_plugins(args)
    suite = load_suite(args.suite)
    if args.sealed:
        from ..seal import SealKey
        from ..results.suite import open_sealed

        suite = open_sealed(suite, SealKey.read(args.sealed))
    if args.config:
        if not args.planner:
            raise EarthbenchError("--config needs --planner NAME: the settings are checked against that planner's Config")
        from ..running.harness.probe import info

        for name in dict.fromkeys(args.planner):  # the command line's settings over the suite file's
            suite.config[name] = {**suite.config.get(name, {}), **parse_config(args.config, info(name))}
    seeds = parse_seed_range(args.seeds) if args.seeds else None
    if seeds is not None and not suite.select(seeds):
        have = sorted({int(s.meta["seed"]) for s in suite.scenarios if s.meta.get("seed") is not None})
        raise SuiteError(f"--seeds {args.seeds} selects no scenario of suite {suite.name!r}; its seeds: "
                         f"{', '.join(map(str, have[:20])) or '(none)'}{' …' if len(have) > 20 else ''}")
    cases, notes = build_cases(suite, args.planner or None, plugins=args.plugin, seeds=seeds)
    for note in notes:
        print(f"earthbench: note: {note}", file=sys.stderr)
    if args.jobs is not None and args.jobs < 1:
        print("earthbench: error: --jobs must be at least 1", file=sys.stderr)
        return 2
    with Store(args.db) as store:
        store.check_writable()
        check_code(cases, store)  # a planner squatting on another's name and version: before anything is written
        store.register_suite(suite)
        executor = make_executor(args, suite)
        if args.jobs is not None and isinstance(executor, LocalExecutor) and args.jobs > len(executor.slots):
            print(f"earthbench: note: --jobs {args.jobs}: only {plural(len(executor.slots), 'case')} at once here, "
                  f"as each case gets {suite.budget.cores} cores of its own and this machine lets earthbench use "
                  f"{plural(len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else os.cpu_count() or 1, 'core')}",
                  file=sys.stderr)
        from ..results.progress import Progress

        progress = Progress(len(cases), quiet=args.quiet, run_id=lambda case: store.run_id(case.key),
                            runs_command=f"earthbench runs{db_option(args.db)}")
        planners = sorted({c.planner.name for c in cases})
        if not args.quiet:
            print(
                f"suite {suite.name} ({suite.digest[:12]}): {plural(len(cases), 'case')} "
                f"({plural(len(suite.select(seeds)), 'scenario')} × {', '.join(planners) or 'no planner'}), "
                f"{plural(len(executor.slots), 'slot')} of {suite.budget.cores} cores, budget {suite.budget.wall_s:g} s / "
                f"{suite.budget.memory_mb} MB per case, db {args.db}",
                file=sys.stderr,
            )
        shown = PrepareDisplay()  # a preparation's start, progress and end (docs/running.md "Preparation")
        old = signal.signal(signal.SIGTERM, _sigterm) if _main_thread() else None
        try:
            report = run_cases(cases, store, executor, rerun=args.rerun, progress=progress,
                               log=None if args.quiet else shown.log, on_prepare=None if args.quiet else shown.progress)
        finally:
            if old is not None:
                signal.signal(signal.SIGTERM, old)
            getattr(executor, "close", lambda: None)()
        print_summary(store, suite.name, planners, seeds=seeds)
        if report.interrupted:
            left = report.planned - report.skipped - report.stored
            print(f"earthbench: interrupted: {plural(report.stored, 'finished case')} stored, {left} not run"
                  + (f", {report.skipped} skipped as already stored" if report.skipped else "")
                  + "; the table above is partial (a scenario without a run counts as failed); "
                  "run the same command again to resume", file=sys.stderr)
            return 130
        enough = any_stored(store, cases, succeeded=args.require_success)
        if not args.quiet:
            print("\n" + next_steps(store, cases, args, suite.name), file=sys.stderr)
        if cases and not enough:
            what = "succeeded" if args.require_success else "has a valid plan"
            print(f"earthbench: no case {what} (exit status 1); see {runs_command(args, suite.name)}", file=sys.stderr)
            return 1
    return 0


def runs_command(args: argparse.Namespace, suite: str) -> str:
    """``earthbench runs`` narrowed to this command's store, suite, seeds and planners, runnable as printed."""
    planners = "".join(f" --planner {shlex.quote(p)}" for p in dict.fromkeys(args.planner))
    seeds = f" --seeds {shlex.quote(args.seeds)}" if args.seeds else ""
    return f"earthbench runs{db_option(args.db)} --suite {shlex.quote(suite)}{seeds}{planners}"


def next_steps(store: Store, cases: list[Any], args: argparse.Namespace, suite: str) -> str:
    """The commands to look further, each runnable as printed: the ``runs`` filters that show the
    failures that happened (none named when none did) and the leaderboard of the same selection."""
    keys = {c.key for c in cases}
    rows = [r for r in store.query(suite=suite, planner=sorted({c.planner.name for c in cases}))
            if (r["scenario_digest"], r["planner"], r["planner_version"], r["config_hash"]) in keys]
    base = runs_command(args, suite)
    lines = [f"{base} {flt}  ({what}; then --id N for one run)" for flt, what in failure_filters(rows)]
    if rows and not lines:
        lines = [f"{base}  (every run reached the target; --id N shows one in full)"]
    seeds = f" --seeds {shlex.quote(args.seeds)}" if args.seeds else ""
    lines.append(f"earthbench leaderboard{db_option(args.db)} --suite {shlex.quote(suite)}{seeds}  "
                 "(tables, figures and a page with replays, in board/)")
    return "next: " + "\n      ".join(lines)


def any_stored(store: Store, cases: list[Any], *, succeeded: bool) -> bool:
    """Whether any of ``cases`` has a stored run (by this command or before it) that succeeded, or
    without ``succeeded`` that ended ``ok`` (a valid plan)."""
    keys = store.finished_keys(succeeded=True) if succeeded else store.finished_keys(reason="ok")
    return any(c.key in keys for c in cases)


def make_executor(args: argparse.Namespace, suite: Any) -> Any:
    """The local executor, or a :class:`~earthbench.running.harness.dask_executor.DaskExecutor` for ``--executor dask``."""
    if (args.executor or ("dask" if args.scheduler else "local")) == "dask":
        from ..running.harness.dask_executor import DaskExecutor
        from ..errors import EarthbenchError

        try:
            executor = DaskExecutor(scheduler=args.scheduler, jobs=args.jobs)
        except ImportError as exc:
            raise EarthbenchError(f"--executor dask needs Dask distributed ({exc}); pip install 'earthbench[dask]'") from None
        try:
            executor.check()
        except BaseException:
            executor.close()
            raise
        return executor
    return LocalExecutor(jobs=args.jobs, cores_per_case=suite.budget.cores)


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()
