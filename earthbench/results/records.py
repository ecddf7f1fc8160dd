"""The records of a run: the planner a case names, the case, and what happened in it.

The store keeps them and the harness makes them, so they live below both (docs/DESIGN.md §2):
the store reads these types and imports nothing of the harness. They are plain frozen
dataclasses, picklable, so any executor can ship a case to where it runs and its result back.
``earthbench.running.harness.cases`` and ``earthbench.running.harness`` still export them under their old names.
"""

from __future__ import annotations

import ast
import statistics
import sys
from dataclasses import dataclass, field
from datetime import datetime, UTC
from pathlib import Path
from types import FrameType
from typing import Any

from ..errors import PluginError
from ..planner import Planner, SharedFolder
from ..registry import PLANNERS, class_digest
from ..world import Scenario

#: Termination reasons of a stored case (``cancelled`` results are never stored).
REASONS = ("ok", "invalid", "timeout", "memory", "error", "crashed")


def utc_now() -> str:
    """The time stamp of ``started_at``/``finished_at``: UTC, to the second."""
    return datetime.now(UTC).isoformat(timespec="seconds")


@dataclass(frozen=True)
class PlannerRef:
    """How a fresh process finds a planner class, plus the identity the store keys on.

    ``source`` is ``module:qualname`` (importable in the child) or the path of a plugin file.
    """

    name: str
    version: str
    source: str
    config: dict[str, Any] = field(hash=False, compare=False)
    config_hash: str = ""
    overrides: dict[str, Any] = field(default_factory=dict, hash=False, compare=False)
    tracks: tuple[str, ...] = ("backhoe",)
    #: Whether the planner declares a preparation (docs/DESIGN.md §6 "Preparation").
    prepares: bool = field(default=False, compare=False)
    #: A digest of the code that provides the planner (docs/DESIGN.md §6 "Plugin code"): ``sha256:…`` of a
    #: plugin file or of a distribution's files, ``earthbench`` for the built-in planners, '' unknown.
    code_digest: str = field(default="", compare=False)
    #: The folders outside its own files its cases read (``Planner.reads``; docs/DESIGN.md §6 "Isolation").
    reads: tuple[SharedFolder, ...] = field(default=(), compare=False)

    @classmethod
    def resolve(cls, name: str, overrides: dict[str, Any] | None = None) -> PlannerRef:
        """Look ``name`` up in this process's registry (the built-in planners and those a script
        registered) and check ``overrides`` against its ``Config``. Another distribution's planner or
        a plugin file is resolved by :func:`earthbench.running.harness.probe.resolve`, never imported here."""
        klass = PLANNERS.get(name)
        overrides = dict(overrides or {})
        probe = object.__new__(klass)  # the base initialiser only: a heavy subclass __init__ runs in the case
        Planner.__init__(probe, **overrides)
        return cls(
            name=name,
            version=str(klass.version),
            source=_source_of(klass),
            config=probe.config_dict,
            config_hash=probe.config_hash,
            overrides=overrides,
            tracks=tuple(klass.tracks),
            prepares=klass.prepares(),
            code_digest=class_digest(klass),
            reads=tuple(klass.reads),
        )


def _source_of(klass: type[Planner]) -> str:
    mod = sys.modules.get(klass.__module__)
    file = getattr(mod, "__file__", None)
    if "<locals>" in klass.__qualname__:
        raise PluginError(
            f"planner class {klass.__qualname__} is defined inside a function; define it at module level so a case process can import it"
        )
    if klass.__module__ == "__main__" or klass.__module__.startswith("earthbench_plugin_"):
        if not file:
            raise PluginError(f"planner {klass.name!r} is defined interactively; put it in a file and pass --plugin FILE.py")
        if klass.__module__ == "__main__":
            line = _unguarded_main_line(file)
            if line is not None:
                raise PluginError(
                    f"planner {klass.name!r} is defined in the script {file}, whose line {line} starts the run outside "
                    f"'if __name__ == \"__main__\":'. Each case process imports the script to find the planner and would "
                    f"run that line again; put the code that runs suites under that guard"
                )
        return str(Path(file).resolve())
    return f"{klass.__module__}:{klass.__qualname__}"


def _unguarded_main_line(file: str) -> int | None:
    """The line of the running script's top-level statement that led here, unless it is a ``__main__`` guard.

    A case process executes the script that defines its planner; a statement outside the guard
    would start the suite again inside every case (each then waits out its start-up cap).
    """
    main = sys.modules.get("__main__")
    frame: FrameType | None = sys._getframe()
    while frame is not None and not (frame.f_code.co_name == "<module>" and main is not None
                                     and frame.f_globals is vars(main)):
        frame = frame.f_back
    if frame is None:
        return None  # called later (a callback, an interactive session): the script's top level has run
    try:
        tree = ast.parse(Path(file).read_text())
    except (OSError, SyntaxError, ValueError):
        return None
    line = frame.f_lineno
    for node in tree.body:
        if node.lineno <= line <= (node.end_lineno or node.lineno):
            return None if _is_main_guard(node) else line
    return None


def _is_main_guard(node: ast.stmt) -> bool:
    if not isinstance(node, ast.If) or not isinstance(node.test, ast.Compare) or len(node.test.comparators) != 1:
        return False
    sides = [node.test.left, node.test.comparators[0]]
    return (any(isinstance(s, ast.Name) and s.id == "__name__" for s in sides)
            and any(isinstance(s, ast.Constant) and s.value == "__main__" for s in sides))


@dataclass(frozen=True)
class Case:
    """One (planner configuration, scenario) pair of a suite; ``key`` identifies its result."""

    suite: str
    suite_digest: str
    threshold: float
    scenario: Scenario
    planner: PlannerRef
    plugins: tuple[str, ...] = ()
    #: Whether the planner's preparation runs (or is used) for this case: the suite's ``prepare``.
    prepare: bool = True

    @property
    def key(self) -> tuple[str, str, str, str]:
        """(scenario digest, planner, version, config hash): the resume key of the store."""
        p = self.planner
        return (self.scenario.digest, p.name, p.version, p.config_hash)

    @property
    def label(self) -> str:
        return f"{self.scenario.id} × {self.planner.name}"


@dataclass(frozen=True)
class CaseResult:
    """What happened in one case. ``metrics`` is None unless the planner returned a plan."""

    key: tuple[str, str, str, str]
    scenario_id: str
    reason: str
    solve_time_s: float | None = None
    solve_cpu_s: float | None = None
    startup_s: float | None = None
    peak_rss_mb: float | None = None
    metrics: dict[str, Any] | None = None
    violations: tuple[dict[str, Any], ...] = ()
    plan_json: str | None = None
    error: str = ""
    log_tail: str = ""
    exit_status: int | None = None
    cores: tuple[int, ...] = ()
    started_at: str = ""
    finished_at: str = ""
    environment: dict[str, Any] = field(default_factory=dict)
    #: What the case itself reported (its own timings): information only, never stored or trusted.
    detail: dict[str, Any] = field(default_factory=dict, compare=False)
    #: A closed-loop run's planner calls: (actions executed, harness-measured compute seconds)
    #: each, in order (0 actions: the call that said done or was cut short); None when open loop.
    steps: tuple[tuple[int, float], ...] | None = None
    #: The fences the case ran in (docs/isolation.md): ``namespaces+cgroup-v1`` …, or ``none``.
    isolation: str = "none"
    #: The most processes the case held at once, from its cgroup (None without one).
    processes: int | None = None
    #: The machine's load around the case (:func:`earthbench.running.harness.load.around`): ``load_before``,
    #: ``load_after``, ``steal_share``; empty where it was not measured (e.g. a merged run of an older store).
    machine_load: dict[str, Any] = field(default_factory=dict)
    #: The wall and CPU seconds of the planner's preparation this case used (None: it has none);
    #: the harness's measurements of that job, never part of the solve time.
    prepare_s: float | None = None
    prepare_cpu_s: float | None = None
    #: The version of the referee's rules that judged the plan; None: this earthbench's
    #: (:data:`earthbench.referee.RULES_VERSION`), the store writes it.
    rules: int | None = None

    @classmethod
    def failure(cls, case: Case, reason: str, error: str) -> CaseResult:
        """The result of a case that failed outside its process (its executor, its worker)."""
        now = utc_now()
        return cls(key=case.key, scenario_id=case.scenario.id, reason=reason, error=error, started_at=now, finished_at=now)

    @property
    def success(self) -> bool:
        return bool(self.metrics and self.metrics.get("success"))


@dataclass(frozen=True)
class SpotCheck:
    """One planner's sample, rerun here: do its referee figures agree, how do its solve times compare?"""

    planner: str
    version: str
    config_hash: str
    run_ids: tuple[int, ...]
    agree: int
    ratios: tuple[float, ...]          #: solve time here / stored solve time, per run with both
    disagreements: tuple[str, ...]
    machine: str                        #: where the sample was rerun
    stored_machines: tuple[str, ...]    #: where the stored runs had run
    checked_at: str
    cpu_ratios: tuple[float, ...] = ()  #: CPU time here / stored CPU time, per run with both
    load_stored: tuple[float, ...] = ()  #: the 1-minute load averages recorded around the stored runs
    load_here: tuple[float, ...] = ()    #: and around their reruns
    steal: float | None = None           #: the largest CPU steal share of the reruns

    @property
    def n(self) -> int:
        return len(self.run_ids)

    @property
    def ratio_median(self) -> float | None:
        return statistics.median(self.ratios) if self.ratios else None

    def line(self) -> str:
        """One line: agreement, the re-timings as ratios (wall and CPU), and the load both were measured under."""
        def ratios(name: str, r: tuple[float, ...]) -> str:
            return f"{name} here / stored: median {statistics.median(r):.2f} ({min(r):.2f}–{max(r):.2f})" if r else ""

        def load(values: tuple[float, ...]) -> str:
            return f"{min(values):.2f}–{max(values):.2f}" if values else "not recorded"

        timing = "; ".join(t for t in (ratios("solve wall time", self.ratios), ratios("CPU time", self.cpu_ratios)) if t)
        context = (f" (load average {load(self.load_here)} here, {load(self.load_stored)} when stored"
                   + (f"; CPU steal up to {100 * self.steal:.1f} % here" if self.steal else "") + ")")
        return (f"{self.planner} {self.version}: {self.n} run(s) rerun on {self.machine} ({self.checked_at}); "
                f"referee figures agree {self.agree}/{self.n}; " + (timing + context if timing else "no solve times to compare"))
