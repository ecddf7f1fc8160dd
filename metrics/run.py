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

``time_per_target_m3_lower_bound`` — the least time per target m³ (:func:`lower_bound_time_to_target`
÷ the target) under every rule of today's referee, for the primary metric. It adds what a given
scenario forces on the time to its target and the bound above leaves out: whole buckets (the
target needs ``n = ⌈target / C_eff⌉`` loaded dumps, ``C_eff`` the bank m³ a bucket really holds:
the capacity × the soil's fill factor on the realistic track), and the travel before the first
dump when the truck starts out of dump reach of the excavator. It does **not** price the swing
of each cycle: the referee lets the truck stand anywhere clear of the excavator, including on the
ray to the contact (on the dig area beyond it, or between the base and a contact the arm reaches
over), where a cycle swings 0 rad; ``tests/test_bound.py`` builds such a plan (docs/metrics.md,
"What the geometry forces").
"""

from __future__ import annotations

import math
from typing import Any

from earthbench.motion import ABS_TOL, RATE_TOL
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


def _buckets(target: float, capacity: float) -> int:
    """The fewest loaded dumps after which the scoring rule (:func:`earthbench.scoring.time_to_target`,
    with its slack) finds ``target`` loaded when each carries at most ``capacity``; float sums of
    the digs may exceed a whole number of buckets by rounding, so a bucket counts 1e-9 fuller."""
    n = max(1, math.ceil(target / capacity) - 1)
    while not math.isfinite(scoring_time_to_target(((0.0, n * capacity * (1 + 1e-9)),), target)):
        n += 1
    return n


def _first_dump_start(scenario: Scenario) -> float:
    """The earliest start of the first loaded dump (s): the excavator digs once first (at least
    the minimum stroke), and the truck must be within dump reach (centre distance ≤ ``reach_max``
    + loading radius). Whatever gap ``G`` the two starting poses leave, the two machines close
    it between them: the truck by driving ``L_t``, the excavator by ``L_e`` (its driving and its
    dig never overlap), ``L_e + L_t ≥ G``. The start is at least ``max(L_e / v_e + t_s, L_t / v_t)``,
    least over the split where both are equal."""
    m = scenario.machines
    exc, truck, p, q = m.excavator, m.truck, m.excavator_pose, m.truck_pose
    assert exc is not None and p is not None
    ts = exc.min_stroke_time
    gap = math.hypot(q.x - p.x, q.y - p.y) - (exc.reach_max + truck.loading_radius + ABS_TOL)
    ve, vt = exc.travel_speed * (1 + RATE_TOL), truck.travel_speed * (1 + RATE_TOL)
    if gap <= 0 or gap / vt <= ts:
        return ts
    le = (gap / vt - ts) / (1 / ve + 1 / vt)  # the excavator's share where both take as long
    return ts + le / ve


def lower_bound_time_to_target(scenario: Scenario) -> float:
    """The least time (s) after which any valid plan's truck holds the target.

    One excavator: ``n = ⌈target / C_eff⌉`` loaded dumps, each after a dig of its own since the
    dump before (the bucket is empty after a dump that did not fill the truck), the first
    starting no earlier than :func:`_first_dump_start`:
    ``S₁ + t_d + (n − 1)(t_s + t_d)``, less the referee's tolerance of ``ABS_TOL`` per action on
    durations and overlaps. One loader: ``n (t_c + t_d)`` likewise. Both on one site: the
    machines' rates add, ``target × lower_bound_time_per_m3``.
    """
    m, target = scenario.machines, scenario.task.target_volume
    fill = scenario.soil.fill_factor if scenario.soil is not None else 1.0
    if m.excavator is not None and m.loader is None:
        e = m.excavator
        n = _buckets(target, e.bucket_capacity * fill)
        t = _first_dump_start(scenario) + e.min_dump_time + (n - 1) * (e.min_stroke_time + e.min_dump_time)
        return max(t - 4 * n * ABS_TOL, 0.0)
    if m.loader is not None and m.excavator is None:
        lo = m.loader
        n = _buckets(target, lo.bucket_capacity * fill)
        return max(n * (lo.min_charge_time + lo.min_dump_time) - 4 * n * ABS_TOL, 0.0)
    return target * lower_bound_time_per_m3(scenario)


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
    target_bound = lower_bound_time_to_target(scenario) / target
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
        "time_per_target_m3_lower_bound": target_bound,
        "time_per_target_m3_bound_ratio": tpt / target_bound,
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
