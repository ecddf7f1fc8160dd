"""What a case that floods its pipes costs the harness (docs/isolation.md, "Nothing after the result").

    python scripts/protocol_flood.py [PLANNER ...]   # default h-after-result h-blank-lines h-log-flood

Runs each hostile planner of ``tests/plugins/hostile_planners.py`` as one case (a 30 s wall
budget) and prints its termination reason, the CPU seconds this process (the harness) spent on
it, the case's wall time and solve CPU, and the start of its error. Run it with another
install's interpreter (its own earthbench, this checkout's plugin file) to compare two versions.
"""

from __future__ import annotations

import resource
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
PLUGIN = str(HERE / "tests" / "plugins" / "hostile_planners.py")
sys.path.insert(0, str(HERE / "tests"))

from helpers import tiny_suite_toml  # noqa: E402

from earthbench.running.harness import build_cases, run_case  # noqa: E402
from earthbench.registry import load_plugin_file  # noqa: E402
from earthbench.results.suite import parse_suite  # noqa: E402


def cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def main(names: list[str]) -> int:
    load_plugin_file(PLUGIN)
    for name in names or ["h-after-result", "h-blank-lines", "h-log-flood"]:
        (case,), _ = build_cases(parse_suite(tiny_suite_toml("flood", wall_s=30.0)), [name], plugins=[PLUGIN])
        c0, t0 = cpu(), time.monotonic()
        res = run_case(case)
        print(f"{name}: {res.reason}, harness CPU {cpu() - c0:.2f} s, wall {time.monotonic() - t0:.1f} s, "
              f"solve CPU {res.solve_cpu_s or 0:.3f} s; {res.error[:90]!r}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
