"""One case and one closed-loop step, this checkout's harness against another's, in pairs.

    python scripts/harness_side_by_side.py OTHER_PYTHON OTHER_CHECKOUT [CASE_PAIRS] [STEP_PAIRS]
    # e.g. .venv/bin/python scripts/harness_side_by_side.py /work/venv/bin/python /work/main 20 10

Each side is a long-lived worker process of its own install (its interpreter, its checkout as
the working folder) that runs greedy's first ``smoke`` case, or s-digs closed and open loop on
paper-extensive's largest rbf30 scenario ((closed − open) ÷ steps: what a step costs the
harness). The sides alternate within each pair, the order swapped every pair, so the machine's
load falls on both alike; prints the medians and the median paired difference. Isolation is
as each machine allows (the same for both).
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
from pathlib import Path

WORKER = r'''
import dataclasses, sys, time
from pathlib import Path
from earthbench.running.harness import build_cases, run_case
from earthbench.results.records import PlannerRef
from earthbench.registry import load_plugin_file
from earthbench.results.suite import load_suite
(case, *_), _ = build_cases(load_suite("smoke"), ["greedy"])
steps = str(Path("tests/plugins/step_planners.py").resolve())
load_plugin_file(steps)
cases, _ = build_cases(load_suite("paper-extensive"), ["s-digs"], plugins=[steps])
closed = max((c for c in cases if c.scenario.meta.get("family") == "rbf30"), key=lambda c: c.scenario.task.target_volume)
opened = dataclasses.replace(closed, planner=PlannerRef.resolve("s-digs", {"closed_loop": False}))
def wall(c):
    t = time.perf_counter(); r = run_case(c); assert r.reason == "ok", r.error
    return time.perf_counter() - t, r
wall(case); wall(closed)
print("ready", flush=True)
for line in sys.stdin:
    if line.strip() == "case":
        print(wall(case)[0], flush=True)
    else:
        wc, r = wall(closed); wo, _ = wall(opened)
        print((wc - wo) / r.metrics["steps"], flush=True)
'''


def main(argv: list[str]) -> int:
    if len(argv) < 2:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    sides = {"this": (sys.executable, str(Path(__file__).resolve().parents[1])), "other": (argv[0], argv[1])}
    workers = {k: subprocess.Popen([py, "-c", WORKER], cwd=cwd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
               for k, (py, cwd) in sides.items()}
    for w in workers.values():
        assert w.stdout is not None and w.stdout.readline().strip() == "ready"

    def ask(side: str, kind: str) -> float:
        w = workers[side]
        assert w.stdin is not None and w.stdout is not None
        w.stdin.write(kind + "\n")
        w.stdin.flush()
        return float(w.stdout.readline())

    for kind, n in (("case", int(argv[2]) if len(argv) > 2 else 20), ("step", int(argv[3]) if len(argv) > 3 else 10)):
        got: dict[str, list[float]] = {"this": [], "other": []}
        for i in range(n):
            for side in ("other", "this") if i % 2 == 0 else ("this", "other"):
                got[side].append(ask(side, kind))
        diff = [a - b for a, b in zip(got["this"], got["other"])]
        what = "a case" if kind == "case" else "a closed-loop step"
        print(f"{what}: this {statistics.median(got['this']) * 1e3:.1f} ms, other {statistics.median(got['other']) * 1e3:.1f} ms, "
              f"paired difference (this − other) median {statistics.median(diff) * 1e3:+.1f} ms "
              f"({n} pairs, load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)", flush=True)
    for w in workers.values():
        assert w.stdin is not None
        w.stdin.close()
        w.wait()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
