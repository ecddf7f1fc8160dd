"""Judge: turn what the sandbox measured of a case into its stored result.

The sandbox (:mod:`.sandbox`, :mod:`.supervisor`) runs and measures and returns a raw
:class:`~.supervisor.Outcome`: the exit status, the result message, the fault, which deadline
passed, the times and figures. :func:`judge` decides what that was: the termination reason
(``ok``, ``invalid``, ``timeout``, ``memory``, ``error``, ``crashed``, or ``cancelled``, never
stored) with its message and, for a plan, the referee's verdict and the metrics of
:func:`earthbench.results.scoring.score`, run here in the harness's process (docs/DESIGN.md §6, §7).
"""

from __future__ import annotations

import signal
import traceback
from typing import Any

from ...results.records import Case, CaseResult, utc_now
from ...results.scoring import score  # the one scoring rule, in the core
from .environment import environment
from .steps import StepLoop, step_metrics
from .outcome import Outcome

#: Fraction of the memory budget above which a death by signal counts as ``memory``.
MEMORY_KILL_FRACTION = 0.9
_MEMORY_WORDS = ("std::bad_alloc", "MemoryError", "Cannot allocate memory", "out of memory", "Unable to allocate")


def mentions_memory(text: str) -> bool:
    """An allocation failure inside a C/C++ extension shows up only as text (or an abort)."""
    tail = text[-2000:]
    return any(w in tail for w in _MEMORY_WORDS)


def judge(case: Case, o: Outcome, loop: StepLoop | None, cores: tuple[int, ...], started_at: str,
          machine_load: dict[str, Any] | None = None) -> CaseResult:
    """The stored result of ``case`` from what the sandbox measured (``o``) and, for a closed
    loop, the steps it executed (``loop``): its termination reason and message, and for a plan
    the referee's verdict and the metrics (:func:`earthbench.results.scoring.score`)."""
    budget = case.scenario.budget
    times: dict[str, Any] = dict(solve_time_s=o.solve_time_s, solve_cpu_s=o.solve_cpu_s)
    log_tail = o.log_tail
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
        if (o.maxrss_mb or 0) >= near or o.peak_vms_mb >= near or mentions_memory(log_tail):
            return CaseResult(reason="memory", error=f"the case process {how} near its memory budget of {budget.memory_mb} MB "
                              f"(peak {o.maxrss_mb or 0:.0f} MB resident, {o.peak_vms_mb:.0f} MB address space seen)", **times, **common)
        return CaseResult(reason="crashed", error=f"the case process {how} without a result", **times, **common)
    d = o.done
    if d["outcome"] in ("error", "memory"):
        reason = "memory" if d["outcome"] == "memory" or mentions_memory(d.get("error", "")) else "error"
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
