"""A metric plugin: how ``stl-tamp``'s (and ``separate``'s) local NLP solves ended, and which
solver took every solve (FATROP, IPOPT, and FATROP's failures IPOPT solved again).

These are the planner's own report (``plan.info["local_solves"]`` from the solvers' return
status, ``plan.info["solvers"]``),
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


SOLVERS = ("fatrop", "ipopt", "fallback")


def _counts(info: dict[str, Any], key: str, kinds: tuple[str, ...]) -> dict[str, int] | None:
    counts = info.get(key)
    if not isinstance(counts, dict):
        return None
    vals = {k: counts.get(k) for k in kinds}
    if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in vals.values()):
        return None
    return vals  # type: ignore[return-value]


def local_solve_counts(scenario: Scenario, plan: Plan, verdict: Verdict) -> dict[str, Any]:
    """``planner_reported_local_<kind>`` for each kind of :func:`.hierarchy.solve_counts`, and
    the share that ended Solve_Succeeded; ``planner_reported_solves_<solver>`` (every solve,
    global and local) and the share of FATROP's solves that fell back to IPOPT."""
    info = plan.info if isinstance(plan.info, dict) else {}
    out: dict[str, Any] = {}
    vals = _counts(info, "local_solves", KINDS)
    if vals is not None:
        out.update({f"planner_reported_local_{k}": v for k, v in vals.items()})
        out["planner_reported_local_succeeded_share"] = vals["succeeded"] / vals["total"] if vals["total"] else None
    solvers = _counts(info, "solvers", SOLVERS)
    if solvers is not None:
        out.update({f"planner_reported_solves_{k}": v for k, v in solvers.items()})
        out["planner_reported_fallback_share"] = solvers["fallback"] / solvers["fatrop"] if solvers["fatrop"] else None
    return out
