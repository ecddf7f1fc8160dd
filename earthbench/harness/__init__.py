"""The harness: runs every case of a suite in a fenced subprocess and hands results to the store.

Modules, each with one job:

* :mod:`.cases` — :class:`PlannerRef`, :class:`Case`, :class:`CaseResult`, ``REASONS``;
* :mod:`.sandbox` — :func:`run_case`: one case in a fresh, supervised process tree;
* :mod:`.child` — the bootstrap and the code that runs inside a case's process;
* :mod:`.scoring` — :func:`score`: the referee's verdict and the metrics of a plan;
* :mod:`.environment` — :func:`environment`: the machine and software stamp of a run;
* :mod:`.slots` — :func:`make_slots`, :class:`SlotPool`: disjoint core groups;
* :mod:`.local` — the :class:`Executor` protocol and :class:`LocalExecutor`;
* :mod:`.dask_executor` — :class:`~.dask_executor.DaskExecutor` (imported on demand: needs ``distributed``);
* :mod:`.orchestrate` — :func:`build_cases`, :func:`run_cases`, :func:`run_suite`.
"""

from .cases import REASONS, Case, CaseResult, PlannerRef
from .environment import environment
from .local import Executor, LocalExecutor
from .orchestrate import RunReport, build_cases, run_cases, run_suite
from .sandbox import run_case
from .scoring import score
from .slots import SlotPool, make_slots

__all__ = [
    "REASONS", "Case", "CaseResult", "Executor", "LocalExecutor", "PlannerRef", "RunReport", "SlotPool",
    "build_cases", "environment", "make_slots", "run_case", "run_cases", "run_suite", "score",
]
