"""``earthbench compare DB_A [DB_B]``: paired per-metric differences of two planner configurations.

With two databases, side A is read from DB_A and side B from DB_B (e.g. before and after a
change, run on the same suite); with one, both sides come from it. Each side is a selection
PLANNER[@VERSION][#CONFIG] (--a, --b) that must match exactly one configuration (without
@VERSION, each configuration's latest version, as boards rank); it may be left out when the
database holds only one. Runs are paired by scenario digest; each metric
gets the medians, the median difference B − A with its distribution-free 95 % interval (none
below 6 pairs), the mean difference and a two-sided Wilcoxon signed-rank p-value, Holm-adjusted
across the metrics; success gets an exact McNemar test. A run short of the target has an
infinite time per target m³, which ranks after every finite one. A warning says when the number
of pairs can never reach alpha. A side may be named by its configuration's label, e.g.
greedy[closed_loop]; an ambiguous one lists the candidates. In CI: --format markdown for a
comment, --fail-on-regression time_per_target_m3,success exits 1 when B is significantly worse
on any of them.
"""

from __future__ import annotations

import argparse
import re
import sys

from ..results.store import Store, default_db
from ._common import check_filters, plain, refuse_unstored


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("compare", help="paired comparison of two planners/versions (Wilcoxon signed-rank per metric)",
                       description=plain(__doc__), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("db_a", nargs="?", default=default_db(), metavar="DB_A", help="results database of side A")
    p.add_argument("db_b", nargs="?", metavar="DB_B", help="results database of side B (default: DB_A)")
    p.add_argument("--a", metavar="PLANNER[@VERSION][#CONFIG]", help="side A's planner configuration (or its label[@VERSION])")
    p.add_argument("--b", metavar="PLANNER[@VERSION][#CONFIG]", help="side B's planner configuration (or its label[@VERSION])")
    p.add_argument("--suite", help="only the runs of this suite's scenarios")
    p.add_argument("--metric", action="append", default=[], metavar="NAME", help="compare this metric (repeatable; default: the main ones)")
    p.add_argument("--alpha", type=float, default=0.05, help="significance level of the verdicts (default 0.05)")
    p.add_argument("--csv", metavar="FILE", help="also write the per-metric table as CSV")
    p.add_argument("--format", choices=("text", "markdown"), default="text", help="report format (default: text)")
    p.add_argument("--fail-on-regression", metavar="METRIC[,...]", default="",
                   help="exit 1 when B is significantly worse (Holm-adjusted) on any of these metrics; "
                        "'success' names the McNemar test")
    return p


def run(args: argparse.Namespace) -> int:
    from ..publishing.compare import DEFAULT_METRICS, SUCCESS, CompareError, Selector, compare, format_comparison
    from ..errors import UnknownNameError
    import pandas as pd

    from ..results.store import check_one_rules, load_runs

    metrics = tuple(args.metric) or DEFAULT_METRICS
    guard = tuple(m.strip() for m in args.fail_on_regression.split(",") if m.strip())
    for m in guard:
        if m != SUCCESS and m not in metrics:
            raise UnknownNameError("metric for --fail-on-regression", m, (*metrics, SUCCESS))

    for db in dict.fromkeys(d for d in (args.db_a, args.db_b) if d):
        with Store(db, create=False) as store:
            check_filters(store, db, args.suite, [])
    runs_a = load_runs(args.db_a, suite=args.suite)
    runs_b = load_runs(args.db_b, suite=args.suite) if args.db_b else runs_a
    for spec, runs, db in ((args.a, runs_a, args.db_a), (args.b, runs_b, args.db_b or args.db_a)):
        if spec:  # a planner's name mistyped: the close matches, as `run` gives them
            refuse_unstored("planner", [re.split(r"[@#\[]", spec)[0]], runs["planner"].astype(str).unique(), db)
    if not args.db_b and not (args.a and args.b):
        raise CompareError("with one database, name both sides: --a PLANNER[@VERSION][#CONFIG] --b PLANNER[@VERSION][#CONFIG]")
    a = Selector.parse(args.a).pick(runs_a, "A")
    b = Selector.parse(args.b).pick(runs_b, "B")
    check_one_rules(pd.concat([a, b]), *dict.fromkeys(d for d in (args.db_a, args.db_b) if d))
    if not args.db_b and a.index.equals(b.index):
        raise CompareError("--a and --b select the same configuration")
    res = compare(a, b, metrics, args.alpha)
    print(format_comparison(res, fmt=args.format))
    if args.csv:
        res.table.to_csv(args.csv, index=False)
        print(f"table written to {args.csv}", file=sys.stderr)
    worse = res.regressions(guard)
    if worse:
        print(f"earthbench: regression: B is significantly worse on {', '.join(worse)} (α = {args.alpha:g})", file=sys.stderr)
        return 1
    return 0
