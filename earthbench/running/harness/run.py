"""One case, start to stored result: run and measure it in the sandbox, then judge it.

A *case* is (planner with its configuration, scenario). :func:`run_case` is the unit of work:
a pure function of a picklable :class:`Case` (and the CPU cores of its slot) returning a
picklable :class:`CaseResult`, so any executor can ship it: the local executor runs slots on
this machine; a distributed executor calls the same function on a worker and streams the
results back to the client, which alone writes the store.

The two steps are apart, as in BenchExec (docs/DESIGN.md §6): :func:`.sandbox.run_fenced`
runs the case in its fences and returns what it measured, raw; :func:`.judge.judge` turns that
into the result (termination reason, verdict, metrics). A closed-loop case's steps are executed
on the truth by :class:`.steps.StepLoop`, the one loop that owns a step, which the sandbox
drives through its hooks. The planner gets :func:`earthbench.sensing.observe` of the scenario
(the scan and the soil's nominal class), computed here; the referee judges on the truth.
"""

from __future__ import annotations

import dataclasses
import json
import threading
from collections.abc import Sequence

from ...results.records import Case, CaseResult, utc_now
from ...sensing import observe
from . import load
from .cases import Prepared
from .judge import judge
from .protocol import MAX_RESULT_BYTES
from .sandbox import STARTUP_S, run_fenced
from .slots import SlotPool
from .steps import StepLoop
from .visible import shared_folders, visible_paths


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

    Never raises for anything the planner does; raises :class:`.sandbox.HarnessError` when this
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
    shared, seen = shared_folders(case.planner.reads)
    visible = (*visible_paths(case.planner.source), *seen, *((prepared.path,) if prepared is not None else ()))
    out = run_fenced(spec, scenario, cores, budget, what="a case", visible=visible, shared=shared, loop=loop,
                     stop=stop, startup_s=startup_s)
    res = judge(case, out, loop, cores, started_at, load.around(load_before, load.snapshot()))
    if prepared is not None:
        res = dataclasses.replace(res, prepare_s=prepared.wall_s, prepare_cpu_s=prepared.cpu_s)
    return res
