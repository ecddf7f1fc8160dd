"""Run a suite's cases on a Dask distributed cluster (``earthbench run SUITE --executor dask``).

:class:`DaskExecutor` implements the runner's :class:`~earthbench.running.harness.Executor` protocol.
Each case is one Dask task that calls the very same :func:`~earthbench.running.harness.run_case` on a
worker, so a case there gets what it gets locally: a fresh process tree in its own session under its warden,
CPU affinity on a slot of ``budget.cores`` cores, BLAS/OpenMP thread caps, ``RLIMIT_AS`` and
the wall budget. The referee and the environment stamp (:func:`~earthbench.running.harness.environment`:
hostname, CPU model, cores, OS, Python, packages, commits) are computed on the worker too, so
each stored run records the machine that ran it. Results stream back as they finish
(``distributed.as_completed``); only the client writes the store (in
:func:`~earthbench.running.harness.run_cases`), so resume and ``--rerun`` work as with the local executor.

**Slots.** A worker machine with N cores runs floor(N / 2) cases at once. Two mechanisms
enforce it:

* Dask *resources*: start each worker with ``--resources "slots=K"`` (K = floor(cores it may
  use / 2); with ``--nworkers W`` on one machine, K = floor(N / 2 / W) per worker) and at least
  K threads (``--nthreads K``: a case occupies one worker thread while it supervises its
  subprocess). Every case task asks for ``{"slots": 1}``, so the scheduler never sends a
  worker more cases than it has slots. A ``LocalCluster`` takes ``resources={"slots": K}``.
* a host-wide slot pool that chooses the cores: before it starts the case subprocess, the
  task locks (``fcntl.flock``) one lock file per core of a free group of ``budget.cores``
  cores from the worker's CPU affinity (the groups of :func:`~earthbench.running.harness.make_slots`).
  The lock files (``HOST-cpuN.lock``) live in ``$EARTHBENCH_SLOT_DIR`` (default
  ``<tmp>/earthbench-slots-<uid>``) and are shared by every worker process of the machine, so
  two workers on one host never pin cases to the same cores even if their ``slots`` add up to
  more than the host has (the surplus case waits for a group to free). The kernel drops a dead
  worker's locks.

**Faults.** A worker lost mid-case (killed, out of memory, machine gone) kills its case
process tree with it (the case's warden has ``PR_SET_PDEATHSIG`` and ends every descendant; the
case folder is removed by the next harness process on that machine) and Dask runs the task again on another
worker; after ``distributed.scheduler.allowed-failures`` losses (default 3) the task fails
with ``KilledWorker`` and the case is recorded as ``crashed``. A task that raises (e.g.
earthbench cannot be imported on the worker) is recorded as ``error`` with the traceback.
Each case key is yielded at most once, and the store refuses a key it already holds, so a case
that ran twice is never stored twice. :meth:`DaskExecutor.cancel` (Ctrl-C) cancels the queued
tasks and tells every worker to end the cases of this run that are in flight; their results
are dropped, as locally.

Workers need earthbench (and the planners' packages) installed, at the same version as the
client; a planner given as a plugin file (``--plugin FILE.py``) must be readable at the same
path on the workers (a shared file system).
"""

from __future__ import annotations

import contextlib
import fcntl
import itertools
import os
import socket
import tempfile
import threading
import time
import traceback
import uuid
from collections.abc import Iterator, Sequence
from typing import Any

from ...errors import EarthbenchError
from ...results.records import Case, CaseResult
from .prepare import run_prepared_case
from .sandbox import STARTUP_S
from .slots import make_slots

#: The Dask resource a worker declares (``--resources "slots=K"``) and each case task needs one of.
RESOURCE = "slots"
#: Seconds between tries to lock a free core group while all are taken.
SLOT_POLL_S = 0.1


class DaskError(EarthbenchError):
    """The Dask cluster cannot be reached or is not set up to run earthbench cases."""


# -- on the worker -------------------------------------------------------------------------------

_stops: dict[str, threading.Event] = {}
_stops_lock = threading.Lock()


def _stop_event(run_id: str) -> threading.Event:
    with _stops_lock:
        ev = _stops.get(run_id)
        if ev is None:
            ev = _stops[run_id] = threading.Event()
            if len(_stops) > 256:  # forget old runs (never a set one: a late task must still see it)
                for old in [k for k, e in _stops.items() if not e.is_set() and k != run_id][:128]:
                    del _stops[old]
        return ev


def stop_run(run_id: str) -> None:
    """Worker side of :meth:`DaskExecutor.cancel`: end this run's cases here (run by ``client.run``)."""
    _stop_event(run_id).set()


def slot_dir() -> str:
    """The directory of the host-wide per-core lock files."""
    return os.environ.get("EARTHBENCH_SLOT_DIR") or os.path.join(tempfile.gettempdir(), f"earthbench-slots-{os.getuid()}")


def _lock_group(directory: str, group: Sequence[int]) -> list[int] | None:
    """Lock one file per core of ``group`` without waiting; the descriptors, or None if one is taken."""
    held: list[int] = []
    host = socket.gethostname()  # a slot directory on a shared file system still locks per machine
    for c in group:
        try:
            fd = os.open(os.path.join(directory, f"{host}-cpu{c}.lock"), os.O_RDWR | os.O_CREAT, 0o600)
        except OSError:
            for h in held:
                os.close(h)
            raise
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            for h in held:
                os.close(h)
            return None
        held.append(fd)
    return held


@contextlib.contextmanager
def host_slot(cores: int, stop: threading.Event | None = None) -> Iterator[tuple[int, ...] | None]:
    """Hold a free group of ``cores`` CPU cores of this machine for the duration of the block.

    The groups are those of :func:`make_slots` over this process's CPU affinity; a group is
    held by ``flock``-ing one file per core, so every process on the host that uses this pool
    (every Dask worker) sees it taken. Yields the cores, or None if ``stop`` was set first.
    """
    groups = make_slots(cores, None)
    directory = slot_dir()
    os.makedirs(directory, exist_ok=True)
    while True:
        for group in groups:
            held = _lock_group(directory, group)
            if held is None:
                continue
            try:
                yield group
            finally:
                for fd in held:
                    os.close(fd)  # closing the descriptor releases its lock
            return
        if stop is None:
            time.sleep(SLOT_POLL_S)
        elif stop.wait(SLOT_POLL_S):
            yield None
            return


def probe() -> dict[str, Any]:
    """What a worker reports in the preflight of a run (run there by ``client.run``)."""
    from importlib import metadata

    try:
        version = metadata.version("earthbench")
    except metadata.PackageNotFoundError:
        version = None
    return {"earthbench": version, "cpus": len(os.sched_getaffinity(0))}


def _cancelled(case: Case) -> CaseResult:
    return CaseResult(key=case.key, scenario_id=case.scenario.id, reason="cancelled", error="the run was interrupted")


def run_on_worker(case: Case, run_id: str, startup_s: float = STARTUP_S) -> CaseResult:
    """The Dask task of one case: take a slot of this machine, then :func:`run_case` in it (after
    the planner's preparation on this worker: each worker prepares once, :mod:`.prepare`)."""
    stop = _stop_event(run_id)
    if stop.is_set():
        return _cancelled(case)
    with host_slot(case.scenario.budget.cores, stop) as cores:
        if cores is None:
            return _cancelled(case)
        return run_prepared_case(case, cores, stop=stop, startup_s=startup_s)


# -- on the client -------------------------------------------------------------------------------


class DaskExecutor:
    """Runs cases as Dask tasks on a ``distributed.Client`` (or the scheduler at ``scheduler``).

    ``client`` may come from any Dask cluster (``LocalCluster``, dask-jobqueue, Kubernetes…);
    it is left open. Given ``scheduler`` (``tcp://HOST:PORT``) instead, the executor connects
    itself and :meth:`close` (or ``with``) disconnects. ``jobs`` caps the cases in flight
    (default: every case is submitted at once and the workers' ``slots`` decide).
    ``resource`` is the Dask resource each task needs one of (None: no resource restriction;
    then only the host slot pool gates the cases and waiting cases occupy worker threads).
    """

    def __init__(
        self,
        client: Any = None,
        *,
        scheduler: str | None = None,
        jobs: int | None = None,
        startup_s: float = STARTUP_S,
        resource: str | None = RESOURCE,
        connect_timeout: float = 30.0,
    ):
        import distributed

        self._distributed = distributed
        if client is None:
            address = scheduler or _configured_scheduler()
            if not address:
                raise DaskError("no Dask scheduler given: pass --scheduler tcp://HOST:PORT (or set DASK_SCHEDULER_ADDRESS)")
            try:
                client = distributed.Client(address, timeout=connect_timeout)
            except (OSError, TimeoutError) as exc:
                raise DaskError(f"cannot reach the Dask scheduler at {address}: {exc}; is `dask scheduler` running there?") from None
            self._own = True
        else:
            self._own = False
        self.client = client
        self.jobs = jobs
        self.startup_s = startup_s
        self.resource = resource
        self.run_id = ""
        self._futures: dict[Any, Case] = {}
        self._lock = threading.Lock()
        self._stopped = threading.Event()

    # -- cluster facts -----------------------------------------------------------------------
    def worker_slots(self) -> dict[str, float]:
        """Each worker's declared ``slots`` (0 for a worker without the resource)."""
        workers = (
            self.client.scheduler_info(n_workers=-1)["workers"]
            if _accepts_n_workers(self.client)
            else self.client.scheduler_info()["workers"]
        )
        return {addr: float((w.get("resources") or {}).get(self.resource or RESOURCE, 0)) for addr, w in workers.items()}

    @property
    def slots(self) -> list[tuple[str, int]]:
        """(worker, index) of every slot the cluster declares right now (for the run's header line)."""
        return [(addr, i) for addr, k in sorted(self.worker_slots().items()) for i in range(int(k))]

    def check(self) -> None:
        """Refuse a cluster whose workers cannot run a case: explain how to start them.

        Every worker present must import this earthbench at the client's version, and (unless
        ``resource`` is None) at least one must declare the resource. A cluster with no worker
        yet (an adaptive dask-jobqueue cluster) passes: its cases wait for workers.
        """
        from importlib import metadata

        try:
            mine = metadata.version("earthbench")
        except metadata.PackageNotFoundError:
            mine = None
        try:
            reports = self.client.run(probe, on_error="return")
        except Exception as exc:  # noqa: BLE001
            raise DaskError(f"the Dask workers could not be asked for their earthbench version: {exc!r}") from None
        for addr, rep in sorted(reports.items()):
            if isinstance(rep, BaseException):
                raise DaskError(f"Dask worker {addr} cannot run earthbench cases ({type(rep).__name__}: {rep}); "
                                "install earthbench (and the planners' packages) on every worker") from None
            if rep.get("earthbench") != mine:
                raise DaskError(f"Dask worker {addr} has earthbench {rep.get('earthbench')}, the client {mine}; "
                                "install the same version everywhere so every case is scored by the same referee")
        if self.resource is None:
            return
        have = self.worker_slots()
        if have and not any(have.values()):
            raise DaskError(
                f"none of the {len(have)} Dask worker(s) declares the {self.resource!r} resource, so no case could run; "
                f'start workers with `dask worker ADDRESS --nthreads K --resources "{self.resource}=K"` '
                "(K = floor(cores / 2)), or LocalCluster(..., resources={'%s': K})" % self.resource
            )

    # -- the Executor protocol ---------------------------------------------------------------
    def run(self, cases: Sequence[Case]) -> Iterator[CaseResult]:
        distributed = self._distributed
        self.check()
        self.run_id = uuid.uuid4().hex[:12]
        self._stopped.clear()
        restrictions = {self.resource: 1} if self.resource else None
        seen: set[tuple[str, str, str, str]] = set()
        lost = 0
        todo = iter(cases)
        ac = distributed.as_completed([], with_results=False)
        serial = itertools.count()

        def submit(case: Case) -> None:
            p = case.planner  # a readable task key (the dashboard shows it), unique within the run
            key = f"earthbench-{p.name}-{case.scenario.digest[:12]}-{p.config_hash[:8]}-{self.run_id}-{next(serial)}"
            fut = self.client.submit(
                run_on_worker, case, self.run_id, self.startup_s,
                key=key, pure=False, resources=restrictions, retries=0,
            )
            with self._lock:
                self._futures[fut] = case
            ac.add(fut)

        try:
            for n, case in enumerate(todo, 1):
                submit(case)
                if self.jobs is not None and n >= self.jobs:
                    break
            for fut in ac:
                with self._lock:
                    mine = self._futures.pop(fut) if fut in self._futures else None
                if mine is None:
                    continue
                res = self._collect(fut, mine)
                if not self._stopped.is_set():
                    nxt = next(todo, None) if self.jobs is not None else None
                    if nxt is not None:
                        submit(nxt)
                if res is None and not self._stopped.is_set():
                    lost += 1
                if res is None or res.reason == "cancelled" or res.key in seen:
                    continue
                seen.add(res.key)
                yield res
            if lost:
                raise DaskError(f"{lost} case(s) were cancelled by the Dask cluster (scheduler restarted or connection lost?); "
                                "nothing of them was stored: run the same command again to run them")
        finally:
            self.cancel()

    def _collect(self, fut: Any, case: Case) -> CaseResult | None:
        status = fut.status
        if status == "finished":
            try:
                res = fut.result()
            except Exception as exc:  # noqa: BLE001 - a result that cannot be fetched is the task's failure
                return CaseResult.failure(case, "error", f"the Dask task's result could not be fetched: {exc!r}")
            if not isinstance(res, CaseResult) or res.key != case.key:
                return CaseResult.failure(
                    case, "error", f"the Dask task returned {type(res).__qualname__} for another case, not this case's result"
                )
            return res
        if status == "error":
            failure = fut.exception()
            if isinstance(failure, self._distributed.KilledWorker):
                return CaseResult.failure(case, "crashed", f"the Dask workers running this case died repeatedly ({failure}); "
                                                "it was given up after distributed.scheduler.allowed-failures tries")
            tb = fut.traceback()
            text = "".join(traceback.format_exception(type(failure), failure, tb)) if tb is not None else repr(failure)
            return CaseResult.failure(case, "error", "the Dask task failed on its worker:\n" + text)
        return None  # cancelled or lost: not stored, a rerun picks it up

    def cancel(self) -> None:
        """Cancel queued tasks and end this run's cases in flight on every worker (results dropped)."""
        self._stopped.set()
        with self._lock:
            futures = list(self._futures)
            self._futures.clear()
        if not futures:
            return
        with contextlib.suppress(Exception):
            self.client.cancel(futures)
        if self.run_id:
            with contextlib.suppress(Exception):
                self.client.run(stop_run, self.run_id, wait=True)

    def close(self) -> None:
        """Disconnect, if this executor opened the connection."""
        if self._own:
            with contextlib.suppress(Exception):
                self.client.close()

    def __enter__(self) -> DaskExecutor:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def _configured_scheduler() -> str | None:
    try:
        import dask

        return dask.config.get("scheduler-address", None)
    except Exception:  # noqa: BLE001
        return None


def _accepts_n_workers(client: Any) -> bool:
    import inspect

    try:
        return "n_workers" in inspect.signature(client.scheduler_info).parameters
    except (TypeError, ValueError):
        return False
