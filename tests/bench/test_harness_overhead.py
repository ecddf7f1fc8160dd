"""Harness overhead per case: spawn a fenced subprocess, import, plan (instantly), judge, store.

Goal (issue 18): median under 0.5 s on 2 cores; with isolation (issue 33) at most 0.25 s,
measured side by side with isolation off in one run (the ``isolation`` fixture). Run with
``python -m pytest tests/bench/test_harness_overhead.py --benchmark-only``.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from earthbench.registry import load_plugin_file
from earthbench.running.harness import build_cases, run_case
from earthbench.results.store import Store
from earthbench.results.suite import load_suite

PLUGIN = str(Path(__file__).parents[1] / "plugins" / "faulty_planners.py")


pytestmark = pytest.mark.usefixtures("forget_test_planners", "compiled_bytecode")


@pytest.mark.parametrize("planner", ["t-fast", "greedy", "singh-cannon-backhoe"])
def test_overhead_per_case(benchmark, tmp_path, planner, isolation):
    load_plugin_file(PLUGIN)
    suite = load_suite("smoke")
    cases, _ = build_cases(suite, [planner], plugins=[PLUGIN])
    case = cases[0]
    store = Store(tmp_path / "bench.db")
    store.register_suite(suite)

    def one() -> str:
        result = run_case(case)
        store.record(case, result, replace=True)
        assert result.isolation == isolation
        return result.reason

    assert benchmark.pedantic(one, rounds=10, iterations=1, warmup_rounds=1) == "ok"
    store.close()
