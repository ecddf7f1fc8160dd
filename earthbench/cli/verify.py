"""``earthbench verify STORE``: check a store's suites, its sealed draws and its plans; rerun a sample here.

Always: every suite version in the store must be stored under its own name (a registered
suite's name with that suite's digest; a sealed draw under its commitment;
docs/sealed-evaluation.md).

``--key FILE`` (repeatable): a revealed key of a sealed draw. Its commitment is recomputed from
the registered public suite (every sealed scenario regenerated), the store's draw must be
exactly those scenarios, and every plan of the draw is judged again.

Without ``--key`` and ``--sample``: every plan of the store is judged again.

``--sample N``: referee figures in a store can be re-judged from its plans; solve times, CPU
times and memory cannot: they come from the machine that ran each case. This reruns N randomly
chosen runs (``--seed``) under the harness here, with the same planner version and
configuration (which must be installed, or given with ``--plugin FILE.py``), and reports per planner whether the referee figures
agree (identical for a deterministic planner) and the ratio of solve times here to those
stored. The result is kept in the store (table ``spot_checks``, unless ``--no-record``) so that
``earthbench leaderboard`` shows it in the table's stamp.

Exits 1 when anything does not hold: a suite under another's name, a sealed draw the key does
not reproduce, a stored figure the re-judged plan does not give, or a rerun's referee figures
that differ from the stored ones.
"""

from __future__ import annotations

import argparse
import statistics

from ._common import add_plugin_arg, check_filters, load_plugins, plain


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("verify", help="check a store's suites, sealed draws and plans; rerun a random sample here",
                       description=plain(__doc__), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("store", metavar="STORE", help="results database or export bundle")
    p.add_argument("--key", action="append", default=[], metavar="FILE",
                   help="a revealed key file of a sealed draw (`earthbench seal` wrote it; repeatable)")
    p.add_argument("--sample", type=int, default=None, metavar="N", help="how many runs to rerun on this machine")
    p.add_argument("--seed", type=int, default=0, help="seed of the random sample (default 0)")
    p.add_argument("--suite", help="sample only this suite's runs")
    p.add_argument("--planner", action="append", default=[], metavar="NAME", help="sample only this planner (repeatable)")
    p.add_argument("--jobs", type=int, default=None, metavar="N", help="cases at once (default: cores / 2)")
    p.add_argument("--no-record", action="store_true", help="do not keep the result in the store")
    add_plugin_arg(p)
    return p


def run(args: argparse.Namespace) -> int:
    from ..seal import SealKey
    from ..results.store import Store

    load_plugins(args)
    keys = [SealKey.read(k) for k in args.key]
    with Store(args.store, create=False, read_only=args.sample is None or args.no_record) as store:
        check_filters(store, args.store, args.suite, args.planner)
        failed = _suites_and_plans(store, keys, rejudge_all=not keys and args.sample is None)
        if args.sample is not None:
            failed |= _spot(store, args)
    return 1 if failed else 0


def _suites_and_plans(store, keys, *, rejudge_all: bool) -> bool:
    """The identity check, each key's draw and the re-judging; prints what it finds, returns whether anything failed."""
    from ..publishing.verify import audit, check_seal, identity_problems

    problems = identity_problems(store)
    print(f"suite names: {len(problems)} problem(s)" if problems else "suite names: every suite version is stored under its own name")
    for p in problems:
        print(f"  {p}")
    failed = bool(problems)
    rows = []
    for key in keys:
        seal = check_seal(store, key)
        state = "does not hold" if seal.problems else "holds"
        print(f"sealed draw {seal.suite}: {state}: commitment {key.commitment[:12]}…, {seal.scenarios} scenario(s) regenerated "
              f"and matched, {len(seal.run_rows)} run(s) to re-judge")
        for p in seal.problems[:20]:
            print(f"  {p}")
        failed |= bool(seal.problems)
        rows += seal.run_rows
    if keys or rejudge_all:
        a = audit(store, rows if keys else None)
        judged = a.agreed + len(a.differ)
        print(f"re-judged {judged} plan(s): {a.agreed} agree with the stored figures"
              + (f"; {sum(a.unjudged.values())} run(s) without a plan" if a.unjudged else ""))
        if a.other_rules:
            print(a.rules_note())
        for f in (a.broken + a.differ)[:20]:
            print(f"  {f}")
        failed |= bool(a.broken or a.differ)
    return failed


def _spot(store, args: argparse.Namespace) -> bool:
    from ..publishing.verify import spot_check

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
        store.record_spot_checks(checks)
    return any(c.disagreements for c in checks)
