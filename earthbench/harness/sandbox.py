"""The sandbox: run one case in a fresh, fenced process tree and report what happened.

A *case* is (planner with its configuration, scenario). :func:`run_case` is the unit of work:
a pure function of a picklable :class:`Case` (and the CPU cores of its slot) returning a
picklable :class:`CaseResult`, so any executor can ship it: the local executor runs slots on
this machine; a distributed executor calls the same function on a worker and streams the
results back to the client, which alone writes the store.

What ``run_case`` enforces (the trust model is in docs/running.md, "What a plugin can influence"):

* where the machine allows it, its own namespaces and cgroup (:mod:`.isolation`,
  docs/isolation.md): a read-only view of the Python environment and the planner's files, a
  private tmpfs, the memory budget for the whole tree, the slot's cores as a cpuset, and the
  CPU, peak memory and process count read from the cgroup; frozen between closed-loop steps;
* a fresh interpreter per case in its own session, under a warden process (see
  :mod:`.child`) that is a child subreaper, so every descendant of the case, in any session,
  ends with it; CPU affinity on the slot's cores and OMP/OpenBLAS/MKL/… thread caps, so numpy's
  BLAS never sees more cores than the budget;
* ``RLIMIT_AS`` = the budget's memory in the planner's process, set before anything is
  imported; a ``MemoryError``, or death by a signal near the limit (by the peak of the case's
  own process tree), is termination reason ``memory``;
* every time on this process's monotonic clock: start-up (bounded by ``startup_s``) runs
  until the case says it is ready; the wall budget and ``solve_time_s`` run from the moment
  this process hands the scenario over until the result has arrived; ``solve_cpu_s`` is the
  kernel's CPU accounting of the case's process tree over the same span (never negative);
* the specification and every input over the case's stdin, each input with a fresh nonce its
  reply must echo; every message validated: anything malformed, out of order, not echoing
  the nonce or larger than :data:`MAX_RESULT_BYTES` ends the case as ``error`` saying what
  was wrong; the CPU budget (``cpu_s``) over the planner's calls, when the suite sets one;
* the referee runs here, in the harness process, never inside the planner's process;
* the planner gets :func:`earthbench.sensing.observe` of the scenario (the scan and the
  soil's nominal class), computed here; the referee judges on the truth.

Termination reasons: ``ok`` (a valid plan), ``invalid`` (the referee found violations),
``timeout``, ``memory``, ``error`` (with the traceback or the protocol fault), ``crashed``
(killed by a signal or exited without a result).
"""

from __future__ import annotations

import dataclasses
import functools
import glob
import json
import os
import queue
import secrets
import selectors
import shutil
import signal
import site
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import psutil

from . import isolation
from ..errors import EarthbenchError
from ..world import Budget
from ..records import Case, CaseResult, utc_now
from .cases import Prepared
from .child import BOOTSTRAP
from . import load
from .environment import environment
from ..scoring import score  # the one scoring rule, in the core
from ..sensing import observe
from .slots import SlotPool
from .steps import StepLoop, step_metrics

#: Seconds a case may spend starting (interpreter, imports of the planner's code) before it is ready.
STARTUP_S = 60.0
#: Seconds the warden gets to end the case tree after SIGTERM before the harness kills it all.
TERM_GRACE_S = 2.0
#: Seconds a case may take to exit after it has sent its result.
EXIT_GRACE_S = 5.0
#: Fraction of the memory budget above which a death by signal counts as ``memory``.
MEMORY_KILL_FRACTION = 0.9
#: Bytes of the case's stdout/stderr kept with the result.
LOG_TAIL = 4000
#: Bytes a case may write to its stdout and stderr in all: past them it ends as ``error`` (the
#: harness reads them from a pipe and keeps only :data:`LOG_TAIL`; nothing goes to a disk).
LOG_LIMIT = 64 * 2**20
#: The plan-size rule: the largest message (in practice, a plan's JSON) a case may send. A plan
#: of about 350,000 actions fits; a larger one is refused as ``error`` with its own message, so
#: a case can neither exhaust the harness's memory nor hold it parsing for minutes.
MAX_RESULT_BYTES = 64 * 2**20
#: Seconds between samples of the case tree's memory while it runs.
SAMPLE_S = 0.25
#: Seconds between samples of the whole tree (descendants of the planner too).
TREE_SAMPLE_S = 1.0
#: The environment variable that tags every process of a case (for the last-resort sweep).
CASE_TAG = "EARTHBENCH_CASE"
THREAD_VARS = (
    "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS", "NUMBA_NUM_THREADS",
)
#: Variables of the harness's environment a case (and a preparation) is given, with the
#: locale's ``LC_*``: what an interpreter and a compiler need. Nothing else of the harness's
#: environment reaches a case (its tokens, ``HOME``, its working folders, where the store is;
#: docs/isolation.md "What leaks into a case"); a planner that needs a setting of its own is
#: given it by name in :data:`CASE_ENV`. Allocator settings stay out too: a Dask nanny gives
#: its worker ``MALLOC_TRIM_THRESHOLD_=65536``, which made greedy's 96 × 48 m plan fault 25x as
#: many pages; a planner's speed must not depend on the executor that started it.
PASSED_VARS = ("PATH", "LANG", "LANGUAGE", "TZ", "LD_LIBRARY_PATH", "PYTHONHASHSEED", "PYTHONDONTWRITEBYTECODE",
               "CC", "CXX")
#: ``EARTHBENCH_CASE_ENV=NAME,NAME``: more variables of the harness's environment to give every
#: case and preparation, for a planner's own settings (the operator chooses; never the store's).
CASE_ENV = "EARTHBENCH_CASE_ENV"
#: Variables never given to a case, whatever :data:`CASE_ENV` says: where the results store is
#: (it holds the truth of every scenario, sealed ones too; docs/sealed-evaluation.md).
HIDDEN_VARS = ("EARTHBENCH_DB",)
_DIR_PREFIX = "earthbench-case-"
#: This harness's case tags start so (random: a tag does not tell a case the harness's pid).
TAG_PREFIX = f"{_DIR_PREFIX}{secrets.token_hex(6)}-"


class HarnessError(EarthbenchError):
    """This machine cannot run a case at all (e.g. the temp directory is full): the run stops."""


def _child_env(cores: int, tag: str, home: str) -> dict[str, str]:
    """The allow-listed environment of a case: :data:`PASSED_VARS`, the operator's
    :data:`CASE_ENV`, the thread caps, the module path and ``HOME`` (the case's own folder)."""
    chosen = {n.strip() for n in os.environ.get(CASE_ENV, "").split(",") if n.strip()} - set(HIDDEN_VARS)
    env = {k: v for k, v in os.environ.items() if k in PASSED_VARS or k.startswith("LC_") or k in chosen}
    env[CASE_TAG] = tag
    env["HOME"] = home
    cache = isolation.nlp_cache_setting()
    if cache:  # where the planner finds the built NLPs, resolved here (the case has no HOME of the user's)
        env[isolation.NLP_CACHE_ENV] = cache
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
    if os.environ.get("PYTHONPATH"):
        paths.append(os.environ["PYTHONPATH"])
    env["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(paths))
    env["PYTHONUNBUFFERED"] = "1"
    return env


def _case_dir() -> str:
    """A fresh case folder, named by this process's pid so a later harness can clear it if we die."""
    _clear_stale_case_dirs()
    try:
        return tempfile.mkdtemp(prefix=f"{_DIR_PREFIX}{os.getpid()}-")
    except OSError as exc:
        raise HarnessError(f"cannot create a case folder in {tempfile.gettempdir()}: {exc.strerror}; "
                           "free space there or point TMPDIR elsewhere") from None


@functools.lru_cache(maxsize=1)
def _clear_stale_case_dirs() -> None:
    """Once per process: remove case folders left by a harness (or Dask worker) that was killed."""
    for path in glob.glob(os.path.join(tempfile.gettempdir(), _DIR_PREFIX + "*-*")):
        pid = os.path.basename(path)[len(_DIR_PREFIX):].split("-", 1)[0]
        if pid.isdigit() and int(pid) != os.getpid() and not psutil.pid_exists(int(pid)):
            shutil.rmtree(path, ignore_errors=True)


def run_case(
    case: Case,
    cores: Sequence[int] | None = None,
    *,
    stop: threading.Event | None = None,
    startup_s: float = STARTUP_S,
    prepared: Prepared | None = None,
) -> CaseResult:
    """Run one case in a fresh process tree on ``cores``; ``prepared``: the planner's preparation
    on this machine, whose folder the case is told (and may read, read only) and whose times go
    with its result (the executors find or run it first: :func:`.prepare.run_prepared_case`).

    Without ``cores`` the case waits for a free slot of a process-wide :class:`SlotPool`, so
    concurrent calls in one process (threads of a distributed worker) never share cores.

    Never raises for anything the planner does; raises :class:`HarnessError` when this
    machine cannot run a case (no space for the case folder). ``stop`` (set by an executor on
    Ctrl-C) ends the case early; the result then has reason ``"cancelled"`` and must not be
    stored.
    """
    budget = case.scenario.budget
    if cores is None:  # e.g. on a distributed worker: take a free slot of this process's pool
        with SlotPool.shared(budget.cores).slot() as slot:
            return run_case(case, slot, stop=stop, startup_s=startup_s, prepared=prepared)
    cores = tuple(cores)
    started_at = utc_now()
    load_before = load.snapshot()
    spec = {"name": case.planner.name, "source": case.planner.source, "overrides": case.planner.overrides,
            "prepared": prepared.path if prepared is not None else None}
    scenario = json.dumps(observe(case.scenario).to_dict()).encode() + b"\n"  # the planner's view; the referee keeps the truth
    loop = (
        StepLoop(case.scenario, max_steps=budget.max_steps, max_bytes=MAX_RESULT_BYTES)
        if case.planner.config.get("closed_loop")
        else None
    )
    visible = isolation.visible_paths(case.planner.source) + ((prepared.path,) if prepared is not None else ())
    out, log_tail, label = _run_fenced(spec, scenario, cores, budget, what="a case", visible=visible, loop=loop,
                                       stop=stop, startup_s=startup_s)
    out.isolation = label
    res = _result(case, out, cores, started_at, log_tail, load.around(load_before, load.snapshot()))
    if prepared is not None:
        res = dataclasses.replace(res, prepare_s=prepared.wall_s, prepare_cpu_s=prepared.cpu_s)
    return res


# -- a job that is not a case: a planner's preparation (.prepare) ----------------------------------
# The same fences (namespaces, cgroup), warden, limits and supervision as a case; what differs is
# the specification ("job": "prepare"), the one input it is given (the output folder and the
# number of cores: no scenario), its one result ("prepared"), and that its output folder is the
# one path it may write besides its private /tmp.


@dataclass(frozen=True)
class JobOutcome:
    """What the supervisor measured of a non-case job: its result message (None: none came),
    why it ended otherwise, and the wall and CPU seconds from hand-over to result."""

    done: dict[str, Any] | None
    fault: str
    timed_out: bool
    cancelled: bool
    status: int | None
    wall_s: float | None
    cpu_s: float | None
    peak_rss_mb: float | None
    log_tail: str
    isolation: str = "none"


def run_job(job: dict[str, Any], payload: bytes, cores: Sequence[int], budget: Budget, *, writable: str | None,
            stop: threading.Event | None = None, startup_s: float = STARTUP_S, visible: Sequence[str] | None = None,
            what: str = "a preparation", watch: Callable[[], str] | None = None) -> JobOutcome:
    """Run a non-case job (``job`` is its specification, with ``"job"`` naming it) in a fresh,
    fenced process tree on ``cores`` under ``budget``, giving it ``payload`` as its one input once
    it is ready; ``writable`` is the folder it may write (None: none); ``watch`` (called every
    second while it runs) says why to end it, e.g. its folder is over its disk budget. The jobs:
    ``prepare`` (:mod:`.prepare`) and ``probe`` (:mod:`.probe`, whose one result is ``probed``)."""
    if visible is None:
        visible = isolation.visible_paths(str(job.get("source", "")))
    o, tail, label = _run_fenced(job, payload, tuple(cores), budget, what=what, visible=visible,
                                 writable=(writable,) if writable else (), prepare=job.get("job") or False,
                                 stop=stop, startup_s=startup_s, watch=watch)
    return JobOutcome(o.done, o.fault, o.timed_out, o.cancelled, o.status, o.solve_time_s, o.solve_cpu_s, o.maxrss_mb,
                      tail, label)


def _run_fenced(spec: dict[str, Any], payload: bytes, cores: tuple[int, ...], budget: Budget, *, what: str,
                visible: Sequence[str], writable: Sequence[str] = (), loop: StepLoop | None = None, prepare: bool | str = False,
                stop: threading.Event | None = None, startup_s: float = STARTUP_S,
                watch: Callable[[], str] | None = None) -> tuple[_Outcome, str, str]:
    """One process tree of the bootstrap in the fences (namespaces, cgroup) on ``cores`` under
    ``budget``, supervised until it ends: ``spec`` is the first line of its input (a pipe; no file
    anyone else can reach), ``payload`` the one it is handed once ready (a case's observation, a
    preparation's job). Returns the outcome, the tail of its log and the fences it had; a case
    and a preparation differ only in these arguments (``what`` names it in errors); ``watch``,
    called every :data:`TREE_SAMPLE_S` while it runs, says why to end it ('' to go on)."""
    fences = isolation.support()
    _undumpable()
    tmp = _case_dir()  # the working folder of a case without namespaces; a sandboxed one never sees it
    try:
        mr, mw = os.pipe()
        rr, rw = os.pipe()
        lr, lw = os.pipe()  # its stdout and stderr: read here with a byte budget, never a file on disk
        mem = int(budget.memory_mb) * 1024 * 1024
        tag = TAG_PREFIX + secrets.token_hex(8)
        env = _child_env(len(cores), tag, "/tmp" if fences.bwrap else tmp)
        env["TMPDIR"] = "/tmp" if fences.bwrap else tempfile.gettempdir()
        fsize = budget.prepare_disk_mb * 2**20 if prepare else 0
        argv = [sys.executable, "-c", BOOTSTRAP, str(mw), str(rw), ",".join(map(str, cores)), str(mem),
                "0" if fences.bwrap else str(os.getpid()), str(fsize)]
        fence = isolation.Fence(
            argv, bwrap=fences.bwrap, cgroup=fences.cgroup, cores=cores, memory_bytes=mem, visible=visible, writable=writable,
            pass_fds=(mw, rw), env=env, stdin=subprocess.PIPE, stdout=lw, stderr=lw, cwd=tmp,
        )
        t_spawn = time.monotonic()
        try:
            try:
                proc = fence.start()
            except isolation.FenceError as exc:
                raise HarnessError(f"cannot start a sandbox for {what}: {exc}") from None
            finally:
                for fd in (mw, rw, lw):
                    os.close(fd)
            assert proc.stdin is not None
            try:
                proc.stdin.write(json.dumps(spec).encode() + b"\n")
                proc.stdin.flush()
            except OSError:
                pass
            sup = _Supervisor(proc, mr, rr, payload, tag, budget, startup_s, stop, t_spawn, loop, fence.cgroup, bool(fences.bwrap),
                              log_fd=lr)
            sup.prepare = prepare
            sup.watch = watch
            out = sup.run()
        finally:
            for fd in (mr, rr, lr):
                os.close(fd)
            fence.close()
        log_tail = bytes(sup.log).decode(errors="replace")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return out, log_tail, fence.label


@functools.lru_cache(maxsize=1)
def _undumpable() -> None:
    """Once per process: no case may read the harness's memory or descriptors through /proc."""
    isolation.make_undumpable()


@dataclass
class _Outcome:
    """What the supervisor saw; every time here is from the harness's monotonic clock."""

    t_spawn: float
    startup_s: float
    t_ready: float | None = None
    t_done: float | None = None
    t_end: float | None = None
    #: When the planner's current call began (the hand-over of the scenario or of an observation).
    t_given: float | None = None
    #: Harness-measured seconds of each finished planner call (one for an open-loop run).
    calls: list[float] = field(default_factory=list)
    #: Which limit the current deadline is: "wall" (the budget over all calls) or "step".
    limit: str = "wall"
    loop: StepLoop | None = None
    cpu_ready: float = 0.0
    done: dict[str, Any] | None = None
    fault: str = ""
    timed_out: bool = False
    cancelled: bool = False
    status: int | None = None
    report: dict[str, Any] | None = None
    peak_vms_mb: float = 0.0
    peak_rss_mb: float = 0.0
    #: The kernel's figures of the case's cgroup when it has one (None: per-process fences only).
    cgroup_cpu_s: float | None = None
    cgroup_peak_mb: float | None = None
    oom_kills: int = 0
    processes: int | None = None
    #: The case used more CPU seconds than its budget's ``cpu_s``.
    cpu_out: bool = False
    isolation: str = "none"

    @property
    def solve_time_s(self) -> float | None:
        """The planner's compute: every call from hand-over to reply (the call cut short by a deadline too)."""
        if self.t_ready is None:
            return None
        running = (self.t_end or self.t_given) - self.t_given if self.t_given is not None else 0.0
        return max(0.0, sum(self.calls) + running)

    def replied(self, now: float) -> float:
        """End the planner's current call at ``now``; returns its length."""
        took = now - (self.t_given if self.t_given is not None else now)
        self.calls.append(took)
        self.t_given = None
        return took

    @property
    def solve_cpu_s(self) -> float | None:
        if self.t_ready is None:
            return None
        if self.cgroup_cpu_s is not None:
            return max(0.0, self.cgroup_cpu_s - self.cpu_ready)
        if self.report is None:
            return None
        return max(0.0, float(self.report["cpu_s"]) - self.cpu_ready)  # tick-resolution sample vs µs accounting

    @property
    def maxrss_mb(self) -> float | None:
        if self.cgroup_peak_mb is not None:
            return self.cgroup_peak_mb
        if self.report is not None:
            return float(self.report["maxrss_kb"]) / 1024.0
        return self.peak_rss_mb or None


class _Supervisor:
    """Hands the scenario over, reads and validates the case's messages, enforces the deadlines."""

    def __init__(self, proc: subprocess.Popen, msg_fd: int, report_fd: int, scenario: bytes, tag: str,
                 budget: Budget, startup_s: float, stop: threading.Event | None, t_spawn: float, loop: StepLoop | None = None,
                 cgroup: isolation.CaseCgroup | None = None, sandboxed: bool = False, log_fd: int = -1):
        self.proc, self.msg_fd, self.report_fd, self.scenario, self.tag = proc, msg_fd, report_fd, scenario, tag
        self.prepare: bool | str = False  # a non-case job (run_job): its name, ``prepare`` or ``probe``
        self.watch: Callable[[], str] | None = None
        self.next_watch = t_spawn + TREE_SAMPLE_S
        self.log_fd, self.log, self.logged = log_fd, bytearray(), 0
        self.budget, self.stop = budget, stop
        self.o = _Outcome(t_spawn=t_spawn, startup_s=startup_s, loop=loop)
        self.outbox: queue.SimpleQueue[bytes | None] = queue.SimpleQueue()
        self.deadline = t_spawn + startup_s
        self.buf = bytearray()
        self.scanned = 0
        self.writer: threading.Thread | None = None
        self.next_sample = 0.0
        self.next_tree_sample = t_spawn + TREE_SAMPLE_S
        self.planner: psutil.Process | None = None
        self.report_buf = bytearray()
        self.cgroup = cgroup
        self.sandboxed = sandboxed
        self.next_cpu_check = 0.0
        #: The nonce of the input the case is answering (None: no answer is due).
        self.nonce: str | None = None
        try:
            self.warden: psutil.Process | None = psutil.Process(proc.pid)
        except psutil.Error:
            self.warden = None

    def run(self) -> _Outcome:
        o = self.o
        sel = selectors.DefaultSelector()
        sel.register(self.msg_fd, selectors.EVENT_READ)
        os.set_blocking(self.msg_fd, False)
        if self.log_fd >= 0:
            sel.register(self.log_fd, selectors.EVENT_READ)
            os.set_blocking(self.log_fd, False)
        eof = False
        try:
            while not o.fault:
                now = time.monotonic()
                if self.stop is not None and self.stop.is_set():
                    o.cancelled = True
                    break
                if now >= self.deadline:
                    o.timed_out = o.done is None
                    break
                if now >= self.next_sample:
                    self._sample(now)
                    self.next_sample = now + SAMPLE_S
                if self.watch is not None and now >= self.next_watch:
                    o.fault = self.watch()
                    self.next_watch = time.monotonic() + TREE_SAMPLE_S
                if o.fault or self._over_cpu():
                    break
                if sel.get_map():
                    eof = self._pump(sel, min(self.deadline - now, 0.005 if eof else 0.25)) or eof
                else:
                    time.sleep(0.005)
                if self._reaped():
                    while not eof and not o.fault:  # what is still in the pipe
                        got = self._pump(sel, 0.05, drain=True)
                        if got is None:
                            break
                        eof = got
                    break
        finally:
            sel.close()
            o.t_end = time.monotonic()
            if o.done is None:
                self._cpu_at_end()
            if o.status is None:  # still running: past a deadline, a fault, or cancelled
                self._end()
            self._read_report()
            if self.cgroup is not None:
                self.cgroup.kill()  # what the warden left (none, unless it was killed)
                o.cgroup_peak_mb = self.cgroup.peak_bytes() / 2**20
                o.oom_kills = self.cgroup.oom_kills()
                o.processes = self.cgroup.pids_peak
            if self.log_fd >= 0:
                self._read_log()  # what its processes wrote before they ended (they all have)
            if self.writer is not None:
                self.outbox.put(None)
                self.writer.join(timeout=1.0)
        return o

    def _pump(self, sel: selectors.BaseSelector, timeout: float, drain: bool = False) -> bool | None:
        """Wait up to ``timeout`` for the message pipe or the log; read what came. Returns whether
        the message pipe reached its end (None: nothing came while ``drain``ing the messages)."""
        events = sel.select(timeout=max(0.0, timeout))
        eof, got = False, False
        for key, _ in events:
            if key.fd == self.log_fd:
                if not self._read_log():
                    sel.unregister(self.log_fd)
            else:
                got = True
                eof = self._read()
                if eof:
                    sel.unregister(self.msg_fd)
        return None if drain and not got else eof

    def _read_log(self) -> bool:
        """Keep the last :data:`LOG_TAIL` bytes of what the case wrote to its stdout and stderr
        (nothing reaches a disk); past :data:`LOG_LIMIT` bytes it is a fault. False at its end."""
        while True:
            try:
                part = os.read(self.log_fd, 1 << 20)
            except BlockingIOError:
                return True
            except OSError:
                return False
            if not part:
                return False
            self.logged += len(part)
            self.log += part[-LOG_TAIL:]
            del self.log[:-LOG_TAIL]
            if self.logged > LOG_LIMIT and not self.o.fault:
                self.o.fault = (f"the case wrote more than {LOG_LIMIT // 2**20} MB to its stdout and stderr "
                                f"(only the last {LOG_TAIL:,} bytes are kept)")
                return True

    # -- messages ------------------------------------------------------------------------------
    def _read(self) -> bool:
        """Read what the pipe holds; scan only the new bytes for line ends (linear in the size).
        After the result nothing more may come: any byte is a protocol fault, read no further."""
        chunk, eof = bytearray(), False
        while len(chunk) < 1 << 24:  # drain what is there (up to 16 MB) before scanning it
            try:
                part = os.read(self.msg_fd, 1 << 20)
            except BlockingIOError:
                break
            if not part:
                eof = True
                break
            chunk += part
            if self.o.done is not None:
                break
        if self.o.done is not None and chunk and not self.o.fault:
            self.o.fault = f"the case wrote on its message pipe after its result: {bytes(chunk[:40])!r}"
            return eof
        self.buf += chunk
        start = 0
        while not self.o.fault:
            nl = self.buf.find(b"\n", self.scanned)
            if nl < 0:
                self.scanned = len(self.buf)
                if len(self.buf) - start > MAX_RESULT_BYTES:
                    self.o.fault = _too_large(len(self.buf) - start)
                break
            line = bytes(self.buf[start:nl])
            start = self.scanned = nl + 1
            if len(line) > MAX_RESULT_BYTES:
                self.o.fault = _too_large(len(line))
            elif not line.strip():
                self.o.fault = "the case sent an empty line on its message pipe (every message is one JSON object)"
            else:
                self._handle(line)
                if self.o.done is not None and len(self.buf) > start and not self.o.fault:
                    self.o.fault = f"the case wrote on its message pipe after its result: {bytes(self.buf[start:start + 40])!r}"
        del self.buf[:start]
        self.scanned = max(0, self.scanned - start)
        if eof and self.buf.strip() and not self.o.fault:
            self.o.fault = "the case's last message is not terminated by a newline"
        return eof

    def _handle(self, line: bytes) -> None:
        o = self.o
        try:
            msg = json.loads(line)
        except ValueError as exc:
            o.fault = f"the case sent a message that is not JSON ({exc})"
            return
        event = msg.get("event") if isinstance(msg, dict) else None
        if o.done is not None:
            o.fault = "the case sent a message after its result"
        elif event == "ready" and o.t_ready is None:
            self._hand_over()
        elif event == "ready":
            o.fault = "the case said 'ready' twice"
        elif event == "done":
            problem = _check_done(msg, o.t_ready is not None, o.loop is not None, self.prepare) or (
                self._unechoed(msg) if o.t_ready is not None else "")
            if problem:
                o.fault = problem
            else:
                self._finish(msg)
                if o.loop is not None and msg["outcome"] == "steps":
                    o.loop.said_done(o.calls[-1])
        elif event == "step":
            self._step(msg)
        else:
            o.fault = f"the case sent a message that is not an earthbench message: {_clip(line)}"

    def _finish(self, msg: dict[str, Any]) -> None:
        """The run's result is in: stop the clock, close the case's stdin, give it time to exit."""
        o = self.o
        o.t_done = time.monotonic()
        o.replied(o.t_done)
        o.done = msg
        self.nonce = None
        self._cpu_at_end()
        self.deadline = o.t_done + EXIT_GRACE_S
        self.outbox.put(None)

    def _give(self, data: bytes, now: float) -> None:
        """Hand the planner its next input and start its call's clock: the wall budget left over
        all calls, and for a closed-loop run at most the per-step limit."""
        o = self.o
        o.t_given = now
        left = self.budget.wall_s - sum(o.calls)
        o.limit = "step" if o.loop is not None and self.budget.step_s < left else "wall"
        self.deadline = now + (min(self.budget.step_s, left) if o.loop is not None else left)
        self.nonce = secrets.token_hex(16)
        self.outbox.put(b'{"nonce": "%s", "input": ' % self.nonce.encode() + data.rstrip(b"\n") + b"}\n")

    def _hand_over(self) -> None:
        """The planner's code is loaded: start the clock and give the case its scenario."""
        o = self.o
        o.t_ready = time.monotonic()
        o.cpu_ready = self._tree_cpu()
        stdin, outbox = self.proc.stdin, self.outbox
        assert stdin is not None  # the case is started with stdin=PIPE

        def write() -> None:  # one writer, so a case that stops reading never blocks the supervisor
            try:
                while (data := outbox.get()) is not None:
                    stdin.write(data)
                    stdin.flush()
            except OSError:  # the case ended (or closed its stdin) before reading it all
                pass
            try:
                stdin.close()
            except OSError:
                pass

        self.writer = threading.Thread(target=write, name="earthbench-stdin", daemon=True)
        self.writer.start()
        self._give(self.scenario, o.t_ready)

    def _step(self, msg: dict[str, Any]) -> None:
        """One closed-loop step: time it, execute it on the truth, hand over the next observation."""
        o, loop = self.o, self.o.loop
        now = time.monotonic()
        if loop is None:
            o.fault = "the case sent a step, but its configuration does not run closed loop"
        elif o.t_given is None:
            o.fault = (
                "the case sent a step before it was given an observation"
                if o.t_ready is None
                else "the case sent a step it was not asked for"
            )
        elif not isinstance(msg.get("plan"), str):
            o.fault = f"the case's step has a plan of type {type(msg.get('plan')).__name__}, not a JSON text"
        elif problem := self._unechoed(msg):
            o.fault = problem
        else:
            self.nonce = None
            took = o.replied(now)
            if self.cgroup is not None:  # no compute between steps: the case stands still while the harness works
                self.cgroup.freeze(True, wait=False)
            try:
                problem = loop.take(msg["plan"], took)
                data = loop.next_observation() if not (problem or loop.ended) else b""
            finally:
                if self.cgroup is not None:
                    self.cgroup.freeze(False, wait=False)
            if problem:
                o.fault = problem
            elif loop.ended:
                o.done = {"event": "done", "outcome": "steps"}
                o.t_done = now
                self._cpu_at_end()
                self.deadline = now + EXIT_GRACE_S
                self.outbox.put(None)
            else:
                self._give(data, time.monotonic())

    def _cpu_at_end(self) -> None:
        """The cgroup's CPU seconds when the planner's last call ended (what its processes burn
        while the case exits is not the planner's compute)."""
        if self.cgroup is not None and self.o.cgroup_cpu_s is None:
            self.o.cgroup_cpu_s = self.cgroup.cpu_s()

    def _unechoed(self, msg: dict[str, Any]) -> str:
        """Why a reply is not an answer to the input the case was last given ('' when it is)."""
        if self.nonce is None or msg.get("nonce") != self.nonce:
            return ("the case's reply does not echo the nonce of the input it answers "
                    "(a reply written before its input arrived, or not by the case's bootstrap)")
        return ""

    def _over_cpu(self) -> bool:
        """The planner's calls have used more CPU seconds than the budget's ``cpu_s``."""
        cap, o = self.budget.cpu_s, self.o
        if cap is None or o.t_ready is None or o.done is not None:
            return False
        if self.cgroup is None and time.monotonic() < self.next_cpu_check:
            return False  # without a cgroup, reading the tree's CPU is a scan: every SAMPLE_S
        self.next_cpu_check = time.monotonic() + SAMPLE_S
        if self._tree_cpu() - o.cpu_ready > cap:
            o.cpu_out = True
            return True
        return False

    # -- the process tree ----------------------------------------------------------------------
    def _tree(self) -> list[psutil.Process]:
        try:
            return self.warden.children(recursive=True) if self.warden is not None else []
        except psutil.Error:
            return []

    def _planner(self) -> psutil.Process | None:
        """The planner's process, by the pid its warden reported (no scan of the process table);
        None in a sandbox of its own (that pid is its PID namespace's, not ours)."""
        if self.sandboxed:
            return None
        if self.planner is None:
            self._read_report_pipe()
            first = self.report_buf.split(b"\n", 1)[0]
            try:
                self.planner = psutil.Process(int(json.loads(first)["planner"]))
            except (ValueError, KeyError, TypeError, psutil.Error):
                return None
        return self.planner

    def _tree_cpu(self) -> float:
        """CPU seconds the case's processes have used so far (the warden's own excluded, as in its report).

        The planner's process (with its reaped children) is read directly; only if its pid is
        not known is the whole tree scanned.
        """
        if self.cgroup is not None:
            return self.cgroup.cpu_s()
        planner = self._planner()
        total = 0.0
        for p in [planner] if planner is not None else self._tree():
            try:
                t = p.cpu_times()
            except psutil.Error:
                continue
            total += t.user + t.system + t.children_user + t.children_system
        return total

    def _sample(self, now: float) -> None:
        """Address space (what RLIMIT_AS caps) and resident memory, as we wait: the planner's process
        every :data:`SAMPLE_S`, the whole tree every :data:`TREE_SAMPLE_S` (a scan of the process table).
        With a cgroup the kernel keeps the peak itself; the process count is sampled."""
        if self.cgroup is not None:
            self.cgroup.sample_pids()
            return
        if now >= self.next_tree_sample:
            procs = self._tree()
            self.next_tree_sample = now + TREE_SAMPLE_S
        else:
            planner = self._planner()
            procs = [planner] if planner is not None else []
        rss = 0.0
        for p in procs:
            try:
                m = p.memory_info()
            except psutil.Error:
                continue
            self.o.peak_vms_mb = max(self.o.peak_vms_mb, m.vms / 2**20)
            rss += m.rss / 2**20
        self.o.peak_rss_mb = max(self.o.peak_rss_mb, rss)

    def _reaped(self, block: bool = False) -> bool:
        try:
            pid, status, _ = os.wait4(self.proc.pid, 0 if block else os.WNOHANG)
        except ChildProcessError:
            pid, status = self.proc.pid, 0
        if not pid:
            return False
        self.o.status = os.waitstatus_to_exitcode(status)
        self.proc.returncode = self.o.status
        return True

    def _end(self) -> None:
        """Ask the warden to end the tree; if it does not within the grace, kill every process we find.
        With a cgroup, the kernel's list of the case's processes is killed at once."""
        if self.cgroup is not None:
            self.cgroup.kill()
            self._reaped(block=True)
            return
        try:
            os.kill(self.proc.pid, signal.SIGTERM)
        except ProcessLookupError:
            pass
        end = time.monotonic() + TERM_GRACE_S
        while time.monotonic() < end:
            if self._reaped():
                return
            time.sleep(0.01)
        for p in self._tree():  # the warden is stopped or gone astray: do its job
            try:
                p.kill()
            except psutil.Error:
                pass
        try:
            os.kill(self.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self._reaped(block=True)

    def _read_report_pipe(self) -> None:
        try:
            os.set_blocking(self.report_fd, False)
            while chunk := os.read(self.report_fd, 1 << 16):
                self.report_buf += chunk
        except OSError:  # nothing more yet (BlockingIOError) or the pipe is gone
            pass

    def _read_report(self) -> None:
        """The warden's final report, if it wrote one; without it, sweep for processes tagged with this case."""
        self._read_report_pipe()
        for line in bytes(self.report_buf).splitlines()[1:2]:
            try:
                rep = json.loads(line)
            except ValueError:
                break
            if isinstance(rep, dict) and all(isinstance(rep.get(k), (int, float)) for k in ("cpu_s", "maxrss_kb")):
                self.o.report = rep
                if isinstance(rep.get("status"), int) and self.o.status == 0:
                    self.o.status = rep["status"]  # the planner process's own exit status
                return
        if self.cgroup is None:  # with a cgroup, the kernel's list of its processes is killed instead
            _sweep(self.tag)


def _sweep(tag: str) -> None:
    """Kill every process of ours that carries the case's tag (the warden died before its job was done)."""
    me = os.getuid()
    for p in psutil.process_iter(["uids"]):
        try:
            if p.info["uids"] and p.info["uids"].real == me and p.environ().get(CASE_TAG) == tag:
                p.kill()
        except psutil.Error:
            continue


#: A non-case job's one result: a preparation's ``prepared``, a probe's ``probed`` (with a JSON text).
JOB_RESULTS = {"prepare": "prepared", "probe": "probed"}


def _check_done(msg: dict[str, Any], ready: bool, closed_loop: bool = False, prepare: bool | str = False) -> str:
    """Why a result message is malformed, or '' when it is well formed. ``prepare``: the job it is
    (``prepare``, ``probe``; True: ``prepare``), whose one result is ``prepared`` or ``probed`` (or an error)."""
    outcome = msg.get("outcome")
    job = "prepare" if prepare is True else (prepare or "")
    expected = JOB_RESULTS.get(job)
    if (outcome in JOB_RESULTS.values() or expected) and outcome != expected and outcome not in ("error", "memory"):
        return f"the {job or 'case'}'s result has outcome {_clip(outcome)}"
    if expected and outcome == expected:
        return "" if ready and isinstance(msg.get("summary"), str) else f"the {job}'s result is malformed"
    if outcome not in ("plan", "error", "memory", "steps"):
        return f"the case's result has outcome {_clip(outcome)}, not one of plan, error, memory, steps"
    if outcome == "steps" and not (closed_loop and ready):
        return "the case said its steps are done, but it " + ("runs open loop" if ready else "was not ready")
    if outcome == "plan" and closed_loop:
        return "the case sent a whole plan, but its configuration runs closed loop (one step at a time)"
    if not isinstance(msg.get("error", ""), str):
        return f"the case's result has an error text of type {type(msg['error']).__name__}, not a string"
    if not isinstance(msg.get("detail", {}), dict):
        return "the case's result has a detail that is not an object"
    if outcome == "plan":
        if not ready:
            return "the case sent a plan before it said it was ready"
        if not isinstance(msg.get("plan"), str):
            return f"the case's result has a plan of type {type(msg.get('plan')).__name__}, not a JSON text"
    return ""


def _too_large(n: int) -> str:
    return (f"the case's result is over the plan-size limit: more than {MAX_RESULT_BYTES / 2**20:.0f} MB of JSON "
            f"(read {n / 2**20:.0f} MB before it was refused)")


def _clip(value: Any, n: int = 120) -> str:
    text = value.decode(errors="replace") if isinstance(value, bytes) else repr(value)
    return text if len(text) <= n else text[:n] + "…"


_MEMORY_WORDS = ("std::bad_alloc", "MemoryError", "Cannot allocate memory", "out of memory", "Unable to allocate")


def _mentions_memory(text: str) -> bool:
    """An allocation failure inside a C/C++ extension shows up only as text (or an abort)."""
    tail = text[-2000:]
    return any(w in tail for w in _MEMORY_WORDS)


def _result(case: Case, o: _Outcome, cores: tuple[int, ...], started_at: str, log_tail: str,
            machine_load: dict[str, Any] | None = None) -> CaseResult:
    budget = case.scenario.budget
    times: dict[str, Any] = dict(solve_time_s=o.solve_time_s, solve_cpu_s=o.solve_cpu_s)
    loop = o.loop
    if loop is not None and o.t_given is not None and o.t_end is not None:  # the call a deadline or a fault cut short
        loop.steps.append((0, o.t_end - o.t_given))
    common: dict[str, Any] = dict(
        key=case.key, scenario_id=case.scenario.id, cores=cores, started_at=started_at, finished_at=utc_now(),
        log_tail=log_tail, exit_status=o.status, peak_rss_mb=o.maxrss_mb,
        startup_s=(o.t_ready - o.t_spawn) if o.t_ready is not None else None,
        environment=environment(case.planner.source),
        detail=dict(o.done.get("detail") or {}) if o.done else {},
        steps=tuple(loop.steps) if loop is not None else None,
        isolation=o.isolation, processes=o.processes, machine_load=machine_load or {},
    )
    if o.cancelled and o.done is None:
        return CaseResult(reason="cancelled", error="the run was interrupted", **common)
    if o.fault:
        return CaseResult(reason="error", error=o.fault + "; the case was ended", **times, **common)
    if o.oom_kills:  # the whole tree's memory is the budget, whatever the planner made of a lost process
        return CaseResult(reason="memory", error=f"the kernel ended {o.oom_kills} process(es) of the case at its memory budget "
                          f"of {budget.memory_mb} MB (the whole process tree's; peak {o.maxrss_mb or 0:.0f} MB)", **times, **common)
    if o.cpu_out and o.done is None:
        over = f" over {len(loop.steps)} step(s)" if loop is not None else ""
        return CaseResult(reason="timeout", error=f"the planner used more than its CPU budget of {budget.cpu_s:g} s{over} and was ended",
                          **times, **common)
    if o.done is None:
        if o.timed_out:
            if o.t_ready is not None and o.limit == "step":
                msg = f"step {len(loop.steps) - 1 if loop else 0} ran past the per-step limit of {budget.step_s:g} s and was ended"
            elif o.t_ready is not None:
                over = f" over {len(loop.steps)} step(s)" if loop is not None else ""
                msg = f"the planner ran past its wall budget of {budget.wall_s:g} s{over} and was ended"
            else:
                msg = f"the case did not reach the planner call within {o.startup_s:g} s of start-up"
            return CaseResult(reason="timeout", error=msg, **times, **common)
        st = o.status
        how = f"killed by {signal.Signals(-st).name}" if st is not None and st < 0 else f"exited with status {st}"
        near = MEMORY_KILL_FRACTION * budget.memory_mb
        if (o.maxrss_mb or 0) >= near or o.peak_vms_mb >= near or _mentions_memory(log_tail):
            return CaseResult(reason="memory", error=f"the case process {how} near its memory budget of {budget.memory_mb} MB "
                              f"(peak {o.maxrss_mb or 0:.0f} MB resident, {o.peak_vms_mb:.0f} MB address space seen)", **times, **common)
        return CaseResult(reason="crashed", error=f"the case process {how} without a result", **times, **common)
    d = o.done
    if d["outcome"] in ("error", "memory"):
        reason = "memory" if d["outcome"] == "memory" or _mentions_memory(d.get("error", "")) else "error"
        return CaseResult(reason=reason, error=d.get("error", ""), **times, **common)
    plan_json = loop.plan().to_json() if loop is not None else d["plan"]
    try:
        verdict, metrics = score(case.scenario, plan_json, case.threshold)
    except Exception:  # noqa: BLE001 - a referee bug must not lose the plan; `earthbench rescore` can retry
        return CaseResult(
            reason="error", error="the referee failed on this plan:\n" + traceback.format_exc(), plan_json=plan_json, **times, **common
        )
    metrics.update(times)
    if loop is not None:
        metrics.update(step_metrics(loop.steps))
    return CaseResult(
        reason="ok" if verdict.valid else "invalid", metrics=metrics, error=loop.ended if loop is not None else "",
        violations=tuple(v.to_dict() for v in verdict.violations), plan_json=plan_json, **times, **common,
    )
