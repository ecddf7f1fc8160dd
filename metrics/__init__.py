"""The built-in metric plugin (entry point ``earthbench.metrics: core``) and the lower bounds it uses.

Metrics are measured by the referee and the harness, never taken from a planner's claims.
Each metric plugin is a callable ``(scenario, plan, verdict) -> dict[str, float]`` registered
in the ``earthbench.metrics`` entry-point group; :func:`earthbench.results.scoring.evaluate` merges them all.
"""

from .run import core_metrics, least_time, lower_bound_time_per_m3, lower_bound_time_to_target, time_to_target

__all__ = ["core_metrics", "least_time", "lower_bound_time_per_m3", "lower_bound_time_to_target", "time_to_target"]
