"""``earthbench export --suite S --planner P OUT.db``: a submission bundle of one planner's runs.

Writes one new SQLite file (a results store) holding the runs of the planner(s) on the suite
with their plans, the scenario documents, the planner configurations, the environments they
ran in and the suite versions they are labelled with: everything ``earthbench merge`` needs to
re-judge them on another machine, and ``earthbench verify`` to re-time a sample.
"""

from __future__ import annotations

import argparse
import shlex

from ..results.store import default_db
from ._common import plain


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("export", help="write a submission bundle: a planner's runs on a suite, verifiable by merge",
                       description=plain(__doc__), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("out", metavar="OUT.db", help="the bundle to write (must not exist)")
    p.add_argument("--db", default=default_db(), metavar="PATH", help="results database to export from")
    p.add_argument("--suite", required=True, help="the suite whose runs to export")
    p.add_argument("--planner", action="append", required=True, metavar="NAME", help="planner to export (repeatable)")
    return p


def run(args: argparse.Namespace) -> int:
    from ..publishing.merge import export

    report = export(args.db, args.out, args.suite, args.planner)
    print(f"exported {report.runs} run(s) of {', '.join(args.planner)} on {args.suite} into {args.out}; "
          f"merge it with `earthbench merge ALL.db {shlex.quote(str(args.out))}`")
    return 0
