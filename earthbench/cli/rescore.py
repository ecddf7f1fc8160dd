"""``earthbench rescore``: judge stored plans again (after a referee or metric fix, or under a
new version of the referee's rules).

Only runs that returned a plan (reason ok or invalid, or error because the referee itself
failed) are re-judged; their reason, metrics and violations are replaced, their solve times
kept, and ``rescored_at`` and the rules version (``rules``) are set; runs without a plan are
marked as standing under the current rules (no rule changes a timeout). Each run is updated in
its own transaction. Re-judging is the same function ``earthbench merge`` uses to verify
incoming runs. It ends with the account of what moved: per planner and suite, the runs that
were valid and are not now, by the rule that refused them.

``--dry-run`` re-judges and prints the account without writing anything.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter

from ..results.store import Store, decompress, default_db, stored_steps
from ..publishing.verify import rejudge
from ._common import check_filters, plain


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("rescore", help="re-run the referee on stored plans", description=plain(__doc__),
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--db", default=default_db(), metavar="PATH", help="results database")
    p.add_argument("--suite", help="only this suite")
    p.add_argument("--planner", action="append", default=[], metavar="NAME", help="only this planner (repeatable)")
    p.add_argument("--dry-run", action="store_true", help="re-judge and report what would move, write nothing")
    return p


class Account:
    """What a re-judging moved, per (planner, suite): runs re-judged, valid before, valid now,
    and the runs valid before and not now by each rule that refuses them."""

    def __init__(self) -> None:
        self.judged: Counter[tuple[str, str]] = Counter()
        self.valid_before: Counter[tuple[str, str]] = Counter()
        self.valid_now: Counter[tuple[str, str]] = Counter()
        self.lost: dict[tuple[str, str], Counter[str]] = {}
        self.rules_before: Counter[int] = Counter()

    def add(self, key: tuple[str, str], before: str, after: str, rules: set[str]) -> None:
        self.judged[key] += 1
        self.valid_before[key] += before == "ok"
        self.valid_now[key] += after == "ok"
        lost = self.lost.setdefault(key, Counter())
        if before == "ok" and after != "ok":
            lost.update(rules)
            lost["(any)"] += 1

    def table(self) -> str:
        rules = sorted({r for c in self.lost.values() for r in c if r != "(any)"})
        head = ["planner", "suite", "plans", "valid before", "valid now", "newly invalid", *rules]
        rows = [[p, s, str(self.judged[(p, s)]), str(self.valid_before[(p, s)]), str(self.valid_now[(p, s)]),
                 str(self.lost[(p, s)]["(any)"]), *(str(self.lost[(p, s)][r]) for r in rules)] for p, s in sorted(self.judged)]
        widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)] if rows else [len(h) for h in head]
        lines = ["| " + " | ".join(h.ljust(w) for h, w in zip(head, widths)) + " |",
                 "|" + "|".join("-" * (w + 2) for w in widths) + "|"]
        lines += ["| " + " | ".join(c.ljust(w) for c, w in zip(r, widths)) + " |" for r in rows]
        return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from ..referee import RULES_VERSION

    changed = same = failed = 0
    account = Account()
    with Store(args.db, create=False, read_only=args.dry_run) as store:
        if not args.dry_run:
            store.check_writable()
        check_filters(store, args.db, args.suite, args.planner)
        selected = store.query(suite=args.suite, planner=args.planner)
        rows = [r for r in selected if r["plan"] is not None]
        scenarios = {}
        for r in rows:
            digest = r["scenario_digest"]
            if digest not in scenarios:
                scenarios[digest] = store.scenario(digest)
            account.rules_before[r["rules"] if "rules" in r.keys() else 1] += 1
            judged = rejudge(scenarios[digest], decompress(r["plan"]), r["threshold"],
                             solve_time_s=r["solve_time_s"], solve_cpu_s=r["solve_cpu_s"], steps=stored_steps(r))
            if judged.metrics is None:  # the referee failed on it: keep the row, say so
                failed += 1
                print(f"run {r['id']} {r['scenario_id']} × {r['planner']}: {judged.error.strip().splitlines()[-1]}", file=sys.stderr)
                continue
            metrics = judged.metrics
            account.add((r["planner"], r["suite"]), r["reason"], judged.reason, {v["rule"] for v in judged.violations})
            before = (r["reason"], r["volume_ratio"], bool(r["success"]))
            if not args.dry_run:
                store.update_score(r["id"], judged.reason, metrics, judged.violations)
            if before != (judged.reason, metrics["volume_ratio"], bool(metrics["success"])):
                changed += 1
                print(f"run {r['id']} {r['scenario_id']} × {r['planner']}: {before[0]} → {judged.reason}, "
                      f"volume ratio {before[1]} → {metrics['volume_ratio']:.4g}", file=sys.stderr)
            else:
                same += 1
        if not args.dry_run:
            store.mark_rules(r["id"] for r in selected if r["plan"] is None)
    older = ", ".join(f"{n} under rules {v}" for v, n in sorted(account.rules_before.items()) if v != RULES_VERSION)
    print(f"{'would rescore' if args.dry_run else 'rescored'} {changed + same} run(s) under rules {RULES_VERSION}"
          + (f" (judged before: {older})" if older else "") + f": {changed} changed, {same} unchanged"
          + (f"; the referee failed on {failed} (left as they were)" if failed else ""))
    if account.judged:
        print(account.table())
    return 1 if failed else 0
