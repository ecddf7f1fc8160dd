"""The harness: run each case in a fresh, fenced subprocess and report what happened.

A *case* is (planner with its configuration, scenario). :func:`run_case` is the unit of work:
a pure function of a picklable :class:`Case` (and the CPU cores of its slot) returning a
picklable :class:`CaseResult`, so any executor can ship it: :class:`LocalExecutor` runs slots
on this machine; a distributed executor only has to call the same function on a worker and
stream the results back to the client, which alone writes the store.

What ``run_case`` enforces (DESIGN §5):

* a fresh interpreter per case, in its own session/process group, with CPU affinity set to
  the slot's cores and OMP/OpenBLAS/MKL/… thread caps set in its environment, so numpy's
  BLAS never sees more cores than the budget;
* ``RLIMIT_AS`` = the budget's memory, set before anything is imported; a ``MemoryError``,
  or death by a signal near the limit, is termination reason ``memory``;
* the wall budget, counted from the moment the child is about to construct the planner (so
  interpreter start-up and imports are not the planner's time, but are bounded by
  ``startup_s``); past it the whole process group and every descendant gets SIGTERM, then
  SIGKILL after a grace period;
* ``solve_time_s``/``solve_cpu_s`` measured around the planner call by the child (also when
  the planner raises) or, on a timeout, by the harness;
* the referee runs here, in the harness process, never inside the planner's process.

Termination reasons: ``ok`` (a valid plan), ``invalid`` (the referee found violations),
``timeout``, ``memory``, ``error`` (with the traceback), ``crashed`` (killed by a signal or
exited without a result).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import importlib.util
import json
import os
import platform
import queue
import selectors
import shutil
import signal
import site
import socket
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Iterable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, field
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import psutil

from .errors import PluginError
from .planner import Planner
from .registry import PLANNERS
from .world import Scenario

if TYPE_CHECKING:  # pragma: no cover
    from .progress import Progress
    from .store import Store
    from .suite import Suite

REASONS = ("ok", "invalid", "timeout", "memory", "error", "crashed")
#: Seconds a case may spend starting (interpreter, imports, reading the scenario) before the planner call.
STARTUP_S = 60.0
#: Seconds between SIGTERM and SIGKILL when a case is ended.
TERM_GRACE_S = 2.0
#: Seconds a child may take to exit after it has sent its result.
EXIT_GRACE_S = 5.0
#: Fraction of the memory budget above which a death by signal counts as ``memory``.
MEMORY_KILL_FRACTION = 0.9
#: Bytes of the case's stdout/stderr kept with the result.
LOG_TAIL = 4000
THREAD_VARS = (
    "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS", "NUMBA_NUM_THREADS",
)


# -- what is run ---------------------------------------------------------------------------------


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

    @classmethod
    def resolve(cls, name: str, overrides: dict[str, Any] | None = None) -> PlannerRef:
        """Look ``name`` up in the registry and check ``overrides`` against its ``Config``."""
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
        )


def _source_of(klass: type) -> str:
    mod = sys.modules.get(klass.__module__)
    file = getattr(mod, "__file__", None)
    if "<locals>" in klass.__qualname__:
        raise PluginError(f"planner class {klass.__qualname__} is defined inside a function; define it at module level so a case process can import it")
    if klass.__module__ == "__main__" or klass.__module__.startswith("earthbench_plugin_"):
        if not file:
            raise PluginError(f"planner {klass.name!r} is defined interactively; put it in a file and pass --plugin FILE.py")
        return str(Path(file).resolve())
    return f"{klass.__module__}:{klass.__qualname__}"


@dataclass(frozen=True)
class Case:
    """One (planner configuration, scenario) pair of a suite; ``key`` identifies its result."""

    suite: str
    suite_digest: str
    threshold: float
    scenario: Scenario
    planner: PlannerRef
    plugins: tuple[str, ...] = ()

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

    @property
    def success(self) -> bool:
        return bool(self.metrics and self.metrics.get("success"))


# -- one case ------------------------------------------------------------------------------------


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def _child_env(cores: int) -> dict[str, str]:
    env = dict(os.environ)
    for var in THREAD_VARS:
        env[var] = str(cores)
    # the child sees the modules the harness sees (test modules, plugins added to sys.path), but
    # the interpreter's own directories stay where its start-up puts them, after the stdlib
    own = {os.path.realpath(d) for d in (*site.getsitepackages(), site.getusersitepackages())}
    prefixes = tuple(os.path.realpath(p) + os.sep for p in {sys.prefix, sys.base_prefix, sys.exec_prefix})
    paths = [
        p for p in sys.path
        if p and os.path.isdir(p) and os.path.realpath(p) not in own and not (os.path.realpath(p) + os.sep).startswith(prefixes)
    ]
    if env.get("PYTHONPATH"):
        paths.append(env["PYTHONPATH"])
    env["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(paths))
    env["PYTHONUNBUFFERED"] = "1"
    return env


def _kill_tree(pid: int, grace: float = TERM_GRACE_S, *, reap: bool = True) -> tuple[int, Any] | None:
    """SIGTERM the case's process group and every descendant, then SIGKILL what is left.

    Descendants that left the group (``setsid``) are found through psutil. With ``reap`` the
    case process itself is waited for here and its ``(status, rusage)`` returned.
    """
    try:
        kids = psutil.Process(pid).children(recursive=True)
    except psutil.Error:
        kids = []
    reaped = None
    for sig in (signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(pid, sig)
        except (ProcessLookupError, PermissionError):
            pass
        for p in kids:
            try:
                p.send_signal(sig)
            except psutil.Error:
                pass
        end = time.monotonic() + (grace if sig == signal.SIGTERM else 5.0)
        while time.monotonic() < end:
            if reap and reaped is None:
                try:
                    got, status, ru = os.wait4(pid, os.WNOHANG)
                    if got:
                        reaped = (status, ru)
                except ChildProcessError:
                    reaped = (0, None)
            kids = [p for p in kids if _running(p)]
            if (reaped is not None or not reap) and not kids and not _group_alive(pid):
                return reaped
            time.sleep(0.02)
    if reap and reaped is None:
        _, status, ru = os.wait4(pid, 0)
        reaped = (status, ru)
    return reaped


def _running(p: psutil.Process) -> bool:
    try:
        return p.is_running() and p.status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
        return True
    except (ProcessLookupError, PermissionError):
        return False


def run_case(
    case: Case,
    cores: Sequence[int] | None = None,
    *,
    stop: threading.Event | None = None,
    startup_s: float = STARTUP_S,
) -> CaseResult:
    """Run one case in a fresh subprocess on ``cores``.

    Without ``cores`` the case waits for a free slot of a process-wide :class:`SlotPool`, so
    concurrent calls in one process (threads of a distributed worker) never share cores.

    Never raises for anything the planner does. ``stop`` (set by an executor on Ctrl-C) ends
    the case early; the result then has reason ``"cancelled"`` and must not be stored.
    """
    budget = case.scenario.budget
    if cores is None:  # e.g. on a distributed worker: take a free slot of this process's pool
        with SlotPool.shared(budget.cores).slot() as slot:
            return run_case(case, slot, stop=stop, startup_s=startup_s)
    cores = tuple(cores)
    started_at = _now()
    tmp = tempfile.mkdtemp(prefix="earthbench-case-")
    try:
        case_file = os.path.join(tmp, "case.json")
        with open(case_file, "w") as f:
            json.dump(
                {
                    "name": case.planner.name,
                    "source": case.planner.source,
                    "overrides": case.planner.overrides,
                    "plugins": list(case.plugins),
                    "scenario": case.scenario.to_dict(),
                },
                f,
            )
        log = open(os.path.join(tmp, "log.txt"), "wb")
        r, w = os.pipe()
        mem = int(budget.memory_mb) * 1024 * 1024
        t_spawn = time.monotonic()
        try:
            proc = subprocess.Popen(
                [sys.executable, "-c", _bootstrap(), case_file, str(w), ",".join(map(str, cores)), str(mem), str(os.getpid())],
                stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT, pass_fds=(w,),
                cwd=tmp, env=_child_env(len(cores)), start_new_session=True,
            )
        except BaseException:
            os.close(r)
            raise
        finally:
            os.close(w)
            log.close()
        out = _supervise(proc, r, t_spawn, budget.wall_s, startup_s, stop)
        with open(os.path.join(tmp, "log.txt"), "rb") as f:
            f.seek(0, os.SEEK_END)
            f.seek(max(0, f.tell() - LOG_TAIL))
            log_tail = f.read().decode(errors="replace")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return _result(case, out, cores, started_at, log_tail)


@dataclass
class _Outcome:
    started: dict[str, Any] | None = None
    done: dict[str, Any] | None = None
    timed_out: bool = False
    cancelled: bool = False
    status: int | None = None
    maxrss_mb: float | None = None
    peak_vms_mb: float = 0.0
    elapsed: float | None = None
    cpu: float | None = None
    t_spawn: float = 0.0
    startup_s: float = STARTUP_S


def _supervise(proc: subprocess.Popen, r: int, t_spawn: float, wall_s: float, startup_s: float, stop: threading.Event | None) -> _Outcome:
    """Read the child's messages until it exits, enforcing start-up, wall and exit deadlines."""
    o = _Outcome(t_spawn=t_spawn, startup_s=startup_s)
    sel = selectors.DefaultSelector()
    sel.register(r, selectors.EVENT_READ)
    os.set_blocking(r, False)
    buf = b""
    deadline = t_spawn + startup_s
    eof = False
    ps = None
    try:
        ps = psutil.Process(proc.pid)
    except psutil.Error:
        pass
    try:
        while True:
            now = time.monotonic()
            if stop is not None and stop.is_set():
                o.cancelled = True
                break
            if now >= deadline:
                o.timed_out = o.done is None
                break
            if ps is not None:  # address space, the quantity RLIMIT_AS caps, sampled as we wait
                try:
                    o.peak_vms_mb = max(o.peak_vms_mb, ps.memory_info().vms / 2**20)
                except psutil.Error:
                    pass
            if not eof:
                for _ in sel.select(timeout=min(deadline - now, 0.25)):
                    try:
                        chunk = os.read(r, 1 << 20)
                    except BlockingIOError:
                        continue
                    if not chunk:
                        eof = True
                        break
                    buf += chunk
                    while b"\n" in buf:
                        line, buf = buf.split(b"\n", 1)
                        msg = _message(line)
                        if msg.get("event") == "started":
                            o.started = msg
                            deadline = msg["t"] + wall_s
                        elif msg.get("event") == "done":
                            o.done = msg
                            deadline = time.monotonic() + EXIT_GRACE_S
            else:
                time.sleep(0.005)
            pid, status, ru = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                o.status = os.waitstatus_to_exitcode(status)
                proc.returncode = o.status
                o.maxrss_mb = ru.ru_maxrss / 1024.0
                # collect what is still in the pipe (unless a descendant keeps it open)
                while not eof and sel.select(timeout=0.05):
                    try:
                        chunk = os.read(r, 1 << 20)
                    except BlockingIOError:
                        break
                    if not chunk:
                        break
                    buf += chunk
                for line in buf.split(b"\n"):
                    if line.strip():
                        msg = _message(line)
                        if msg.get("event") == "done":
                            o.done = msg
                        elif msg.get("event") == "started":
                            o.started = msg
                break
        if o.status is None:  # still running: past a deadline, or cancelled
            if o.started and o.done is None and ps is not None:
                try:
                    t = ps.cpu_times()
                    o.cpu = t.user + t.system + t.children_user + t.children_system - o.started["cpu"]
                except psutil.Error:
                    pass
            o.elapsed = time.monotonic() - o.started["t"] if o.started else None
            status, ru = _kill_tree(proc.pid)
            o.status = os.waitstatus_to_exitcode(status)
            proc.returncode = o.status
            o.maxrss_mb = ru.ru_maxrss / 1024.0 if ru is not None else None
        elif _group_alive(proc.pid):  # the planner left processes behind
            _kill_tree(proc.pid, grace=0.2, reap=False)
    finally:
        sel.close()
        os.close(r)
    return o


_MEMORY_WORDS = ("std::bad_alloc", "MemoryError", "Cannot allocate memory", "out of memory", "Unable to allocate")


def _mentions_memory(text: str) -> bool:
    """An allocation failure inside a C/C++ extension shows up only as text (or an abort)."""
    tail = text[-2000:]
    return any(w in tail for w in _MEMORY_WORDS)


def _message(line: bytes) -> dict[str, Any]:
    try:
        msg = json.loads(line)
    except ValueError:
        return {}
    return msg if isinstance(msg, dict) else {}


def _result(case: Case, o: _Outcome, cores: tuple[int, ...], started_at: str, log_tail: str) -> CaseResult:
    budget = case.scenario.budget
    common = dict(
        key=case.key, scenario_id=case.scenario.id, cores=cores, started_at=started_at, finished_at=_now(),
        log_tail=log_tail, exit_status=o.status, peak_rss_mb=o.maxrss_mb,
        startup_s=(o.started["t"] - o.t_spawn) if o.started else None,
        environment=environment(case.planner.source),
    )
    if o.cancelled and o.done is None:
        return CaseResult(reason="cancelled", error="the run was interrupted", **common)
    if o.done is None:
        if o.timed_out:
            if o.started:
                msg = f"the planner ran past its wall budget of {budget.wall_s:g} s and was ended"
            else:
                msg = f"the case did not reach the planner call within {o.startup_s:g} s of start-up"
            return CaseResult(reason="timeout", solve_time_s=o.elapsed, solve_cpu_s=o.cpu, error=msg, **common)
        st = o.status
        how = f"killed by {signal.Signals(-st).name}" if st is not None and st < 0 else f"exited with status {st}"
        near = MEMORY_KILL_FRACTION * budget.memory_mb
        if (o.maxrss_mb or 0) >= near or o.peak_vms_mb >= near or _mentions_memory(log_tail):
            return CaseResult(reason="memory", error=f"the case process {how} near its memory budget of {budget.memory_mb} MB "
                              f"(peak {o.maxrss_mb or 0:.0f} MB resident, {o.peak_vms_mb:.0f} MB address space seen)", **common)
        return CaseResult(reason="crashed", error=f"the case process {how} without a result", **common)
    d = o.done
    times = dict(solve_time_s=d.get("solve_time_s"), solve_cpu_s=d.get("solve_cpu_s"))
    if d["outcome"] in ("error", "memory"):
        reason = "memory" if d["outcome"] == "memory" or _mentions_memory(d.get("error", "")) else "error"
        return CaseResult(reason=reason, error=d.get("error", ""), **times, **common)
    plan_json = d["plan"]
    from .scoring import score  # the one scoring rule (imported here: the case's child never needs it)

    try:
        verdict, metrics = score(case.scenario, plan_json, case.threshold)
    except Exception:  # noqa: BLE001 - a referee bug must not lose the plan; `earthbench rescore` can retry
        return CaseResult(reason="error", error="the referee failed on this plan:\n" + traceback.format_exc(), plan_json=plan_json, **times, **common)
    metrics.update(times)
    return CaseResult(
        reason="ok" if verdict.valid else "invalid", metrics=metrics,
        violations=tuple(v.to_dict() for v in verdict.violations), plan_json=plan_json, **times, **common,
    )


@functools.lru_cache(maxsize=1)
def _bootstrap() -> str:
    from . import _child

    return _child.BOOTSTRAP


# -- environment stamp ---------------------------------------------------------------------------


@functools.lru_cache(maxsize=64)
def _git_commit(directory: str) -> str | None:
    try:
        head = subprocess.run(["git", "-C", directory, "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5)
        if head.returncode != 0:
            return None
        dirty = subprocess.run(
            ["git", "-C", directory, "status", "--porcelain", "--untracked-files=no", "--", "."],
            capture_output=True, text=True, timeout=10,
        )
        return head.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return None


@functools.lru_cache(maxsize=1)
def _machine() -> dict[str, Any]:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    packages = {}
    for dist in ("earthbench", "numpy", "scipy", "shapely", "pandas", "casadi", "cvxpy", "psutil"):
        try:
            packages[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            pass
    commit = _git_commit(str(Path(__file__).resolve().parent))
    if commit is None:  # installed with `pip install .`: the checkout it came from, if pip recorded it
        try:
            url = json.loads(metadata.distribution("earthbench").read_text("direct_url.json") or "{}").get("url", "")
            if url.startswith("file://"):
                commit = _git_commit(url[len("file://"):])
        except (metadata.PackageNotFoundError, ValueError):
            pass
    return {
        "hostname": socket.gethostname(),
        "cpu_model": cpu,
        "cores": os.cpu_count(),
        "os": platform.platform(),
        "python": platform.python_version(),
        "packages": packages,
        "project_commit": commit,
    }


@functools.lru_cache(maxsize=64)
def environment(planner_source: str = "") -> dict[str, Any]:
    """Machine, software and commits of where a case ran (computed there, cached per process)."""
    env = dict(_machine())
    env["packages"] = dict(env["packages"])
    where: str | None = None
    if planner_source.endswith(".py"):
        where = planner_source
    elif ":" in planner_source:
        module = planner_source.split(":", 1)[0]
        try:
            spec = importlib.util.find_spec(module)
            where = spec.origin if spec else None
        except (ImportError, ValueError):
            where = None
        top = module.split(".", 1)[0]
        for dist in metadata.packages_distributions().get(top, []):
            try:
                env["packages"][dist] = metadata.version(dist)
            except metadata.PackageNotFoundError:
                pass
    env["plugin_commit"] = _git_commit(str(Path(where).resolve().parent)) if where else None
    return env


# -- executors -----------------------------------------------------------------------------------


class Executor(Protocol):
    """Runs cases and yields their results as they finish (in any order).

    An executor may run ``run_case`` anywhere; it must not write the store. ``cancel`` ends
    the cases in flight (their results are dropped) and is safe to call from a signal path.
    """

    def run(self, cases: Sequence[Case]) -> Iterator[CaseResult]: ...

    def cancel(self) -> None: ...


def make_slots(cores_per_case: int, jobs: int | None = None, allowed: Iterable[int] | None = None) -> list[tuple[int, ...]]:
    """Disjoint groups of ``cores_per_case`` cores: floor(N / cores) slots, at most ``jobs``.

    With fewer cores than a case asks for, one slot gets all of them.
    """
    if allowed is None:
        allowed = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else range(os.cpu_count() or 1)
    cpus = sorted(allowed)
    n = max(1, len(cpus) // max(1, cores_per_case))
    if jobs is not None:
        n = max(1, min(n, jobs))
    if len(cpus) < cores_per_case:
        return [tuple(cpus)]
    return [tuple(cpus[i * cores_per_case : (i + 1) * cores_per_case]) for i in range(n)]


class SlotPool:
    """Disjoint core slots handed out to concurrent cases of one process."""

    _shared: dict[int, SlotPool] = {}
    _lock = threading.Lock()

    def __init__(self, slots: Sequence[tuple[int, ...]]):
        self.slots = list(slots)
        self._free: queue.Queue[tuple[int, ...]] = queue.Queue()
        for s in self.slots:
            self._free.put(s)

    @classmethod
    def shared(cls, cores_per_case: int) -> SlotPool:
        with cls._lock:
            if cores_per_case not in cls._shared:
                cls._shared[cores_per_case] = cls(make_slots(cores_per_case))
            return cls._shared[cores_per_case]

    @contextlib.contextmanager
    def slot(self) -> Iterator[tuple[int, ...]]:
        s = self._free.get()
        try:
            yield s
        finally:
            self._free.put(s)


class LocalExecutor:
    """Runs cases on this machine, one per slot, each slot a thread supervising one subprocess."""

    def __init__(self, jobs: int | None = None, cores_per_case: int = 2, *, startup_s: float = STARTUP_S):
        self.slots = make_slots(cores_per_case, jobs)
        self.startup_s = startup_s
        self._stop = threading.Event()

    def run(self, cases: Sequence[Case]) -> Iterator[CaseResult]:
        self._stop.clear()
        slots = SlotPool(self.slots)

        def task(case: Case) -> CaseResult:
            with slots.slot() as slot:
                return run_case(case, slot, stop=self._stop, startup_s=self.startup_s)

        pool = ThreadPoolExecutor(max_workers=len(self.slots), thread_name_prefix="earthbench-slot")
        pending: set[Future[CaseResult]] = set()
        it = iter(cases)
        try:
            # keep only as many cases in flight as there are slots, so a cancel never has a backlog
            for case in it:
                pending.add(pool.submit(task, case))
                if len(pending) >= len(self.slots):
                    break
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                for fut in done:
                    res = fut.result()
                    nxt = next(it, None)
                    if nxt is not None and not self._stop.is_set():
                        pending.add(pool.submit(task, nxt))
                    if res.reason != "cancelled":
                        yield res
        finally:
            self._stop.set()
            pool.shutdown(wait=True, cancel_futures=True)

    def cancel(self) -> None:
        self._stop.set()


def result_to_json(res: CaseResult) -> dict[str, Any]:
    """A plain-JSON form of a result (for logs and for executors that cannot pickle)."""
    return dataclasses.asdict(res)


# -- a suite run ---------------------------------------------------------------------------------


@dataclass
class RunReport:
    """What one ``run_cases`` call did; ``interrupted`` is set when Ctrl-C ended it."""

    planned: int = 0
    skipped: int = 0
    stored: int = 0
    counts: dict[str, int] = field(default_factory=dict)
    interrupted: bool = False


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
    names = list(planners or suite.planners or [n for n, c in PLANNERS.items() if suite.track in c.tracks])
    if not names:
        notes.append(f"no registered planner supports the {suite.track!r} track")
    refs = []
    for name in dict.fromkeys(names):
        ref = PlannerRef.resolve(name, suite.config.get(name))
        if suite.track not in ref.tracks:
            if explicit:
                notes.append(f"planner {name!r} supports {', '.join(ref.tracks)}, not this suite's {suite.track!r} track: skipped")
            continue
        refs.append(ref)
    for name in suite.config:
        if name not in PLANNERS:
            notes.append(f"the suite configures planner {name!r}, which is not registered: its [config.{name}] is unused")
    plugin_paths = tuple(str(Path(p).resolve()) for p in plugins)
    cases = [
        Case(suite.name, suite.digest, suite.success_threshold, sc, ref, plugin_paths)
        for sc in suite.select(seeds)
        for ref in refs
    ]
    return cases, notes


def run_cases(
    cases: Sequence[Case],
    store: Store,
    executor: Executor,
    *,
    rerun: bool = False,
    progress: Progress | None = None,
) -> RunReport:
    """Run every case not yet in ``store`` (all with ``rerun``) and store each as it finishes.

    Only this function writes the store, one transaction per case, so an executor may run
    cases anywhere. Ctrl-C (KeyboardInterrupt) cancels the cases in flight (nothing of them is
    written), keeps every finished one and returns the report marked ``interrupted``.
    """
    report = RunReport(planned=len(cases))
    done = set() if rerun else store.finished_keys()
    by_key: dict[tuple[str, str, str, str], Case] = {}
    for c in cases:  # one case per key: a scenario listed twice is run once
        if c.key not in done:
            by_key.setdefault(c.key, c)
    todo = list(by_key.values())
    report.skipped = len(cases) - len(todo)
    if progress is not None:
        progress.total = len(todo)
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
    cases, _ = build_cases(suite, planners, plugins=plugins, seeds=seeds)
    store.register_suite(suite)
    return run_cases(cases, store, executor or LocalExecutor(cores_per_case=suite.budget.cores), rerun=rerun, progress=progress)
