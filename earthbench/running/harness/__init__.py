"""The harness: runs every case of a suite in a fenced subprocess and hands results to the store.

Modules, each with one job:

* :mod:`.cases` — :class:`~.cases.Prepared`, a planner's finished preparation; :class:`PlannerRef`, :class:`Case`,
  :class:`CaseResult` and ``REASONS`` are :mod:`earthbench.results.records`'s, exported here too;
* :mod:`.run` — :func:`run_case`: one case, run and measured in the sandbox (:mod:`.sandbox`, :mod:`.supervisor`,
  :mod:`.tree`: a raw :class:`~.outcome.Outcome`; the pipe's messages checked by :mod:`.protocol`), then judged
  (:mod:`.judge`); a closed loop's steps owned by :mod:`.steps`;
* the fences: :mod:`.isolation` (what this machine allows; :class:`~.isolation.Fence`), :mod:`.namespaces`
  (bubblewrap), :mod:`.cgroups` (v1 and v2 behind :class:`~.cgroups.CaseCgroup`), :mod:`.visible` (what a job may
  read, with the folders its planner declares);
* :mod:`.prepare` — a planner's preparation: its key, its folder, the job that makes it and its progress;
* :mod:`.child` — the bootstrap and the code that runs inside a case's process;
* :mod:`.environment` — :func:`environment`: the machine and software stamp of a run;
* :mod:`.slots` — :func:`make_slots`, :class:`SlotPool`: disjoint core groups;
* :mod:`.local` — the :class:`Executor` protocol and :class:`LocalExecutor`;
* :mod:`.dask_executor` — :class:`~.dask_executor.DaskExecutor` (imported on demand: needs ``distributed``);
* :mod:`.orchestrate` — :func:`build_cases`, :func:`run_cases`, :func:`run_suite`;
* :mod:`.probe` — a plugin's planners described by a fenced, cached probe (:mod:`.describe` runs inside it):
  the harness never imports a plugin's code (docs/DESIGN.md §6 "Plugin code").
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...lazy import lazy_getattr

#: The public names, one list: imported on first use (:func:`earthbench.lazy.lazy_getattr`),
#: so a case's process, which imports only :mod:`.child`, does not pay for the executors,
#: psutil and concurrent.futures.
if TYPE_CHECKING:  # pragma: no cover
    from .cases import REASONS, Case, CaseResult, PlannerRef
    from .environment import environment
    from .local import Executor, LocalExecutor
    from .orchestrate import RunReport, build_cases, run_cases, run_suite
    from .run import run_case
    from .slots import SlotPool, make_slots


__getattr__ = lazy_getattr(globals())
