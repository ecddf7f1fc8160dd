"""The sandbox: run one job (a case, a preparation, a probe) in a fresh, fenced process tree and
measure it.

:func:`run_fenced` starts the bootstrap (:mod:`.child`) in the fences (:mod:`.isolation`) and
supervises it (:mod:`.supervisor`) until it ends; it returns a raw
:class:`~.supervisor.Outcome` and judges nothing (:func:`earthbench.running.harness.run.run_case` hands a
case's outcome to :mod:`.judge`; this module imports neither the referee nor the scoring rule).
:func:`run_job` is the entry of a non-case job.

What a case's run enforces (the trust model is in docs/running.md, "What a plugin can influence"):

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
* the referee runs in the harness process (:mod:`.judge`, :mod:`.steps`), never inside the
  planner's process.
"""

from __future__ import annotations

import functools
import glob
import json
import os
import secrets
import shutil
import site
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import psutil

from ... import compat
from ...errors import EarthbenchError
from ...planner import PrepareProgress, SharedFolder
from ...world import Budget
from . import isolation
from .child import BOOTSTRAP
from .protocol import ClosedLoop
from .outcome import Outcome
from .supervisor import Supervisor
from .tree import CASE_TAG
from .visible import shared_folders, visible_paths

__all__ = ["CASE_ENV", "CASE_TAG", "HIDDEN_VARS", "PASSED_VARS", "STARTUP_S", "TAG_PREFIX", "THREAD_VARS", "HarnessError",
           "JobOutcome", "run_fenced", "run_job"]

#: Seconds a case may spend starting (interpreter, imports of the planner's code) before it is ready.
STARTUP_S = 60.0
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


def _child_env(cores: int, tag: str, home: str, shared: dict[str, str]) -> dict[str, str]:
    """The allow-listed environment of a case: :data:`PASSED_VARS`, the operator's
    :data:`CASE_ENV`, the variables of the folders its planner reads (``shared``, resolved by
    :func:`.visible.shared_folders`), the thread caps, the module path and ``HOME`` (the case's own folder)."""
    chosen = {n.strip() for n in os.environ.get(CASE_ENV, "").split(",") if n.strip()} - set(HIDDEN_VARS)
    env = {k: v for k, v in os.environ.items() if k in PASSED_VARS or k.startswith("LC_") or k in chosen}
    env[CASE_TAG] = tag
    env["HOME"] = home
    env.update(shared)  # where the planner finds its folders, resolved here (the case has no HOME of the user's)
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


# -- a job that is not a case: a planner's preparation (.prepare), a probe (.probe) ---------------
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
            what: str = "a preparation", watch: Callable[[], str] | None = None, reads: Sequence[SharedFolder] = (),
            on_progress: Callable[[PrepareProgress], None] | None = None) -> JobOutcome:
    """Run a non-case job (``job`` is its specification, with ``"job"`` naming it) in a fresh,
    fenced process tree on ``cores`` under ``budget``, giving it ``payload`` as its one input once
    it is ready; ``writable`` is the folder it may write (None: none); ``reads``: the folders its
    planner declares it reads; ``watch`` (called every second while it runs) says why to end it,
    e.g. its folder is over its disk budget; ``on_progress`` hears a preparation's progress
    (checked, at most :data:`.protocol.PROGRESS_RATE` a second). The jobs: ``prepare``
    (:mod:`.prepare`) and ``probe`` (:mod:`.probe`, whose one result is ``probed``)."""
    shared, seen = shared_folders(reads)
    if visible is None:
        visible = visible_paths(str(job.get("source", "")))
    o = run_fenced(job, payload, tuple(cores), budget, what=what, visible=(*visible, *seen), shared=shared,
                   writable=(writable,) if writable else (), job=job.get("job") or False,
                   stop=stop, startup_s=startup_s, watch=watch, on_progress=on_progress)
    return JobOutcome(o.done, o.fault, o.timed_out, o.cancelled, o.status, o.solve_time_s, o.solve_cpu_s, o.maxrss_mb,
                      o.log_tail, o.isolation)


def run_fenced(spec: dict[str, Any], payload: bytes, cores: tuple[int, ...], budget: Budget, *, what: str,
               visible: Sequence[str], shared: Mapping[str, str], writable: Sequence[str] = (),
               loop: ClosedLoop | None = None, job: bool | str = False, stop: threading.Event | None = None,
               startup_s: float = STARTUP_S, watch: Callable[[], str] | None = None,
               on_progress: Callable[[PrepareProgress], None] | None = None) -> Outcome:
    """One process tree of the bootstrap in the fences (namespaces, cgroup) on ``cores`` under
    ``budget``, supervised until it ends: ``spec`` is the first line of its input (a pipe; no file
    anyone else can reach), ``payload`` the one it is handed once ready (a case's observation, a
    preparation's job); ``visible`` what it may read, ``shared`` the variables of the folders
    its planner reads. Returns the raw outcome, with the tail of its log and the fences it had;
    a case and a preparation differ only in these arguments (``what`` names it in errors;
    ``job``: ``prepare``, ``probe`` or False for a case); ``watch``, called every
    :data:`.supervisor.TREE_SAMPLE_S` while it runs, says why to end it ('' to go on)."""
    fences = isolation.support()
    _undumpable()
    tmp = _case_dir()  # the working folder of a case without namespaces; a sandboxed one never sees it
    try:
        mr, mw = os.pipe()
        rr, rw = os.pipe()
        lr, lw = os.pipe()  # its stdout and stderr: read here with a byte budget, never a file on disk
        mem = int(budget.memory_mb) * 1024 * 1024
        tag = TAG_PREFIX + secrets.token_hex(8)
        env = _child_env(len(cores), tag, "/tmp" if fences.bwrap else tmp, dict(shared))
        env["TMPDIR"] = "/tmp" if fences.bwrap else tempfile.gettempdir()
        fsize = budget.prepare_disk_mb * 2**20 if job else 0
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
            sup = Supervisor(proc, mr, rr, payload, tag, budget, startup_s, stop, t_spawn, loop, fence.cgroup, bool(fences.bwrap),
                             log_fd=lr, job=job, watch=watch, on_progress=on_progress)
            out = sup.run()
        finally:
            for fd in (mr, rr, lr):
                os.close(fd)
            fence.close()
        out.log_tail = bytes(sup.log).decode(errors="replace")
        out.isolation = fence.label
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return out


@functools.lru_cache(maxsize=1)
def _undumpable() -> None:
    """Once per process: no case may read the harness's memory or descriptors through /proc."""
    isolation.make_undumpable()


#: ``run_case`` moved to :mod:`.run` (0.5.0): the old import still works, with a warning.
__getattr__ = compat.forward(__name__)
