"""``earthbench rescore``: judge stored plans again (after a referee or metric fix).

Only runs that returned a plan (reason ok or invalid, or error because the referee itself
failed) are re-judged; their reason, metrics and violations are replaced, their solve times
kept, and ``rescored_at`` is set. Each run is updated in its own transaction. Re-judging is
the same function ``earthbench merge`` uses to verify incoming runs.
"""

from __future__ import annotations

import argparse
import sys

from ..store import Store, decompress, default_db, stored_steps
from ..verify import rejudge
from ._common import check_filters, plain


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("rescore", help="re-run the referee on stored plans", description=plain(__doc__),
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--db", default=default_db(), metavar="PATH", help="results database")
    p.add_argument("--suite", help="only this suite")
    p.add_argument("--planner", action="append", default=[], metavar="NAME", help="only this planner (repeatable)")
    return p


def run(args: argparse.Namespace) -> int:
    changed = same = failed = 0
    with Store(args.db, create=False) as store:
        store.check_writable()
        check_filters(store, args.db, args.suite, args.planner)
        rows = [r for r in store.query(suite=args.suite, planner=args.planner) if r["plan"] is not None]
        scenarios = {}
        for r in rows:
            digest = r["scenario_digest"]
            if digest not in scenarios:
                scenarios[digest] = store.scenario(digest)
            judged = rejudge(scenarios[digest], decompress(r["plan"]), r["threshold"],
                             solve_time_s=r["solve_time_s"], solve_cpu_s=r["solve_cpu_s"], steps=stored_steps(r))
            if judged.metrics is None:  # the referee failed on it: keep the row, say so
                failed += 1
                print(f"run {r['id']} {r['scenario_id']} × {r['planner']}: {judged.error.strip().splitlines()[-1]}", file=sys.stderr)
                continue
            metrics = judged.metrics
            before = (r["reason"], r["volume_ratio"], bool(r["success"]))
            store.update_score(r["id"], judged.reason, metrics, judged.violations)
            if before != (judged.reason, metrics["volume_ratio"], bool(metrics["success"])):
                changed += 1
                print(f"run {r['id']} {r['scenario_id']} × {r['planner']}: {before[0]} → {judged.reason}, "
                      f"volume ratio {before[1]} → {metrics['volume_ratio']:.4g}", file=sys.stderr)
            else:
                same += 1
    print(f"rescored {changed + same} run(s): {changed} changed, {same} unchanged"
          + (f"; the referee failed on {failed} (left as they were)" if failed else ""))
    return 1 if failed else 0
