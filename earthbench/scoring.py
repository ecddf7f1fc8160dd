"""The scoring rule, defined once: judge a plan, compute every registered metric, decide success.

Every place that needs to know whether a run succeeded — the harness, ``rescore``, ``validate``,
:func:`earthbench.store.load_runs` re-labelling a run under another suite's threshold — calls
:func:`is_success`; every metric comes from the ``earthbench.metrics`` registry (the built-in
ones are the ``core`` plugin), so the core never imports a metrics package.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover - imported when used: the suite loader needs only the threshold
    from .plan import Plan
    from .referee import Verdict
    from .world import Scenario

#: A suite's success threshold when its file names none: volume ratio ≥ 0.9 with a valid plan.
DEFAULT_SUCCESS_THRESHOLD = 0.9


def is_success(valid: Any, volume_ratio: Any, threshold: float) -> bool:
    """Success: a valid plan whose loaded volume is at least ``threshold`` × the target."""
    try:
        ratio = float(volume_ratio)
    except (TypeError, ValueError):
        return False
    return bool(valid) and not math.isnan(ratio) and ratio >= threshold


def evaluate(scenario: Scenario, plan: Plan, verdict: Verdict,
             threshold: float = DEFAULT_SUCCESS_THRESHOLD) -> dict[str, Any]:
    """Every registered metric of one run, plus ``success`` (:func:`is_success`).

    ``solve_time_s`` and ``solve_cpu_s`` are left as None: only the harness can measure them.
    Success is decided from the verdict itself, so it holds whichever metric plugins are installed.
    """
    from .registry import METRICS

    out: dict[str, Any] = {"solve_time_s": None, "solve_cpu_s": None}
    for name in sorted(METRICS.names(), key=lambda n: (n != "core", n)):  # the core metrics first
        out.update(METRICS.get(name)(scenario, plan, verdict))
    target = scenario.task.target_volume
    out["success"] = is_success(verdict.valid, verdict.loaded_volume / target if target > 0 else math.nan, threshold)
    return out


def score(scenario: Scenario, plan_json: str, threshold: float) -> tuple[Verdict, dict[str, Any]]:
    """Judge a plan document and :func:`evaluate` it: the harness's, ``rescore``'s and ``merge``'s one call."""
    from .plan import Plan
    from .referee import judge

    verdict = judge(scenario, plan_json)
    try:
        plan = Plan.from_json(plan_json)
    except Exception:  # noqa: BLE001 - malformed: the verdict already says so
        plan = Plan()
    return verdict, evaluate(scenario, plan, verdict, threshold)
