"""The scoring rule, defined once: judge a plan, compute every registered metric, decide success.

Three rules live here and nowhere else: :func:`is_success`, :func:`time_to_target` (with
:func:`time_per_target`, the primary time metric) and :func:`run_order` with
:func:`target_share` (how two runs of one scenario compare: the order rankings follow). Each is *prefix-monotone*: no
prefix of a valid plan is a success where the plan is not, reaches the target earlier, or comes
first in :func:`run_order` (docs/metrics.md, "Why loading less never pays").

Every place that needs to know whether a run succeeded — the harness, ``rescore``, ``validate``,
:func:`relabel` for runs read under another suite's threshold (:func:`earthbench.results.store.load_runs`
with a suite) — calls :func:`is_success`; every metric comes from the ``earthbench.metrics`` registry (the built-in
ones are the ``core`` plugin), so the core never imports a metrics package.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover - imported when used: the suite loader needs only the threshold
    import pandas as pd

    from ..plan import Plan
    from ..referee import Verdict
    from ..world import Scenario

#: A suite's success threshold when its file names none: volume ratio ≥ 0.9 with a valid plan.
DEFAULT_SUCCESS_THRESHOLD = 0.9
#: Relative slack when matching the cumulative loaded volume to the target: float sums only.
SUM_SLACK = 1e-9


def time_to_target(load_curve: Sequence[tuple[float, float]], target: float) -> float:
    """End of the first dump after which the truck holds the target (s); ``inf`` if it never does.

    ``load_curve``: the referee's ``(end time, cumulative m³)`` of every dump (``Verdict.load_curve``).
    A plan short of the target is charged the one cost no continuation can beat: infinity. Any
    finite charge for the missing volume is beaten by stopping early on some plan — the cheapest
    honest one, the machine's fastest cycle per m³ (the lower bound), is beaten by *every* plan,
    since the dumps a prefix leaves out took at least that long (docs/metrics.md).
    """
    for t_end, cumulative in load_curve:
        if cumulative >= target * (1 - SUM_SLACK):
            return float(t_end)
    return math.inf


#: The metrics :func:`restate` brings to the current rule.
TARGET_TIME_METRICS = ("time_to_target_s", "time_per_target_m3", "time_per_target_m3_ratio")


def restate(metrics: dict[str, Any]) -> dict[str, Any]:
    """Stored metrics under today's rule where their own figures decide it (the same dict, changed in place).

    Before issue 35 a run short of the target had a finite time to it (the time to what it loaded,
    divided by that); under :func:`time_to_target` it has none. The loaded and target volumes in
    the metrics decide which runs those are, so a store written before needs no re-judging for the
    tables, ``compare`` or an audit to apply the rule (``earthbench rescore`` rewrites it for good).
    """
    try:
        short = float(metrics["loaded_volume"]) < float(metrics["target_volume"]) * (1 - SUM_SLACK)
    except (KeyError, TypeError, ValueError):
        return metrics
    if short:
        for k in TARGET_TIME_METRICS:
            if k in metrics and metrics[k] is not None:
                metrics[k] = math.inf
    return metrics


def time_per_target(load_curve: Sequence[tuple[float, float]], target: float) -> float:
    """The primary time metric, time to the target / the target (s/m³); ``inf`` short of the target."""
    return time_to_target(load_curve, target) / target


def target_share(volume_ratio: Any) -> float:
    """The share of the target a run loaded, capped at 1 (loading past the target earns nothing); 0 when unknown."""
    try:
        r = float(volume_ratio)
    except (TypeError, ValueError):
        return 0.0
    return 0.0 if math.isnan(r) else min(max(r, 0.0), 1.0)


def run_order(success: bool, time_per_target_m3: float, volume_ratio: float = math.nan,
              solve_cpu_s: float = math.nan) -> tuple[int, float, float, float]:
    """Sort key of one run (lower first): success, time per target m³, the share of the target loaded
    (:func:`target_share`, higher first: among runs short of the target, more is better), solve CPU time.

    The per-run form of :data:`earthbench.results.aggregate.RANKING_RULE` (tables rank on the same keys'
    rates, medians and means). Every key before the solve time is prefix-monotone; NaN sorts last.
    """
    def last(v: float) -> float:
        return math.inf if v is None or math.isnan(v) else float(v)

    return (0 if success else 1, last(time_per_target_m3), -target_share(volume_ratio), last(solve_cpu_s))


def is_success(valid: Any, volume_ratio: Any, threshold: float) -> bool:
    """Success: a valid plan whose loaded volume is at least ``threshold`` × the target."""
    try:
        ratio = float(volume_ratio)
    except (TypeError, ValueError):
        return False
    return bool(valid) and not math.isnan(ratio) and ratio >= threshold


def relabel(runs: pd.DataFrame) -> pd.DataFrame:
    """Stored runs read under another suite (a :func:`earthbench.results.store.load_runs` frame whose
    ``threshold`` is that suite's): ``success`` decided anew by :func:`is_success` from each run's
    stored ``valid`` and ``volume_ratio`` (a run without a plan has neither and never succeeds)."""
    valid = runs["valid"] if "valid" in runs else [None] * len(runs)
    ratio = runs["volume_ratio"] if "volume_ratio" in runs else [None] * len(runs)
    runs["success"] = [v is not None and v == v and is_success(v, r, t) for v, r, t in zip(valid, ratio, runs["threshold"])]
    return runs


def evaluate(scenario: Scenario, plan: Plan, verdict: Verdict,
             threshold: float = DEFAULT_SUCCESS_THRESHOLD) -> dict[str, Any]:
    """Every registered metric of one run, plus ``success`` (:func:`is_success`).

    ``solve_time_s`` and ``solve_cpu_s`` are left as None: only the harness can measure them.
    Success is decided from the verdict itself, so it holds whichever metric plugins are installed.
    """
    from ..registry import METRICS

    out: dict[str, Any] = {"solve_time_s": None, "solve_cpu_s": None}
    for name in sorted(METRICS.names(), key=lambda n: (n != "core", n)):  # the core metrics first
        out.update(METRICS.get(name)(scenario, plan, verdict))
    target = scenario.task.target_volume
    out["success"] = is_success(verdict.valid, verdict.loaded_volume / target if target > 0 else math.nan, threshold)
    return out


def score(scenario: Scenario, plan_json: str, threshold: float) -> tuple[Verdict, dict[str, Any]]:
    """Judge a plan document and :func:`evaluate` it: the harness's, ``rescore``'s and ``merge``'s one call."""
    from ..plan import Plan
    from ..referee import judge

    verdict = judge(scenario, plan_json)
    try:
        plan = Plan.from_json(plan_json)
    except Exception:  # noqa: BLE001 - malformed: the verdict already says so
        plan = Plan()
    return verdict, evaluate(scenario, plan, verdict, threshold)
