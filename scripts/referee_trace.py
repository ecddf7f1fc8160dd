"""How often one judgement enters each module of the referee (issue 52, docs/DESIGN.md §5, "One
loop, a plain state"): greedy's 30-dig plan on ``rbf`` seed 0 (the case of
``tests/bench/test_bench_referee.py``), judged once under :func:`sys.setprofile`.

A module is *entered* when a function of it is called from a function of another module; each
door counts once, however often it is used: the count is the number of distinct (calling
function, called function) pairs that cross into the module. A rule module the replay loop calls
once per action counts one door, a module the rules call back into counts one per place it is
called from. Methods that :mod:`dataclasses` writes (a value's ``__init__``, its ``__eq__``) hold
no rule and are left out. Also printed: every crossing as it happened (``calls``), and which
modules the judgement visits.

    python scripts/referee_trace.py [--all] [--doors] [--loader]

``--all``: every earthbench module entered, not only the referee's and the cut model; ``--doors``:
each door with how often it was used; ``--loader``: singh-cannon-loader's plan on ``pile`` seed 0.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from types import FrameType
from typing import Any

#: The modules whose doors the goal counts (issue 52: each at most two), and the libraries they call.
WATCHED = ("earthbench.referee", "earthbench.cut")


def _module(frame: FrameType) -> str:
    return str(frame.f_globals.get("__name__", "?"))


def trace(judge: Any, scenario: Any, plan: Any) -> tuple[Counter[tuple[str, str, str]], Counter[str]]:
    """Doors (callee module, caller, callee) and crossings per callee module during ``judge(scenario, plan)``."""
    doors: Counter[tuple[str, str, str]] = Counter()
    crossings: Counter[str] = Counter()

    def profile(frame: FrameType, event: str, arg: Any) -> None:
        if event != "call" or frame.f_back is None or frame.f_code.co_filename == "<string>":
            return
        callee, caller = _module(frame), _module(frame.f_back)
        if callee == caller or not callee.startswith("earthbench") or caller == __name__:
            return
        where = frame.f_back.f_code.co_qualname.split(".<locals>")[0]  # a comprehension or lambda counts as its function
        doors[(callee, f"{caller}.{where}", frame.f_code.co_qualname)] += 1
        crossings[callee] += 1

    sys.setprofile(profile)
    try:
        judge(scenario, plan)
    finally:
        sys.setprofile(None)
    return doors, crossings


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--all", action="store_true", help="every earthbench module entered, not only the referee's and the cut model")
    ap.add_argument("--doors", action="store_true", help="list each door")
    ap.add_argument("--loader", action="store_true", help="singh-cannon-loader's plan on pile seed 0 instead")
    args = ap.parse_args()
    from earthbench import judge

    if args.loader:
        from earthbench_planners.singh_cannon.loader import SinghCannonLoader
        from earthbench_terrains.pile import pile

        sc = pile(0, 4.0)
        plan = SinghCannonLoader().plan(sc)
    else:
        from earthbench_planners.greedy.backhoe import GreedyPlanner
        from earthbench_terrains.rbf import rbf

        sc = rbf(0, 30 * 0.28 * 0.97, n_bases=30)
        plan = GreedyPlanner().plan(sc)
    judge(sc, plan)  # once before, so that first-use imports are not counted
    doors, crossings = trace(judge, sc, plan)
    per_module = Counter(m for m, _, _ in doors)
    digs = sum(1 for a in plan.actions if type(a).__name__ in ("Dig", "Charge"))
    print(f"one judgement of a {digs}-dig plan ({len(plan.actions)} actions): {len(per_module)} modules entered")
    print(f"{'module':32} {'entered':>7} {'calls':>7}")
    for module in sorted(per_module):
        if args.all or module.startswith(WATCHED):
            print(f"{module:32} {per_module[module]:>7} {crossings[module]:>7}")
            if args.doors:
                for (m, caller, callee), n in sorted(doors.items()):
                    if m == module:
                        print(f"    {caller} -> {callee} ({n}×)")


if __name__ == "__main__":
    main()
