"""A hostile wrapper from issue 35: greedy's plan cut at the first dump that reaches the success
threshold (0.9 × the target). Under the old time per target m³ it ranked first alone, because
a plan's last buckets are its dearest; under the scoring rule it must rank below greedy."""

from __future__ import annotations

from earthbench import Plan
from earthbench.referee import judge
from earthbench_planners.greedy.backhoe import GreedyPlanner


class TruncatedGreedy(GreedyPlanner):
    """Greedy, stopped as soon as the truck holds 0.9 × the target."""

    name = "h-truncated-greedy"

    def plan(self, scenario):
        plan = super().plan(scenario)
        goal = 0.9 * scenario.task.target_volume
        cut = next((t for t, loaded in judge(scenario, plan).load_curve if loaded >= goal), None)
        if cut is None:
            return plan
        return Plan(tuple(a for a in plan.actions if a.t_end <= cut))
