"""Executors: the protocol, and the one that runs cases on this machine."""

from __future__ import annotations

import threading
import traceback
from collections.abc import Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from typing import Protocol

from ...results.records import Case, CaseResult
from .prepare import run_prepared_case
from .sandbox import STARTUP_S, HarnessError
from .slots import SlotPool, make_slots


class Executor(Protocol):
    """Runs cases and yields their results as they finish (in any order).

    An executor may run ``run_case`` anywhere; it must not write the store. ``cancel`` ends
    the cases in flight (their results are dropped) and is safe to call from a signal path.
    """

    def run(self, cases: Sequence[Case]) -> Iterator[CaseResult]: ...

    def cancel(self) -> None: ...


class LocalExecutor:
    """Runs cases on this machine, one per slot, each slot a thread supervising one subprocess."""

    #: Planners are prepared here, before the first case (:func:`.orchestrate.prepare_planners`).
    prepares_here = True

    def __init__(self, jobs: int | None = None, cores_per_case: int = 2, *, startup_s: float = STARTUP_S):
        self.slots = make_slots(cores_per_case, jobs)
        self.startup_s = startup_s
        self._stop = threading.Event()

    def run(self, cases: Sequence[Case]) -> Iterator[CaseResult]:
        self._stop.clear()
        slots = SlotPool(self.slots)

        def task(case: Case) -> CaseResult:
            with slots.slot() as slot:
                try:
                    return run_prepared_case(case, slot, stop=self._stop, startup_s=self.startup_s)
                except HarnessError:
                    raise  # this machine cannot run any case: stop the run, store nothing of it
                except Exception:  # noqa: BLE001 - a harness fault on one case must not stop the suite
                    return CaseResult.failure(case, "error", "the harness failed on this case:\n" + traceback.format_exc())

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
