"""A metric plugin: how ``stl-tamp``'s (and ``separate``'s) local NLP solves ended.

These are the planner's own report (``plan.info["local_solves"]``, from IPOPT's return status),
not a referee figure: the names say so (``planner_reported_…``). The referee never sees them and
no ranking uses them; they are stored so that convergence can be followed run by run. A plan
whose ``info`` lacks the counts, or holds anything but non-negative integers there, adds nothing.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from earthbench.plan import Plan
from earthbench.world import Scenario

if TYPE_CHECKING:  # a metric reads the verdict it is given; it never calls the judge
    from earthbench import Verdict

KINDS = ("succeeded", "acceptable", "capped", "fallback", "total")


def local_solve_counts(scenario: Scenario, plan: Plan, verdict: Verdict) -> dict[str, Any]:
    """``planner_reported_local_<kind>`` for each kind of :func:`.hierarchy.solve_counts`, and
    the share that ended Solve_Succeeded."""
    info = plan.info if isinstance(plan.info, dict) else {}
    counts = info.get("local_solves")
    if not isinstance(counts, dict):
        return {}
    vals = {k: counts.get(k) for k in KINDS}
    if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in vals.values()):
        return {}
    out: dict[str, Any] = {f"planner_reported_local_{k}": v for k, v in vals.items()}
    out["planner_reported_local_succeeded_share"] = vals["succeeded"] / vals["total"] if vals["total"] else None
    return out
