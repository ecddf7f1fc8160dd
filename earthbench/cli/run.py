"""``earthbench run SUITE``: run a suite's cases under the budget and store every result.

Cases already in the database are skipped, so the same command resumes a killed run;
``--rerun`` runs (and replaces) them again. Ctrl-C stops cleanly: finished cases stay stored.
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import sys
from typing import Any

from ..harness import REASONS, LocalExecutor, build_cases, run_cases
from ..store import DEFAULT_DB, Store, summary_rows
from ..suite import load_suite, parse_seed_range
from ._common import add_plugin_arg, load_plugins

HELP = """Run every (planner, scenario) case of a suite, each in a fresh process pinned to its own
2-core slot under the suite's wall and memory budget, and store each result as it finishes.

Cases already in the database are skipped, so the same command resumes a killed run;
--rerun runs (and replaces) them again. Ctrl-C stops cleanly: finished cases stay stored."""


def default_db() -> str:
    return os.environ.get("EARTHBENCH_DB", DEFAULT_DB)


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
    p.add_argument("--db", default=default_db(), metavar="PATH", help=f"results database (default: $EARTHBENCH_DB or {DEFAULT_DB})")
    p.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="cases at once (default and maximum: floor(cores / budget cores))")
    p.add_argument("--rerun", action="store_true", help="run cases again even if they are stored, replacing their rows")
    p.add_argument("--seeds", metavar="A-B", help="only scenarios whose seed is in this range, e.g. 0-4 or 3")
    p.add_argument("--quiet", action="store_true", help="no progress output, only the summary")
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


def print_summary(store: Store, suite: str, planners: list[str] | None = None, file: Any = None) -> None:
    """A table per planner of everything stored for ``suite``."""
    rows = summary_rows(store, suite, planners)
    file = file or sys.stdout
    if not rows:
        print(f"no runs stored for suite {suite!r}", file=file)
        return
    head = ["planner", "runs", "success", "vol.ratio mean±sd", "time/m³ med", "solve s med", *REASONS]
    table = [head]
    names = [r["planner"] for r in rows]
    for r in rows:
        vr = _fmt(r["volume_ratio_mean"]) + ("±" + _fmt(r["volume_ratio_sd"]) if r["volume_ratio_sd"] is not None else "")
        label = f"{r['planner']} {r['version']}" + (f" [{r['config_hash'][:8]}]" if names.count(r["planner"]) > 1 else "")
        table.append([
            label, f"{r['runs']}/{r['of']}", f"{100 * r['success']:.0f}%", vr, _fmt(r["time_per_m3_median"], ".1f"),
            _fmt(r["solve_time_median"], ".2f"), *(str(r["counts"].get(k, 0)) for k in REASONS),
        ])
    widths = [max(len(row[i]) for row in table) for i in range(len(head))]
    print(f"\nsuite {suite}:", file=file)
    for n, row in enumerate(table):
        print("  " + "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths))), file=file)
        if n == 0:
            print("  " + "  ".join("-" * w for w in widths), file=file)


def _sigterm(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


def run(args: argparse.Namespace) -> int:
    load_plugins(args)
    suite = load_suite(args.suite)
    seeds = parse_seed_range(args.seeds) if args.seeds else None
    cases, notes = build_cases(suite, args.planner or None, plugins=args.plugin, seeds=seeds)
    for note in notes:
        print(f"earthbench: note: {note}", file=sys.stderr)
    if args.jobs is not None and args.jobs < 1:
        print("earthbench: error: --jobs must be at least 1", file=sys.stderr)
        return 2
    with Store(args.db) as store:
        store.check_writable()
        store.register_suite(suite)
        executor = make_executor(args, suite)
        from ..progress import Progress

        progress = Progress(len(cases), quiet=args.quiet)
        planners = sorted({c.planner.name for c in cases})
        if not args.quiet:
            print(
                f"suite {suite.name} ({suite.digest[:12]}): {len(cases)} cases "
                f"({len(suite.select(seeds))} scenarios × {', '.join(planners) or 'no planner'}), "
                f"{len(executor.slots)} slot(s) of {suite.budget.cores} cores, budget {suite.budget.wall_s:g} s / "
                f"{suite.budget.memory_mb} MB per case, db {args.db}",
                file=sys.stderr,
            )
        old = signal.signal(signal.SIGTERM, _sigterm) if _main_thread() else None
        try:
            report = run_cases(cases, store, executor, rerun=args.rerun, progress=progress)
        finally:
            if old is not None:
                signal.signal(signal.SIGTERM, old)
            getattr(executor, "close", lambda: None)()
        if report.skipped and not args.quiet:
            print(f"{report.skipped} case(s) already stored were skipped (use --rerun to run them again)", file=sys.stderr)
        print_summary(store, suite.name, planners)
        if report.interrupted:
            left = report.planned - report.skipped - report.stored
            print(f"earthbench: interrupted: {report.stored} finished case(s) stored, {left} not run; "
                  "run the same command again to resume", file=sys.stderr)
            return 130
    return 0


def make_executor(args: argparse.Namespace, suite: Any) -> Any:
    """The local executor, or a :class:`~earthbench.harness.dask_executor.DaskExecutor` for ``--executor dask``."""
    if (args.executor or ("dask" if args.scheduler else "local")) == "dask":
        from ..harness.dask_executor import DaskExecutor
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
