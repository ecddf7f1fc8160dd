"""The step protocol's overhead per step (issue 20's goal: ≤ 20 ms per step).

A planner that costs nothing per step (``s-digs``: greedy's plan, computed at the first step,
handed out one dig cycle per step) runs one paper-extensive scenario closed loop and, as the
baseline, open loop (the same plan in one call). What the closed loop costs beyond the open
loop, divided by its steps, is the harness's overhead per step: executing the step on the
truth (the referee judges the executed prefix), building and sending the observation, the
planner process reading it, freezing and thawing the case's cgroup (isolation on; the
``isolation`` fixture runs each side by side with it off) — and, on the realistic suite, the scan each observation holds
(``earthbench.sensing.observe``, the sensing model's own cost). Run with
``python -m pytest tests/bench/test_bench_closed_loop.py --benchmark-only -s``.
"""

from __future__ import annotations

import dataclasses
import statistics
import time
from pathlib import Path

import pytest

from earthbench.running.harness import build_cases, run_case
from earthbench.results.records import PlannerRef
from earthbench.registry import load_plugin_file
from earthbench.results.suite import load_suite

PLUGIN = str(Path(__file__).parents[1] / "plugins" / "step_planners.py")

pytestmark = pytest.mark.usefixtures("forget_test_planners")


@pytest.mark.parametrize("suite_name, family", [
    ("paper-extensive", "rbf30"),  # the exact world: the protocol's own cost
    ("paper-extensive-realistic", "rbf30-sand-survey"),  # plus a survey scan per step (earthbench.sensing)
    ("paper-extensive-realistic", "rbf30-sand-cab"),  # plus a cab scan with occlusion per step
])
def test_overhead_per_step(benchmark, suite_name, family, isolation):
    load_plugin_file(PLUGIN)
    suite = load_suite(suite_name)
    cases, _ = build_cases(suite, ["s-digs"], plugins=[PLUGIN])
    case = max((c for c in cases if c.scenario.meta.get("family") == family), key=lambda c: c.scenario.task.target_volume)
    closed = case
    opened = dataclasses.replace(case, planner=PlannerRef.resolve("s-digs", {"closed_loop": False}))

    def wall(c) -> tuple[float, object]:
        t0 = time.monotonic()
        r = run_case(c)
        return time.monotonic() - t0, r

    base = [wall(opened) for _ in range(5)]
    assert all(r.reason == "ok" for _, r in base)
    result = benchmark.pedantic(lambda: run_case(closed), rounds=5, iterations=1, warmup_rounds=1)
    assert result.reason == "ok" and result.metrics["volume_ratio"] == base[0][1].metrics["volume_ratio"]
    steps = result.metrics["steps"]
    per_step = (benchmark.stats.stats.median - statistics.median(w for w, _ in base)) / steps
    benchmark.extra_info.update(steps=steps, overhead_per_step_ms=per_step * 1e3)
    print(f"\n[isolation {isolation}] {case.scenario.id}: {steps} steps, closed {benchmark.stats.stats.median:.3f} s, "
          f"open {statistics.median(w for w, _ in base):.3f} s, overhead {per_step * 1e3:.1f} ms per step")
