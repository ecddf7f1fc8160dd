"""``earthbench verify STORE --sample N``: rerun a seeded sample of a store's cases on this machine.

Referee figures in a store can be re-judged from its plans (``merge`` does); solve times,
CPU times and memory cannot: they come from the machine that ran each case. This command
reruns N randomly chosen runs (``--seed``) under the harness here, with the same planner
version and configuration (which must be installed), and reports per planner whether the
referee figures agree (identical for a deterministic planner) and the ratio of solve times
here to those stored. The result is kept in the store (table ``spot_checks``, unless
``--no-record``) so that ``earthbench leaderboard`` shows it in the table's stamp. Exits 1
when a rerun's referee figures differ from the stored ones.
"""

from __future__ import annotations

import argparse
import statistics


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("verify", help="rerun a random sample of a store's cases here and compare",
                       description=__doc__.replace("``", "`"), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("store", metavar="STORE", help="results database or export bundle")
    p.add_argument("--sample", type=int, required=True, metavar="N", help="how many runs to rerun")
    p.add_argument("--seed", type=int, default=0, help="seed of the random sample (default 0)")
    p.add_argument("--suite", help="sample only this suite's runs")
    p.add_argument("--planner", action="append", default=[], metavar="NAME", help="sample only this planner (repeatable)")
    p.add_argument("--jobs", type=int, default=None, metavar="N", help="cases at once (default: cores / 2)")
    p.add_argument("--no-record", action="store_true", help="do not keep the result in the store")
    return p


def run(args: argparse.Namespace) -> int:
    from ..store import Store
    from ..verify import record_spot_checks, spot_check

    with Store(args.store, create=False) as store:
        if not args.no_record:
            store.check_writable()
        checks = spot_check(store, args.sample, seed=args.seed, suite=args.suite, planners=args.planner, jobs=args.jobs)
        def spread(r: tuple[float, ...]) -> tuple[str, ...]:
            return (f"{statistics.median(r):.2f}", f"{min(r):.2f}–{max(r):.2f}") if r else ("–", "–")

        def load(v: tuple[float, ...]) -> str:
            return f"{min(v):.2f}–{max(v):.2f}" if v else "–"

        head = ("planner", "version", "runs", "referee agree", "solve ratio median", "range", "CPU ratio median", "range",
                "load here", "load stored", "stored on")
        rows = [(c.planner, c.version, str(c.n), f"{c.agree}/{c.n}", *spread(c.ratios), *spread(c.cpu_ratios),
                 load(c.load_here), load(c.load_stored), "; ".join(c.stored_machines)) for c in checks]
        widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)]
        print(f"rerun on {checks[0].machine}; solve ratio = wall time here / stored, CPU ratio = CPU time here / stored; "
              "load: the 1-minute load average around the cases (a ratio far from 1 at a high load says more about the "
              "machine than the planner)")
        for r in (head, *rows):
            print("  ".join(v.ljust(w) for v, w in zip(r, widths)).rstrip())
        for c in checks:
            for d in c.disagreements:
                print(f"  {c.planner} {c.version}: {d}")
        if not args.no_record:
            record_spot_checks(store, checks)
    return 1 if any(c.disagreements for c in checks) else 0
