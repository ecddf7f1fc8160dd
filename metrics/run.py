"""The built-in metric plugin ``core``: the metrics of one run, from the referee's verdict
(docs/DESIGN.md §7).

``time_to_target_s`` — the end of the first dump after which the truck holds the target
(:func:`earthbench.results.scoring.time_to_target`, the rule's one definition); infinite for a plan
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
dump when the truck starts out of dump reach of the excavator or the excavator out of reach of
the dig area. It does **not** price the swing
of each cycle: the referee lets the truck stand anywhere clear of the excavator, including on the
ray to the contact (on the dig area beyond it, or between the base and a contact the arm reaches
over), where a cycle swings 0 rad; ``tests/test_bound.py`` builds such a plan (docs/metrics.md,
"What the geometry forces").

The one wheel loader's ``time_per_target_m3_lower_bound`` adds the meeting of loader, pile and
truck (:func:`_loader_dumps_start`). Facts the referee enforces:

- *Material stays where it was.* A cut lowers only cells above the cut level (the floor, or the
  base level) and the slump only fills cells the cut lowered, so every cell that ever holds
  material held it at the start: the set ``M`` of those cells' centres.
- *A loaded dump's charge touches ``M``.* The bucket is empty after every dump, so each loaded
  dump ``k`` has its own charge since dump ``k − 1`` that cut something: a cell whose centre
  lies in the edge's path (bucket width × penetration from the edge). At the instant the edge
  passes that centre the loader's pose is within ``r_e = hypot(bucket_offset, width / 2)`` of it.
- *A dump is near the truck.* The edge lies within ``ρ + dump_reach`` of the truck's centre, so
  the pose within ``R = bucket_offset + ρ + dump_reach``; the truck stands still meanwhile.
- *Speeds.* Every machine's path is continuous (moves start where it is, a charge at its pose)
  and it covers at most its travel speed ``v`` (the truck ``v_t``) per second, a charge at most
  the penetration speed ``v_p ≤ v``, and lasts at least ``t_c``.

So with ``M`` at least ``D_T`` from the truck's start, the truck is at least ``D_T − v_t s``
from ``M`` at time ``s``, and a dump starting at ``s`` stands at least
``g(s) = (D_T − v_t s − R − r_e)⁺`` from any point where a charge touches: the loader drives at
least ``g(s_k)`` from the touch of charge ``k`` to dump ``k``, and at least ``g(s_k)`` from dump
``k`` to the touch of charge ``k + 1`` (the first touch: at least ``D_L = (D_L0 − r_e)⁺`` from
the loader's start, ``D_L0`` its distance to ``M``). A stretch of path of length ``ℓ`` that holds
a charge of duration ``c ≥ t_c`` takes at least ``c + (ℓ − v_p c)⁺ / v ≥ t_c + (ℓ − v_p t_c)⁺ / v``.
Hence the dumps' starts satisfy ``s₁ ≥ t_c + (D_L + g(s₁) − v_p t_c)⁺ / v`` and
``s_k ≥ s_{k−1} + t_d + t_c + (g(s_{k−1}) + g(s_k) − v_p t_c)⁺ / v``. The right-hand sides fall
as ``s_k`` grows and rise with ``s_{k−1}`` (``g`` falls at most ``v_t < v`` per second), so by
induction every valid plan's ``s_k`` is at least the least ``σ_k`` these allow, and the time to
the target is at least ``σ_n + t_d`` (speeds at ``1 + RATE_TOL`` of their limits, ``ABS_TOL``
on distances and on each action's time). Once ``g`` is 0 the cycles cost ``t_c + t_d``.

What it cannot price, and why (``tests/test_loader_bound.py``): the per-cycle reverse out of the
pile and turn to the truck. A loader may scrape a strip along the pile's face with its bucket
half in it and the truck on the open floor beside the strip, within 45° of its heading; it then
dumps where the charge ended, never reverses or turns, while the truck moves on beside it during
the next charge — every cycle after the first at ``t_c + t_d`` plus a back-off of two cells. Nor
is the turning radius or a yaw rate priced: the referee's ``heading`` rule lets a machine slip
sideways by its chord tolerance per metre of chord (up to 5 % of its travel; before rules 2 it
was per sample, so steps of 4.99 cm slid a machine sideways at full speed), and a bound on a
turn would have to allow for that slip.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from shapely.geometry import Point, Polygon

from earthbench.motion import ABS_TOL, RATE_TOL
from earthbench.plan import Plan
from earthbench.referee import Verdict
from earthbench.rules import loader_base_level
from earthbench.results.scoring import time_per_target
from earthbench.results.scoring import time_to_target as scoring_time_to_target
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
    """The fewest loaded dumps after which the scoring rule (:func:`earthbench.results.scoring.time_to_target`,
    with its slack) finds ``target`` loaded when each carries at most ``capacity``; float sums of
    the digs may exceed a whole number of buckets by rounding, so a bucket counts 1e-9 fuller."""
    n = max(1, math.ceil(target / capacity) - 1)
    while not math.isfinite(scoring_time_to_target(((0.0, n * capacity * (1 + 1e-9)),), target)):
        n += 1
    return n


def _first_dump_start(scenario: Scenario) -> float:
    """The earliest start of the first loaded dump (s): the excavator digs once first (at least
    the minimum stroke), from a base within ``reach_max`` of the dig area (the contact lies in
    its bucket's footprint, on the dig area, and in reach), and the truck must be within dump
    reach (centre distance ≤ ``reach_max`` + loading radius). So the excavator drives at least
    ``A``, its start's distance to the dig area less ``reach_max``, before that dig; and whatever
    gap ``G`` the two starting poses leave, the two machines close it between them: the truck by
    driving ``L_t``, the excavator by ``L_e ≥ A`` (its driving and its dig never overlap),
    ``L_e + L_t ≥ G``. The start is at least ``max(L_e / v_e + t_s, (G − L_e)⁺ / v_t)``, least
    at ``L_e = max(A, the split where both are equal)``."""
    m = scenario.machines
    exc, truck, p, q = m.excavator, m.truck, m.excavator_pose, m.truck_pose
    assert exc is not None and p is not None
    ts = exc.min_stroke_time
    gap = math.hypot(q.x - p.x, q.y - p.y) - (exc.reach_max + truck.loading_radius + ABS_TOL)
    ve, vt = exc.travel_speed * (1 + RATE_TOL), truck.travel_speed * (1 + RATE_TOL)
    approach = max(Polygon(scenario.site.dig_area).distance(Point(p.x, p.y)) - exc.reach_max - ABS_TOL, 0.0)
    split = max((gap / vt - ts) / (1 / ve + 1 / vt), 0.0)  # the excavator's share where both take as long
    le = max(approach, split)
    return max(ts + le / ve, max(gap - le, 0.0) / vt)


def _material(scenario: Scenario) -> np.ndarray:
    """Centres ``[k, 2]`` of the cells holding material above the loader's cut level at the start
    (the floor, or the base level): no cut or slump ever puts material in any other cell."""
    level = scenario.site.floor if scenario.site.floor is not None else loader_base_level(scenario)
    xs, ys = scenario.terrain.cell_centres()
    jj, ii = np.nonzero(np.asarray(scenario.terrain.z) > level)
    return np.stack([xs[ii], ys[jj]], axis=1)


def least_time(floor: float, need: Callable[[float], float]) -> float:
    """The least ``s ≥ floor`` with ``s ≥ need(s)``, for ``need`` continuous and non-increasing
    (so the times that qualify are every time from that one on), by bisection."""
    if floor >= need(floor):
        return floor
    lo, hi = floor, need(floor)
    for _ in range(60):
        mid = (lo + hi) / 2
        lo, hi = (lo, mid) if mid >= need(mid) else (mid, hi)
    return hi


def _loader_dumps_start(scenario: Scenario, n: int) -> float:
    """The earliest start of the ``n``-th loaded dump of the one loader (s): the rendezvous of
    the module docstring. ``g(s)``, the least loader travel between a charge's touch of material
    and a dump at ``s`` (and from that dump to the next touch), is what the truck has not closed
    by ``s``; the dumps' starts ``σ_k`` are the least times the recursion allows."""
    m = scenario.machines
    lo, truck, start, stand = m.loader, m.truck, m.loader_pose, m.truck_pose
    assert lo is not None and start is not None
    cycle, tc = lo.min_charge_time + lo.min_dump_time, lo.min_charge_time
    mat = _material(scenario)
    if not len(mat):
        return n * cycle - lo.min_dump_time
    touch = math.hypot(lo.bucket_offset, lo.bucket_width / 2) + ABS_TOL  # pose to a cell its charge cuts
    dump = lo.bucket_offset + truck.loading_radius + lo.dump_reach + ABS_TOL  # pose to the truck at a dump
    v, vp, vt = (s * (1 + RATE_TOL) for s in (lo.travel_speed, lo.penetration_speed, truck.travel_speed))
    first = max(float(np.min(np.hypot(mat[:, 0] - start.x, mat[:, 1] - start.y))) - touch, 0.0)
    gap = float(np.min(np.hypot(mat[:, 0] - stand.x, mat[:, 1] - stand.y))) - touch - dump

    def g(s: float) -> float:
        return max(gap - vt * s, 0.0)

    def leg(a: float, b: float) -> float:  # a charge ≥ tc (≤ vp·its time of the way) and the travel a + b
        return tc + max(a + b - vp * tc, 0.0) / v

    s = least_time(tc, lambda x: leg(first, g(x)))
    for k in range(1, n):  # s is the k-th dump's start
        if g(s) == 0.0:  # the truck may stand at the pile from here on: every cycle as fast as a cycle can be
            return s + (n - k) * cycle
        after, back = s + lo.min_dump_time, g(s)
        s = least_time(after + tc, lambda x: after + leg(back, g(x)))  # noqa: B023 (used at once)
    return s


def lower_bound_time_to_target(scenario: Scenario) -> float:
    """The least time (s) after which any valid plan's truck holds the target.

    One excavator: ``n = ⌈target / C_eff⌉`` loaded dumps, each after a dig of its own since the
    dump before (the bucket is empty after a dump that did not fill the truck), the first
    starting no earlier than :func:`_first_dump_start`:
    ``S₁ + t_d + (n − 1)(t_s + t_d)``, less the referee's tolerance of ``ABS_TOL`` per action on
    durations and overlaps. One loader: ``σ_n + t_d`` (:func:`_loader_dumps_start`, at least
    ``n (t_c + t_d)``). Both on one site: the machines' rates add, ``target × lower_bound_time_per_m3``.
    """
    m, target = scenario.machines, scenario.task.target_volume
    fill = scenario.soil.fill_factor if scenario.soil is not None else 1.0
    if m.excavator is not None and m.loader is None:
        e = m.excavator
        n = _buckets(target, e.bucket_capacity * fill)
        t = _first_dump_start(scenario) + e.min_dump_time + (n - 1) * (e.min_stroke_time + e.min_dump_time)
        return max(t - 4 * n * ABS_TOL, 0.0)
    if m.loader is not None and m.excavator is None:
        n = _buckets(target, m.loader.bucket_capacity * fill)
        return max(_loader_dumps_start(scenario, n) + m.loader.min_dump_time - 4 * n * ABS_TOL, 0.0)
    return target * lower_bound_time_per_m3(scenario)


def time_to_target(verdict: Verdict, target: float) -> float:
    """End of the first dump after which the truck holds ``target`` m³ (s), ``inf`` if none does.

    Kept for callers of this name; the rule is :func:`earthbench.results.scoring.time_to_target`.
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
