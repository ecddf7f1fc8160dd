"""``earthbench merge OUT.db IN.db…``: merge results stores gathered on several machines.

Refuses (writing nothing) when a run is in two stores (same scenario digest, planner,
version and config hash) or when a suite name has different digests in different stores;
otherwise copies every suite, scenario, configuration, environment and run into OUT.db
(created if missing) through the store's API, one transaction per run.
"""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("merge", help="merge results databases, refusing duplicates and mismatched suite digests",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("out", metavar="OUT.db", help="database to merge into (created if missing)")
    p.add_argument("inputs", nargs="+", metavar="IN.db", help="databases to merge")
    return p


def run(args: argparse.Namespace) -> int:
    from ..merge import merge

    report = merge(args.out, args.inputs)
    for path, n in report.per_input.items():
        print(f"{path}: {n} run(s)")
    print(f"merged {report.runs} run(s) and {report.suites} new suite version(s) into {args.out}")
    return 0
