"""What a sandbox adds to starting a case (docs/DESIGN.md §6, "Why bubblewrap"): the wall time of
``python3 -c pass`` run bare, under bubblewrap with a case's namespaces and filesystem view, and
under BenchExec's ``RunExecutor`` in container mode, in the calling process as a harness would
use it. Needs ``pip install benchexec`` beside earthbench (not one of its dependencies).

    python scripts/sandbox_startup.py [RUNS]

Prints the median, min and max of RUNS runs (default 15, after one warm-up) per way.
"""

from __future__ import annotations

import logging
import statistics
import subprocess
import sys
import time
from collections.abc import Callable

from earthbench.running.harness.isolation import bwrap_binary, bwrap_args, visible_paths

CMD = ["/usr/bin/python3", "-c", "pass"]


def timed(run: Callable[[], object], n: int) -> list[float]:
    run()  # warm-up
    out = []
    for _ in range(n):
        t = time.perf_counter()
        run()
        out.append(time.perf_counter() - t)
    return out


def main(argv: list[str]) -> int:
    n = int(argv[0]) if argv else 15
    ways: dict[str, Callable[[], object]] = {"bare": lambda: subprocess.run(CMD, check=True)}
    bwrap = bwrap_binary()
    if bwrap:  # a case's own command line (earthbench.running.harness.isolation.bwrap_args), without its cgroup
        args = bwrap_args(bwrap, visible_paths(), 64 << 20)
        ways["bubblewrap, a case's namespaces"] = lambda: subprocess.run([*args, *CMD], check=True)
    try:
        from benchexec.container import DIR_HIDDEN, DIR_READ_ONLY
        from benchexec.runexecutor import RunExecutor

        logging.disable(logging.WARNING)
        rx = RunExecutor(use_namespaces=True, dir_modes={"/": DIR_READ_ONLY, "/tmp": DIR_HIDDEN, "/home": DIR_HIDDEN})
        ways["BenchExec RunExecutor, container"] = lambda: rx.execute_run(CMD, output_filename="/dev/null")
    except ImportError:
        print("benchexec is not installed: pip install benchexec", file=sys.stderr)
    for name, run in ways.items():
        ts = timed(run, n)
        print(f"{name}: median {1000 * statistics.median(ts):.1f} ms (min {1000 * min(ts):.1f}, max {1000 * max(ts):.1f}), n={n}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
