"""singh-cannon-backhoe 1.7: a station the truck can get to where 1.6 gave up (planners/singh_cannon/README.md)."""

from __future__ import annotations

from earthbench import judge
from earthbench.results.scoring import evaluate
from earthbench.results.suite import load_suite
from earthbench.sensing import observe
from earthbench_planners.singh_cannon.backhoe import SinghCannonBackhoe


def test_a_large_site_where_the_truck_cannot_serve_the_best_stations_reaches_its_target():
    """On this 64 m³ `scale` site the truck could serve none of the best stations from the corner
    where it stood (it drives straight lines, off the dig area); 1.6 ended "no feasible dig left"
    at 9 % of the target. 1.7 moves to a station in reach of the truck's line instead."""
    sc = next(s for s in load_suite("scale").scenarios if s.id == "scale/rbf48x24/s8/v64")
    plan = SinghCannonBackhoe().plan(observe(sc))
    assert plan.info["status"] == "target reached"
    assert any("further" in ev for ev in plan.info["events"] if ev["event"] == "move")
    verdict = judge(sc, plan)
    assert verdict.valid, verdict.violations[:3]
    assert evaluate(sc, plan, verdict, 0.9)["volume_ratio"] >= 1.0
