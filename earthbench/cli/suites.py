"""``earthbench suites``: the registered suites, or one suite's scenarios and digest."""

from __future__ import annotations

import argparse

from ..results.suite import known_suites, load_suite


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("suites", help="list the registered suites, or show one suite's scenarios")
    p.add_argument("suite", nargs="?", help="a suite name or file: list its scenarios and digest")
    return p


def run(args: argparse.Namespace) -> int:
    if args.suite:
        s = load_suite(args.suite)
        print(f"{s.name}: {s.description}")
        print(f"  file {s.path}\n  track {s.track}, threshold {s.success_threshold:g}, budget {s.budget.wall_s:g} s, "
              f"{s.budget.cores} cores, {s.budget.memory_mb} MB")
        print(f"  planners {', '.join(s.planners) if s.planners else '(every planner of the track)'}")
        print(f"  digest {s.digest}")
        for sc in s.scenarios:
            over = f"  (the truck holds {sc.truck_holds:.2f}: no plan reaches it)" if sc.truck_holds < sc.task.target_volume else ""
            print(f"  {sc.id:<40} {sc.digest[:12]}  target {sc.task.target_volume:g} m³{over}")
        return 0
    suites = known_suites()
    width = max((len(n) for n in suites), default=0)  # the longest name sets the column: no row pushed out of line
    for name, path in suites.items():
        try:
            s = load_suite(path)
            n = sum(len(f.targets) * len(f.seeds) for f in s.families)
            print(f"  {name:<{width}}  {s.track:<12}  {n:>4} scenarios  {s.description}")
        except Exception as exc:  # noqa: BLE001 - one broken file must not hide the others
            print(f"  {name:<{width}}  BROKEN: {exc}")
    return 0
