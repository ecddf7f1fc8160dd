"""``earthbench merge OUT.db IN.db…``: merge results stores gathered on several machines.

Every incoming plan is judged again against the scenario document stored with it (whose
digest is recomputed); the merge is refused, writing nothing, when any run's stored verdict
or metrics differ from the re-judged ones (``--rescore`` merges the re-judged figures instead
and says how many changed), when a run has a verdict but no plan, when a scenario or suite
does not reproduce its digest, when a run is in two stores (same scenario digest, planner,
version and config hash; with ``--skip-duplicates`` only when the two differ in plan or
outcome, and an identical one is merged once), when a suite name has different digests in
different stores, or
when a registered suite's name (built in or installed) holds another digest: a different world
under a known name, which ``--as-variant`` stores as ``NAME~variant-D`` instead.
Runs without a plan (timeout, memory, crashed, error) are merged with the harness's reason,
which cannot be re-checked. Solve times come from the machine that ran each case. An
``earthbench export`` bundle is a store like any other. OUT.db is created if missing.
"""

from __future__ import annotations

import argparse
import sys

from ._common import plain


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("merge", help="merge results databases, re-judging every plan",
                       description=plain(__doc__), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("out", metavar="OUT.db", help="database to merge into (created if missing)")
    p.add_argument("inputs", nargs="+", metavar="IN.db", help="databases or export bundles to merge")
    p.add_argument("--rescore", action="store_true",
                   help="merge runs whose stored figures differ with the re-judged figures instead of refusing")
    p.add_argument("--as-variant", action="store_true",
                   help="store a registered suite name holding another world as NAME~variant-DIGEST instead of refusing it")
    p.add_argument("--skip-duplicates", action="store_true",
                   help="merge once a run that is in several stores with the same plan and outcome (e.g. a deterministic "
                        "baseline run on two machines; the first store's solve times are kept), instead of refusing")
    return p


def run(args: argparse.Namespace) -> int:
    from ..publishing.merge import merge

    report = merge(args.out, args.inputs, rescore=args.rescore, as_variant=args.as_variant, skip_duplicates=args.skip_duplicates)
    for line in report.changes[:20]:
        print(f"re-scored {line}", file=sys.stderr)
    if len(report.changes) > 20:
        print(f"re-scored … and {len(report.changes) - 20} more", file=sys.stderr)
    for path, n in report.per_input.items():
        print(f"{path}: {n} run(s)")
    judged = report.agreed + report.rescored
    print(f"re-judged {judged} plan(s): {report.agreed} agree with the stored figures"
          + (f", {report.rescored} re-scored (stored figures replaced by the re-judged ones)" if args.rescore else ""))
    if report.unjudged:
        counts = ", ".join(f"{n} {r}" for r, n in sorted(report.unjudged.items()))
        print(f"{sum(report.unjudged.values())} run(s) without a plan ({counts}) merged with the reason the harness gave; "
              "it cannot be re-checked from a store")
    if report.other_rules:
        from ..referee import RULES_VERSION

        older = ", ".join(f"{n} under rules {v}" for v, n in sorted(report.other_rules.items()))
        print(f"{sum(report.other_rules.values())} run(s) had been judged under other rules ({older}); "
              f"merged as re-judged under this referee's rules {RULES_VERSION}")
    if report.duplicates:
        print(f"left out {report.duplicates} run(s) already merged from an earlier store with the same plan and outcome")
    print(f"merged {report.runs} run(s) and {report.suites} new suite version(s) into {args.out}")
    return 0
