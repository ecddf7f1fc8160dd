"""What isolation costs a case and a closed-loop step, measured in pairs (docs/isolation.md).

    python scripts/isolation_overhead.py case [PLANNER] [PAIRS]   # default greedy 10, on smoke
    python scripts/isolation_overhead.py step [PAIRS]              # default 8, s-digs on paper-extensive rbf30

On a loaded machine, two benchmark runs minutes apart differ by more than isolation costs, so
this alternates isolation on and off within one process (the order swapped every pair) and
prints the medians and the median of the paired differences. ``case``: one case's wall time
through :func:`earthbench.running.harness.run_case` (spawn, start-up, plan, judge), split into start-up,
solve and the rest. ``step``: (closed-loop run − open-loop run of the same plan) ÷ steps, per
mode. Exits with status 2 where isolation is not available (it says why).
"""

from __future__ import annotations

import dataclasses
import os
import statistics
import sys
import time
from pathlib import Path

from earthbench.running.harness import build_cases, isolation, run_case
from earthbench.results.records import PlannerRef
from earthbench.registry import load_plugin_file
from earthbench.results.suite import load_suite

STEPS = str(Path(__file__).resolve().parents[1] / "tests" / "plugins" / "step_planners.py")


def mode(on: bool) -> None:
    if on:
        os.environ.pop(isolation.SWITCH, None)
    else:
        os.environ[isolation.SWITCH] = "off"
    isolation.support.cache_clear()
    isolation.support()  # the probe (a sandboxed `python -c pass`) is once per process: not timed


def pairs(n: int):
    for i in range(n):
        yield from ((True, False) if i % 2 == 0 else (False, True))


def case(planner: str, n: int) -> None:
    (c, *_), _ = build_cases(load_suite("smoke"), [planner])
    parts: dict[bool, list[tuple[float, ...]]] = {True: [], False: []}
    for on in (True, False):  # warm-up
        mode(on)
        run_case(c)
    for on in pairs(n):
        mode(on)
        t = time.perf_counter()
        r = run_case(c)
        wall = time.perf_counter() - t
        assert r.reason == "ok", r.error
        parts[on].append((wall, r.startup_s or 0.0, r.solve_time_s or 0.0))
    diff = [a[0] - b[0] for a, b in zip(parts[True], parts[False])]
    for on in (True, False):
        wall, start, solve = (statistics.median(x) for x in zip(*parts[on]))
        print(f"isolation {'on ' if on else 'off'}: {planner} case {wall * 1e3:.0f} ms (start-up {start * 1e3:.0f}, "
              f"solve {solve * 1e3:.0f}, rest {(wall - start - solve) * 1e3:.0f}), median of {n}")
    print(f"paired difference (on − off): median {statistics.median(diff) * 1e3:.0f} ms")


def step(n: int) -> None:
    load_plugin_file(STEPS)
    cases, _ = build_cases(load_suite("paper-extensive"), ["s-digs"], plugins=[STEPS])
    closed = max((c for c in cases if c.scenario.meta.get("family") == "rbf30"), key=lambda c: c.scenario.task.target_volume)
    opened = dataclasses.replace(closed, planner=PlannerRef.resolve("s-digs", {"closed_loop": False}))

    def wall(c):
        t = time.perf_counter()
        r = run_case(c)
        assert r.reason == "ok", r.error
        return time.perf_counter() - t, r

    per: dict[bool, list[float]] = {True: [], False: []}
    for on in (True, False):
        mode(on)
        wall(closed)
    for on in pairs(n):
        mode(on)
        wc, r = wall(closed)
        wo, _ = wall(opened)
        per[on].append((wc - wo) / r.metrics["steps"])
    print(f"{closed.scenario.id}, {r.metrics['steps']} steps: overhead per step, isolation on "
          f"{statistics.median(per[True]) * 1e3:.1f} ms, off {statistics.median(per[False]) * 1e3:.1f} ms (medians of {n})")


def main(argv: list[str]) -> int:
    if not argv or argv[0] not in ("case", "step"):
        print(__doc__.strip(), file=sys.stderr)
        return 2
    if not isolation.support().full:
        print(isolation.describe(), file=sys.stderr)
        return 2
    print(isolation.describe(), f"(load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")
    if argv[0] == "case":
        case(argv[1] if len(argv) > 1 else "greedy", int(argv[2]) if len(argv) > 2 else 10)
    else:
        step(int(argv[1]) if len(argv) > 1 else 8)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
