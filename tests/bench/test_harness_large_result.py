"""Reading a large result: the harness's time to take in a case's result of 12, 24 and 48 MB.

Run with ``python -m pytest tests/bench/test_harness_large_result.py --benchmark-only``; the
time should grow linearly with the size (the referee's time on the plan is included, and small
here: the plan has no actions, only a large ``info`` field).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from earthbench.running.harness import build_cases, run_case
from earthbench.registry import load_plugin_file
from earthbench.results.suite import parse_suite

from helpers import tiny_suite_toml

PLUGIN = str(Path(__file__).parents[1] / "plugins" / "hostile_planners.py")

pytestmark = pytest.mark.usefixtures("forget_test_planners")


@pytest.mark.parametrize("mb", [12, 24, 48])
def test_large_result(benchmark, monkeypatch, mb):
    monkeypatch.setenv("EARTHBENCH_TEST_RESULT_MB", str(mb))
    load_plugin_file(PLUGIN)
    (case,), _ = build_cases(parse_suite(tiny_suite_toml("big", wall_s=60.0)), ["h-big-result"], plugins=[PLUGIN])
    result = benchmark.pedantic(lambda: run_case(case), rounds=3, iterations=1)
    assert result.reason == "ok", result.error
