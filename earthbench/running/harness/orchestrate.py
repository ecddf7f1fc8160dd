"""A suite run: build its cases, run what the store lacks, store each result as it arrives."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from ...errors import PluginError, StoreError
from ...results.records import Case
from . import probe
from .local import Executor, LocalExecutor
from .sandbox import CASE_TAG

if TYPE_CHECKING:  # pragma: no cover
    from ...results.progress import Progress
    from .prepare import Prepared, PrepareStatus
    from ...results.store import Store
    from ...results.suite import Suite


@dataclass
class RunReport:
    """What one ``run_cases`` call did; ``interrupted`` is set when Ctrl-C ended it."""

    planned: int = 0
    skipped: int = 0
    stored: int = 0
    counts: dict[str, int] = field(default_factory=dict)
    interrupted: bool = False


def _refuse_inside_a_case() -> None:
    """A case process that reaches a suite run is importing a planner file that starts one at its top level."""
    if os.environ.get(CASE_TAG):
        raise PluginError(
            "the planner's file started a suite run while a case process imported it; "
            "put the code that runs suites under 'if __name__ == \"__main__\":'"
        )


def _refuse_a_visible_store(cases: Sequence[Case], store: Store) -> None:
    """No case may see the store (docs/isolation.md): it lies in no folder a case can read."""
    from . import isolation

    why = isolation.store_exposure(str(store.path), (c.planner for c in cases))
    if why:
        raise StoreError(why)


def build_cases(
    suite: Suite,
    planners: Sequence[str] | None = None,
    *,
    plugins: Sequence[str] = (),
    seeds: Iterable[int] | None = None,
) -> tuple[list[Case], list[str]]:
    """The cases of ``suite`` for ``planners`` (default: the suite's list, else every planner of its track).

    Returns the cases and notes for the user (planners skipped because of their track).
    """
    notes: list[str] = []
    explicit = bool(planners)
    if plugins:
        probe.use_plugin_files(plugins)
    if planners or suite.planners:
        names = list(planners or suite.planners or ())
    else:  # every planner of the track; one whose code failed to load is said, not silently left out
        cat = probe.catalogue()
        names = [n for n, p in cat.planners.items() if suite.track in p.tracks]
        notes += [f"{what} failed to load: {why}" for what, why in sorted(cat.failures.items())]
    if not names:
        notes.append(f"no registered planner supports the {suite.track!r} track")
    refs = []
    for name in dict.fromkeys(names):
        ref = probe.resolve(name, suite.config.get(name))
        if suite.track not in ref.tracks:
            if explicit:
                notes.append(f"planner {name!r} supports {', '.join(ref.tracks)}, not this suite's {suite.track!r} track: skipped")
            continue
        refs.append(ref)
    for name in suite.config:
        if not probe.known(name):
            notes.append(f"the suite configures planner {name!r}, which is not registered: its [config.{name}] is unused")
    plugin_paths = tuple(str(Path(p).resolve()) for p in plugins)
    cases = [
        Case(suite.name, suite.digest, suite.success_threshold, sc, ref, plugin_paths, prepare=suite.prepare)
        for sc in suite.select(seeds)
        for ref in refs
    ]
    return cases, notes


def _say_isolation(executor: Executor, progress: Progress) -> None:
    """Once, at the start of a local run: the fences missing on this machine (each result is stamped too)."""
    from . import isolation
    from .local import LocalExecutor

    if isinstance(executor, LocalExecutor) and not progress.quiet and not isolation.support().full:
        progress.stream.write(isolation.describe() + "\n")
        progress.stream.flush()


def run_cases(
    cases: Sequence[Case],
    store: Store,
    executor: Executor,
    *,
    rerun: bool = False,
    progress: Progress | None = None,
    log: Callable[[str], None] | None = None,
    on_prepare: Callable[[PrepareStatus], None] | None = None,
) -> RunReport:
    """Run every case not yet in ``store`` (all with ``rerun``) and store each as it finishes.

    Each planner that declares a preparation is prepared first, on this machine when the
    executor runs cases here (``log`` hears when it starts and what it took, ``on_prepare`` how
    far it is while it runs), else by each
    worker before its first case of that planner (:mod:`.prepare`).

    Only this function writes the store, one transaction per case, so an executor may run
    cases anywhere. Ctrl-C (KeyboardInterrupt) cancels the cases in flight (nothing of them is
    written), keeps every finished one and returns the report marked ``interrupted``.
    """
    _refuse_inside_a_case()
    check_code(cases, store)
    report = RunReport(planned=len(cases))
    done = set() if rerun else store.finished_keys()
    by_key: dict[tuple[str, str, str, str], Case] = {}
    for c in cases:  # one case per key: a scenario listed twice is run once
        if c.key not in done:
            by_key.setdefault(c.key, c)
    todo = list(by_key.values())
    report.skipped = len(cases) - len(todo)
    _refuse_a_visible_store(todo, store)
    if getattr(executor, "prepares_here", False):
        prepare_planners(todo, getattr(executor, "slots", [None])[0], log=log, on_prepare=on_prepare)
    if progress is not None:
        progress.total = len(todo)
        _say_isolation(executor, progress)
        progress.start()
    results = executor.run(todo)
    try:
        for res in results:
            case = by_key[res.key]
            if store.record(case, res, replace=rerun):
                report.stored += 1
            report.counts[res.reason] = report.counts.get(res.reason, 0) + 1
            if progress is not None:
                progress.update(case, res)
    except KeyboardInterrupt:
        report.interrupted = True
    finally:
        executor.cancel()
        close = getattr(results, "close", None)
        if close is not None:
            close()
        if progress is not None:
            progress.close()
    return report


def check_code(cases: Sequence[Case], store: Store) -> None:
    """Refuse a planner whose name and version the store holds with other code (docs/DESIGN.md §6
    "Plugin code"): its runs would be skipped as stored, or mixed with another planner's."""
    seen: set[tuple[str, str, str]] = set()
    for c in cases:
        p = c.planner
        if not p.code_digest or (p.name, p.version, p.code_digest) in seen:
            continue
        seen.add((p.name, p.version, p.code_digest))
        other = store.code_digests(p.name, p.version) - {p.code_digest}
        if other:
            raise PluginError(
                f"planner {p.name!r} {p.version} is stored in {store.path} with other code ({_short(sorted(other)[0])}) than "
                f"the one given here ({_short(p.code_digest)}): two planners of one name and version. Give this one another "
                f"version (or name), or use another store")


def _short(digest: str) -> str:
    return digest.split(":", 1)[-1][:12]


def prepare_planners(cases: Sequence[Case], cores: Sequence[int] | None = None, *,
                     log: Callable[[str], None] | None = None,
                     on_prepare: Callable[[PrepareStatus], None] | None = None) -> dict[str, Prepared | None]:
    """Prepare, once each and before any case, every planner configuration of ``cases`` that
    declares a preparation and has none on this machine. A failure is logged; that planner's
    cases then end as errors with its message (:func:`.run.run_case`)."""
    from .prepare import PrepareError, ensure

    out: dict[str, Prepared | None] = {}
    seen: set[tuple[str, str, str]] = set()
    for c in cases:
        ref = c.planner
        if not ref.prepares or not c.prepare or (ref.name, ref.version, ref.config_hash) in seen:
            continue
        seen.add((ref.name, ref.version, ref.config_hash))
        try:
            out[ref.name] = ensure(ref, c.scenario.budget, cores, log=log, on_progress=on_prepare)
        except PrepareError as exc:
            out[ref.name] = None
            if log is not None:
                log(str(exc))
    return out


def run_suite(
    suite: Suite,
    store: Store,
    executor: Executor | None = None,
    *,
    planners: Sequence[str] | None = None,
    plugins: Sequence[str] = (),
    seeds: Iterable[int] | None = None,
    rerun: bool = False,
    progress: Progress | None = None,
) -> RunReport:
    """The Python API of ``earthbench run``: register the suite in the store, run what is missing."""
    _refuse_inside_a_case()
    cases, _ = build_cases(suite, planners, plugins=plugins, seeds=seeds)
    store.register_suite(suite)
    return run_cases(cases, store, executor or LocalExecutor(cores_per_case=suite.budget.cores), rerun=rerun, progress=progress)
