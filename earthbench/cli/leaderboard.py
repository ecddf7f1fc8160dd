"""``earthbench leaderboard``: turn the results store into a board folder (tables, CSVs, page, figures).

The folder is ``board/`` unless ``--out`` names another; the published boards of a clone
(``leaderboard/``) are rewritten only when ``--out`` names them.

Writes README.md (one ranked table per suite and track, each with its ranking rule and a
reproducibility stamp, then one table per family and per target and a history of older
versions), runs.csv, summary.csv, a self-contained index.html and figures/ (PNG and SVG):
loaded volume against total time, performance profiles (per family too), version histories,
and terrain before and after for one case per planner.

``--key FILE`` (repeatable) publishes a sealed draw's key with its board: the key is checked
against the store first (it must reproduce its commitment and the stored draw, as ``verify
--key`` checks), then written to ``keys/SUITE~sealed-C.key`` beside the tables, so anyone can
re-judge the board with ``earthbench verify STORE --key FILE`` for as long as the board exists
(docs/publishing.md). A sealed draw published without its key is named in a note.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from ..results.store import default_db
from ._common import check_filters, plain

#: Where a board goes without ``--out``: never the clone's tracked ``leaderboard/``, which a plain run would overwrite.
DEFAULT_OUT = "board"

if TYPE_CHECKING:  # pragma: no cover
    from ..seal import SealKey


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("leaderboard", help="write leaderboard tables, CSVs, an HTML page and figures from the store",
                       description=plain(__doc__), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--db", default=default_db(), metavar="PATH", help="results database (default: $EARTHBENCH_DB or earthbench.db)")
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR",
                   help=f"output directory (default: {DEFAULT_OUT}/; a clone's published boards are in leaderboard/)")
    p.add_argument("--suite", action="append", default=[], metavar="NAME",
                   help="publish only this suite (repeatable; default: every suite with runs in the store)")
    p.add_argument("--no-figures", action="store_true", help="tables, CSVs and page only")
    p.add_argument("--no-terrain", action="store_true", help="skip the terrain before/after figures (no re-judging)")
    p.add_argument("--all-versions", action="store_true",
                   help="rank every stored version of each planner (default: the latest; older ones in a history table)")
    p.add_argument("--seeds", metavar="A-B", default=None,
                   help="only the suite's scenarios of these seeds, e.g. 0-2 (runs and denominators alike; stamped on every table)")
    p.add_argument("--jobs", type=int, default=None, metavar="N", help="processes drawing figures (default: one per core)")
    p.add_argument("--key", action="append", default=[], metavar="FILE",
                   help="a sealed draw's key, checked against the store and published with the board in keys/ (repeatable)")
    p.add_argument("--replays", type=int, default=20, metavar="N",
                   help="runs the page's replay viewer embeds, a success and an invalid run per planner first (default: 20; 0: none)")
    p.add_argument("--best", metavar="DIR", default=None,
                   help="the folder of best known plans (`earthbench best`): a \"× best known\" column and best.csv "
                        "(default: leaderboard/best when it exists; `--best none`: neither)")
    return p


def run(args: argparse.Namespace) -> int:
    from ..publishing.publish import publish
    from ..results.suite import parse_seed_range

    from ..results.store import Store

    t0 = time.perf_counter()
    with Store(args.db, create=False) as store:
        for suite in args.suite:  # a mistyped name: the close matches
            check_filters(store, args.db, suite, [])
    keys = _checked_keys(args.db, args.key)
    res = publish(args.db, args.out, args.suite or None, figures=not args.no_figures, terrain=not args.no_terrain,
                  workers=args.jobs, replays=args.replays, all_versions=args.all_versions,
                  seeds=parse_seed_range(args.seeds) if args.seeds else None, best=_best_dir(args.best))
    runs = 0 if res.runs is None else len(res.runs)
    tables = 0 if res.summary is None or res.summary.empty else res.summary.groupby(["suite", "track"]).ngroups
    print(f"leaderboard: {runs} run(s), {tables} table(s), {len(res.files)} file(s) in {res.out}/ "
          f"({time.perf_counter() - t0:.1f} s)"
          + (f"; removed {len(res.removed)} figure file(s) of an earlier board from {res.out / 'figures'}/" if res.removed else ""),
          file=sys.stderr)
    if res.summary is not None and not res.summary.empty:
        main = res.summary[(res.summary["scope"] == "suite") & res.summary["latest"].astype(bool)]
        partial = sorted(set(main.loc[main["runs"] < main["of"], "suite"]))
        if partial:
            print(f"leaderboard: note: partial data on {', '.join(partial)}: some planners lack runs on some scenarios "
                  "(counted as failed); each such table says which", file=sys.stderr)
    _publish_keys(res.out, keys, set() if res.summary is None or res.summary.empty else set(res.summary["suite"]))
    return 0


def _best_dir(given: str | None) -> Path | None:
    """The best-known folder the board reads: the one named, else the committed one when it is here."""
    from ..publishing.best import BestError, DEFAULT_DIR

    if given == "none":
        return None
    if given is None:
        return DEFAULT_DIR if DEFAULT_DIR.is_dir() else None
    if not Path(given).is_dir():
        raise BestError(f"--best {given}: no such folder of best known plans (`earthbench best update --dir {given}` makes one)")
    return Path(given)


def _checked_keys(db: str, paths: list[str]) -> list[SealKey]:
    """Each key file read and checked against the store's sealed draw; a key that does not open
    its draw there is an error, and nothing is published."""
    from ..seal import SealError, SealKey
    from ..results.store import Store
    from ..publishing.verify import check_seal

    keys = [SealKey.read(p) for p in paths]
    if keys:
        with Store(db, read_only=True) as store:
            for key in keys:
                problems = check_seal(store, key).problems
                if problems:
                    raise SealError(f"--key for {key.name}: " + "; ".join(problems[:3]) + ("; …" if len(problems) > 3 else ""))
    return keys


def _publish_keys(out: Path, keys: list[SealKey], suites: set[str]) -> None:
    """Write each key beside the board (readable by all: it is published), and name every sealed
    draw on the board whose key was not given."""
    from ..seal import SealError, public_name

    for key in keys:
        target = out / "keys" / f"{key.name}.key"
        target.parent.mkdir(parents=True, exist_ok=True)
        if target.exists() and target.read_text() != key.to_json():
            raise SealError(f"{str(target)!r} holds another key for {key.name}; remove it first")
        target.write_text(key.to_json())
        print(f"leaderboard: key of {key.name} published in {target}", file=sys.stderr)
    for name in sorted(n for n in suites - {k.name for k in keys} if public_name(n) is not None):
        if not (out / "keys" / f"{name}.key").exists():
            print(f"earthbench: note: sealed draw {name} is published without its key; once the board is final, publish "
                  "it with --key FILE (docs/publishing.md): a lost key leaves the draw checkable by nobody", file=sys.stderr)
