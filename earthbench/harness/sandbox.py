"""The sandbox: run each case in a fresh, fenced subprocess and report what happened.

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

import json
import os
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
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import psutil

from .cases import Case, CaseResult, utc_now
from .child import BOOTSTRAP
from .environment import environment
from .scoring import score
from .slots import SlotPool

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
    started_at = utc_now()
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
                [sys.executable, "-c", BOOTSTRAP, case_file, str(w), ",".join(map(str, cores)), str(mem), str(os.getpid())],
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
        key=case.key, scenario_id=case.scenario.id, cores=cores, started_at=started_at, finished_at=utc_now(),
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
    try:
        verdict, metrics = score(case.scenario, plan_json, case.threshold)
    except Exception:  # noqa: BLE001 - a referee bug must not lose the plan; `earthbench rescore` can retry
        return CaseResult(reason="error", error="the referee failed on this plan:\n" + traceback.format_exc(), plan_json=plan_json, **times, **common)
    metrics.update(times)
    return CaseResult(
        reason="ok" if verdict.valid else "invalid", metrics=metrics,
        violations=tuple(v.to_dict() for v in verdict.violations), plan_json=plan_json, **times, **common,
    )
