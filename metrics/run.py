"""The built-in metric plugin ``core``: the metrics of one run, from the referee's verdict
(docs/DESIGN.md §7).

``time_to_target_s`` — the end of the first dump after which the truck holds the target
(:func:`earthbench.scoring.time_to_target`, the rule's one definition); infinite for a plan
that never gets there. ``time_per_target_m3`` divides it by the target. Loading past the target
cannot lower it (the dumps after the target end later), and stopping short of it can only raise
it to infinity, so no prefix of a plan scores better than the plan (docs/metrics.md). When the
plan loads exactly the target it equals ``time_per_m3`` minus any time after the last dump.

``time_per_m3_lower_bound`` — why it holds: every m³ loaded into the truck was dug and dumped.
A bucket carries at most ``C`` m³, so loading ``V`` takes at least ``V / C`` digs and as many
dumps by the one excavator; its actions never overlap, each dig lasts at least the minimum
stroke time ``t_s`` and each dump at least the minimum dump time ``t_d``. Hence
``makespan ≥ (V / C)(t_s + t_d)`` and ``makespan / V ≥ (t_s + t_d) / C``. The bound ignores
swinging and driving, so it is loose but never wrong.

Wheel loader (track ``wheel_loader``): each charge needs an empty bucket and fills it with at
most ``C`` m³, so loading ``V`` takes at least ``V / C`` non-empty dumps, each preceded by its
own charge; the loader's actions never overlap, a charge lasts at least ``min_charge_time``
``t_c`` and a dump at least ``min_dump_time`` ``t_d``. Hence ``makespan / V ≥ (t_c + t_d) / C``
(driving between pile and truck, and the penetration time, are left out).

A site with several loading machines (an excavator and a loader) can load in parallel: each
machine ``i`` loads at most ``C_i / (t_i + t_d,i)`` m³ per second, so the bound is
``1 / Σ_i C_i / (t_i + t_d,i)``; with one machine it is that machine's bound above.
"""

from __future__ import annotations

import math
from typing import Any

from earthbench.plan import Plan
from earthbench.referee import Verdict
from earthbench.scoring import time_per_target
from earthbench.scoring import time_to_target as scoring_time_to_target
from earthbench.world import Scenario



def lower_bound_time_per_m3(scenario: Scenario) -> float:
    """The least time per m³ any valid plan can reach on this scenario (s/m³).

    Excavator: ``(min_stroke_time + min_dump_time) / bucket_capacity``; wheel loader:
    ``(min_charge_time + min_dump_time) / bucket_capacity``; both on one site: the parallel
    bound of the module docstring.
    """
    m = scenario.machines
    bounds = []
    if m.excavator is not None:
        bounds.append((m.excavator.min_stroke_time + m.excavator.min_dump_time) / m.excavator.bucket_capacity)
    if m.loader is not None:
        bounds.append((m.loader.min_charge_time + m.loader.min_dump_time) / m.loader.bucket_capacity)
    if not bounds:
        raise ValueError(f"no lower bound is defined for track {scenario.track!r} without an excavator or a loader")
    if len(bounds) == 1:
        return bounds[0]
    return 1.0 / sum(1.0 / b for b in bounds)


def time_to_target(verdict: Verdict, target: float) -> float:
    """End of the first dump after which the truck holds ``target`` m³ (s), ``inf`` if none does.

    Kept for callers of this name; the rule is :func:`earthbench.scoring.time_to_target`.
    """
    return scoring_time_to_target(verdict.load_curve, target)


def core_metrics(scenario: Scenario, plan: Plan, verdict: Verdict) -> dict[str, Any]:
    """Volume ratio, time per m³ and to the target (and their ratios to the bound), digs, fill, travel, claims' error."""
    target = scenario.task.target_volume
    loaded = verdict.loaded_volume
    makespan = verdict.makespan
    tpm = makespan / loaded if loaded > 0 else math.inf
    ttt = time_to_target(verdict, target)
    tpt = time_per_target(verdict.load_curve, target)
    bound = lower_bound_time_per_m3(scenario)
    fills = [d.fill for d in verdict.digs]
    pred = plan.predicted
    return {
        "valid": verdict.valid,
        "violations": len(verdict.violations),
        "loaded_volume": loaded,
        "target_volume": target,
        "volume_ratio": loaded / target,
        "overshoot_m3": max(0.0, loaded - target),
        "makespan_s": makespan,
        "time_to_target_s": ttt,
        "time_per_target_m3": tpt,
        "time_per_target_m3_ratio": tpt / bound,
        "time_per_m3": tpm,
        "time_per_m3_lower_bound": bound,
        "time_per_m3_ratio": tpm / bound,
        "digs": len(verdict.digs),
        "dumps": verdict.dumps,
        "mean_bucket_fill": sum(fills) / len(fills) if fills else 0.0,
        "travel_m": sum(verdict.travel.values()),
        "volume_prediction_error": None if pred.volume is None else pred.volume - loaded,
        "makespan_prediction_error": None if pred.makespan is None else pred.makespan - makespan,
    }
