"""Case start-up per built-in planner: a fresh interpreter importing the planner and making it,
as a case process does before its solve starts. Goal (issue 18): ≤ 0.3 s each.

Two baselines run next to them, so the planner's own share can be read off: the bare
interpreter and the earthbench core (``import earthbench``: numpy, shapely, the referee).
Run with ``python -m pytest tests/bench/test_planner_startup.py --benchmark-only``; the
modules are byte-compiled first, as in an installed wheel (``compiled_bytecode``).
"""

from __future__ import annotations

import resource
import statistics
import subprocess
import sys
from importlib.metadata import entry_points

import pytest

BUILT_IN = sorted((e.name, e.value) for e in entry_points(group="earthbench.planners") if e.value.startswith("earthbench_planners."))
BASELINES = [("interpreter", "pass"), ("earthbench core", "import earthbench")]


def _code(target: str) -> str:
    """What a case's process runs before it says it is ready: the bootstrap loads the planner's class, which is made."""
    return f"from earthbench.running.harness.child import load_planner_class; load_planner_class({target!r}, 'x')()"


pytestmark = pytest.mark.usefixtures("compiled_bytecode")


@pytest.mark.parametrize(("what", "code"), BASELINES + [(name, _code(t)) for name, t in BUILT_IN],
                         ids=[b[0] for b in BASELINES] + [name for name, _ in BUILT_IN])
def test_startup(benchmark, what, code):
    cpu: list[float] = []

    def start() -> int:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        code_ = subprocess.run([sys.executable, "-c", code], check=True).returncode
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu.append(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)
        return code_

    assert benchmark.pedantic(start, rounds=7, iterations=1, warmup_rounds=1) == 0
    # CPU time as well: on a shared machine it moves less with the load than the wall time does
    benchmark.extra_info["cpu_s_median"] = statistics.median(cpu)
    print(f"\n{what}: CPU {statistics.median(cpu):.3f} s median")
