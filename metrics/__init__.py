"""Per-run metrics and lower bounds, aggregation over suites (`aggregate`) and performance profiles (`profiles`).

Metrics are measured by the referee and the harness, never taken from a planner's claims.
Each metric plugin is a callable ``(scenario, plan, verdict) -> dict[str, float]`` registered
in the ``earthbench.metrics`` entry-point group; :func:`evaluate` merges them all.
"""

from .run import DEFAULT_SUCCESS_THRESHOLD, core_metrics, evaluate, lower_bound_time_per_m3

__all__ = ["DEFAULT_SUCCESS_THRESHOLD", "core_metrics", "evaluate", "lower_bound_time_per_m3"]
