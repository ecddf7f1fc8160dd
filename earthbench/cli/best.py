"""``earthbench best update|check``: the best known plan of every scenario (docs/publishing.md "Best known plans").

``update`` offers candidates — every stored plan of a results database (``--db``) and plan files
(``--plans``: a file or a folder of ``*.json``/``*.json.gz`` candidate files, each with
``scenario_digest`` and ``plan``) — for the scenarios of the suite (``--suite``; with ``--db`` only,
default every registered suite the store has runs under). Each is judged again on the suite's own
scenario of that digest; nothing a store or a file says is taken on trust. A candidate is kept,
replacing the kept plan, only when it is valid under this earthbench's rules, reaches the target
and its time to the target is strictly shorter. A candidate judged under other rules, for another
scenario, or stating figures re-judging does not give, is refused; kept entries judged under other
rules, or that no longer re-judge valid with their recorded times, are dropped (a changed target
bound is re-recorded). Exit 1 when a plan file was refused.

``check`` re-judges every kept plan (``--suite``, default every suite folder): valid under this
earthbench's rules, its figures as recorded. Exit 1 when one does not hold.
"""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING

from ._common import plain

if TYPE_CHECKING:  # pragma: no cover
    from ..results.suite import Suite


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    from ..publishing.best import DEFAULT_DIR

    p = sub.add_parser("best", help="keep and check the best known plan of every scenario of a suite",
                       description=plain(__doc__), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("action", choices=("update", "check"), help="update: offer candidates; check: re-judge what is kept")
    p.add_argument("--db", metavar="STORE", help="offer every plan of this results database (update)")
    p.add_argument("--plans", action="append", default=[], metavar="PATH",
                   help="offer these candidate files, or every one in this folder (update; repeatable; needs --suite)")
    p.add_argument("--suite", action="append", default=[], metavar="S",
                   help="the suite (name or TOML file) whose scenarios to update or check (repeatable)")
    p.add_argument("--dir", default=str(DEFAULT_DIR), metavar="DIR",
                   help=f"the folder of best known plans, one sub-folder per suite (default {DEFAULT_DIR})")
    return p


def run(args: argparse.Namespace) -> int:
    from ..publishing.best import BestError
    from ..results.suite import load_suite

    if args.action == "check":
        if args.db or args.plans:
            raise BestError("earthbench best check takes no --db or --plans: it re-judges what --dir keeps")
        names = args.suite or sorted(p.name for p in Path(args.dir).glob("*") if p.is_dir())
        return _check(args.dir, [load_suite(n) for n in names])
    if not args.db and not args.plans:
        raise BestError("earthbench best update needs candidates: --db STORE and/or --plans PATH")
    if args.plans and not args.suite:
        raise BestError("earthbench best update --plans needs --suite: plan files are matched to a suite's scenarios by digest")
    return _update(args, [load_suite(n) for n in args.suite or _store_suites(args.db)])


def _store_suites(db: str) -> list[str]:
    from ..results.store import Store
    from ..results.suite import known_suites

    with Store(db, create=False, read_only=True) as store:
        return [s for s in store.run_suites() if s in known_suites()]


def _update(args: argparse.Namespace, suites: list[Suite]) -> int:
    from ..publishing.best import file_candidates, store_candidates, update
    from ..results.store import Store

    refused_files = 0
    for suite in suites:
        digests = {sc.digest for sc in suite.scenarios}
        files = list(file_candidates(args.plans))
        candidates = list(files)
        from_file = {id(c) for c in files}
        if args.db:
            with Store(args.db, create=False, read_only=True) as store:
                candidates += list(store_candidates(store, digests))
        out = update(args.dir, suite, candidates)
        for line in out.dropped:
            print(f"dropped {line}")
        for line in out.refreshed:
            print(f"re-recorded {line}")
        for line in out.accepted:
            print(f"kept {line}")
        for c, why in out.refused:
            if id(c) in from_file:
                print(f"refused {c.source}: {why}")
        refused_files += sum(1 for c, _ in out.refused if id(c) in from_file)
        stored = Counter(why for c, why in out.refused if id(c) not in from_file)
        if stored:
            print("refused stored plans: " + "; ".join(f"{n} {why}" for why, n in stored.most_common()))
        print(f"suite {suite.name}: re-judged {out.judged} candidate(s): {len(out.accepted)} kept, {out.not_better} not faster "
              f"than the kept plan, {len(out.refused)} refused; {len(out.dropped)} stale entr(ies) dropped; "
              f"{args.dir}/{suite.name} keeps {sum(1 for _ in (Path(args.dir) / suite.name).glob('*.json.gz'))} "
              f"of {len(digests)} scenarios")
    return 1 if refused_files else 0


def _check(root: str, suites: list[Suite]) -> int:
    from ..publishing.best import check

    failed = False
    for suite in suites:
        n, problems = check(root, suite)
        for line in problems:
            print(f"{suite.name}: {line}")
        failed |= bool(problems)
        print(f"suite {suite.name}: {n} best known plan(s) re-judged, {n - len(problems)} hold")
    return 1 if failed else 0
