"""Speed of the referee, today's against the referee before the motion model and footprints.

Goals: replay of a 30-dig plan on the 12 m × 6 m map at 0.05 m cells ≤ 10 ms, of a loader plan
on ``pile`` ≤ 30 ms, and continuous clearance (the motion model, swept paths, footprints) at
most 20 % over the replay before it. The baseline is the referee as it was at commit
``BASELINE`` (read from git history), judged on the same scenario and plan in the same run.
Run with ``pytest tests/bench/test_bench_referee.py --benchmark-only``.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import types
from pathlib import Path

import pytest

from earthbench import judge
from earthbench_planners.greedy.backhoe import GreedyPlanner
from earthbench_planners.singh_cannon.loader import SinghCannonLoader
from earthbench_terrains.pile import pile
from earthbench_terrains.rbf import rbf

BASELINE = "e1318948ddbaee0900a8fda12989cf90f5230e77"  # the point-machine, chord referee
ROOT = Path(__file__).resolve().parents[2]


def _baseline_judge():
    """``judge`` of the referee at ``BASELINE``, loaded from git history as a module."""
    if shutil.which("git") is None:
        pytest.skip("git is needed to read the baseline referee")
    try:
        src = subprocess.run(
            ["git", "-C", str(ROOT), "show", f"{BASELINE}:earthbench/referee.py"], check=True, capture_output=True, text=True
        ).stdout
    except subprocess.CalledProcessError:
        pytest.skip("the baseline commit is not in this clone's history")
    mod = types.ModuleType("earthbench._baseline_referee")
    mod.__package__ = "earthbench"
    sys.modules[mod.__name__] = mod
    exec(compile(src, "baseline referee.py", "exec"), mod.__dict__)
    return mod.judge


@pytest.fixture(scope="module")
def backhoe_case():
    sc = rbf(0, 30 * 0.28 * 0.97, n_bases=30)
    plan = GreedyPlanner().plan(sc)
    assert 29 <= sum(a.kind == "dig" for a in plan.actions) <= 32
    return sc, plan


@pytest.fixture(scope="module")
def loader_case():
    sc = pile(0, 4.0)
    return sc, SinghCannonLoader().plan(sc)


@pytest.mark.parametrize("referee", ["today", "baseline"])
def test_replay_30_digs(benchmark, backhoe_case, referee):
    sc, plan = backhoe_case
    fn = judge if referee == "today" else _baseline_judge()
    verdict = benchmark(fn, sc, plan)
    assert verdict.valid
    benchmark.extra_info["actions"] = len(plan.actions)


@pytest.mark.parametrize("referee", ["today", "baseline"])
def test_replay_loader_pile(benchmark, loader_case, referee):
    sc, plan = loader_case
    fn = judge if referee == "today" else _baseline_judge()
    verdict = benchmark(fn, sc, plan)
    assert verdict.valid
    benchmark.extra_info["actions"] = len(plan.actions)


def test_greedy_plan_7m3(benchmark):
    sc = rbf(0, 7.0, n_bases=30)
    plan = benchmark(GreedyPlanner().plan, sc)
    assert judge(sc, plan).valid
