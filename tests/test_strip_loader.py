"""strip-loader (planners/strip_loader): a strip along the pile with the truck beside it where one
fits, greedy-loader's cycles elsewhere. Its plans are judged by the referee on generated piles:
valid, at the target, never below the loader bound (docs/metrics.md, "What the geometry
forces"), and on these seeds within 2 × the bound at 4 m³."""

from __future__ import annotations

import pytest

from earthbench import Charge, Dump, Move, judge
from earthbench.results.scoring import evaluate, time_to_target
from earthbench_metrics import lower_bound_time_to_target
from earthbench_planners.greedy.loader import GreedyLoader
from earthbench_planners.strip_loader.planner import StripLoader
from earthbench_terrains.pile import pile


@pytest.mark.parametrize("seed,target,within", [(0, 4.0, 2.0), (8, 4.0, 1.8), (8, 2.0, 2.1)])
def test_a_strip_loads_the_target_with_the_truck_moving_beside_it(seed, target, within):
    """The loader never turns between charges (one heading, only the back-off along it), the
    truck drives once to its first stand and on before each further dump, and the plan is valid
    between the bound and ``within`` × it (greedy-loader on these: 3.93, 3.72, 2.92 ×)."""
    sc = pile(seed, target)
    plan = StripLoader().plan(sc)
    assert plan.info["strip"]
    v = judge(sc, plan)
    assert v.valid, v.violations[:3]
    ratio = time_to_target(v.load_curve, target) / lower_bound_time_to_target(sc)
    assert 1.0 <= ratio < within
    assert evaluate(sc, plan, v)["time_per_target_m3_bound_ratio"] == pytest.approx(ratio)
    charges = [a for a in plan.actions if isinstance(a, Charge)]
    dumps = [a for a in plan.actions if isinstance(a, Dump)]
    assert len(charges) == len(dumps) >= round(target / sc.machines.loader.bucket_capacity)
    assert len({round(c.entry[2], 9) for c in charges}) == 1
    truck = [a for a in plan.actions if isinstance(a, Move) and a.machine == "truck"]
    assert len(truck) == len(dumps)


def test_where_no_strip_fits_it_plans_greedy_loaders_cycles():
    """A wall running to 1.5 m from the map's edges: no room for the truck beside a strip along
    its ends, and no strip along the face starts with the wheels on the floor."""
    sc = pile(0, 2.0, wall=(1.5, 18.5))
    plan = StripLoader().plan(sc)
    assert not plan.info.get("strip")
    assert plan.actions == GreedyLoader().plan(sc).actions
    v = judge(sc, plan)
    assert v.valid and v.loaded_volume >= 2.0 - 1e-6
