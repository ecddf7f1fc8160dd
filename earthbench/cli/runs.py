"""``earthbench runs``: list stored runs with filters, or show one run in full."""

from __future__ import annotations

import argparse
import csv
import json
import math
import shlex
import sys
from typing import Any

from ..results.records import REASONS
from ..results.scoring import is_success, restate
from ..results.store import DEFAULT_DB, Store, default_db, suite_members
from ._common import check_filters

HELP = """List the runs stored in the results database, newest first, with filters; or, with --id N,
show one run in full (violations first, then config, metrics, error and output tail) and write
its plan and scenario so `earthbench validate` and `earthbench show` reproduce it.

A --suite or --planner that has no run in the database is refused with the close matches.
Common filters: --reason invalid (the referee found a broken rule), --reason error (the planner
raised), --short (valid plans that loaded less than the target)."""

COLUMNS = ("id", "suite", "scenario_id", "configuration", "planner_version", "reason", "success", "volume_ratio",
           "time_per_target_m3", "time_per_m3", "solve_cpu_s", "solve_time_s")


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("runs", help="list stored runs (filters), or show one with --id", description=HELP,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--db", default=default_db(), metavar="PATH", help=f"results database (default: $EARTHBENCH_DB or {DEFAULT_DB})")
    p.add_argument("--suite", help="only this suite's scenarios")
    p.add_argument("--planner", action="append", default=[], metavar="NAME", help="only this planner (repeatable)")
    p.add_argument("--reason", action="append", default=[], choices=REASONS, help="only this termination reason (repeatable)")
    p.add_argument("--short", action="store_true",
                   help="only valid plans that loaded less than the target (the summary's `short` column)")
    p.add_argument("--scenario", metavar="TEXT", help="only scenarios whose id contains TEXT")
    p.add_argument("--seeds", metavar="A-B", help="with --suite: only its scenarios of these seeds, e.g. 0-2,7 (as `run --seeds`)")
    p.add_argument("--limit", type=int, default=50, help="at most this many rows, newest first (0: all; default 50)")
    p.add_argument("--format", choices=("table", "csv", "json"), default="table", help="output format (default: table)")
    p.add_argument("--id", type=int, metavar="RUN", help="show one run in full: config, violations, error, output tail")
    p.add_argument("--plan-out", metavar="FILE", help="with --id: write the run's plan JSON to FILE")
    p.add_argument("--scenario-out", metavar="FILE",
                   help="with --id: write the run's scenario JSON to FILE (then: earthbench validate PLAN --scenario FILE, "
                        "earthbench show --scenario FILE --plan PLAN)")
    return p


def db_option(db: str) -> str:
    """`` --db PATH`` for a printed command, empty for the default store: a hint must run as printed."""
    return "" if db == default_db() else f" --db {shlex.quote(str(db))}"


def _cell(v: object) -> str:
    if v is None:
        return "–"
    if isinstance(v, float):
        return "inf" if math.isinf(v) else f"{v:.3g}"
    return str(v)


def labels_of(store: Store) -> dict[tuple[str, str], str]:
    """(planner, config hash) → the configuration's readable label (:mod:`earthbench.results.labels`), over the store's configurations."""
    import pandas as pd

    from ..results.labels import config_labels

    return config_labels(pd.DataFrame(store.planner_configs(), columns=["planner", "config_hash", "config"]))


def _values(r: Any, threshold: float | None, labels: dict[tuple[str, str], str] | None = None) -> dict[str, Any]:
    """A stored row's columns; metrics kept only in its JSON (``time_per_target_m3``) filled in, the configuration's
    label, and with a suite named, success under that suite's threshold (:func:`earthbench.results.scoring.is_success`)."""
    metrics = restate(json.loads(r["metrics"])) if r["metrics"] else {}
    d = {c: r[c] if c in r.keys() else metrics.get(c) for c in COLUMNS}
    d["configuration"] = (labels or {}).get((r["planner"], r["config_hash"]), r["planner"])
    if threshold is not None:
        d["success"] = int(is_success(r["valid"], r["volume_ratio"], threshold))
    return d


def run(args: argparse.Namespace) -> int:
    with Store(args.db, create=False) as store:
        if args.id is not None:
            return _show(store, args)
        check_filters(store, args.db, args.suite, args.planner)
        rows = _rows(store, args)
        if args.format == "json":
            json.dump([{c: r[c] for c in COLUMNS} for r in rows], sys.stdout, indent=1)
            print()
        elif args.format == "csv":
            w = csv.writer(sys.stdout)
            w.writerow(COLUMNS)
            for r in rows:
                w.writerow([r[c] for c in COLUMNS])
        else:
            table = [list(COLUMNS)] + [[_cell(r[c]) for c in COLUMNS] for r in rows]
            widths = [max(len(t[i]) for t in table) for i in range(len(COLUMNS))]
            for n, t in enumerate(table):
                print("  ".join(c.ljust(w) for c, w in zip(t, widths)).rstrip())
                if n == 0:
                    print("  ".join("-" * w for w in widths))
            print(f"({len(rows)} run(s){'; more with --limit 0' if args.limit and len(rows) == args.limit else ''})", file=sys.stderr)
    return 0


def _rows(store: Store, args: argparse.Namespace) -> list[dict[str, Any]]:
    """The filtered runs' columns, at most ``--limit`` of them (``--short`` and ``--seeds`` filter after the store's query)."""
    reason = ["ok"] if args.short else args.reason
    if args.short and args.reason and "ok" not in args.reason:
        return []  # a short run is a valid one: no other reason holds one
    limit = None if args.short or args.seeds else args.limit or None
    stored = store.query(suite=args.suite, planner=args.planner, reason=reason, scenario=args.scenario, limit=limit)
    if args.seeds:
        digests = _seed_digests(store, args)
        stored = [r for r in stored if r["scenario_digest"] in digests]
    ver = store.suite_version(args.suite) if args.suite else None
    labels = labels_of(store)
    rows = [_values(r, None if ver is None else ver["threshold"], labels) for r in stored]
    if args.short:
        rows = [r for r, row in zip(rows, stored) if is_short(row)]
    return rows[:args.limit] if args.limit else rows


def _seed_digests(store: Store, args: argparse.Namespace) -> set[str]:
    """The scenario digests of ``--suite``'s scenarios of ``--seeds``."""
    from ..errors import EarthbenchError
    from ..results.suite import parse_seed_range

    if not args.suite:
        raise EarthbenchError("--seeds needs --suite: seeds are counted within a suite")
    members = suite_members(store, [args.suite])
    return set(members.loc[members["seed"].isin(parse_seed_range(args.seeds)), "scenario_digest"])


def is_short(row: Any) -> bool:
    """Whether a stored run is a valid plan that loaded less than the target (``--short``; the summary's ``short``)."""
    if row["reason"] != "ok" or not row["metrics"]:
        return False
    t = restate(json.loads(row["metrics"])).get("time_per_target_m3")
    return t is not None and math.isinf(t)


def failure_filters(rows: list[Any]) -> list[tuple[str, str]]:
    """(filter, what it shows) for the failures among stored ``rows``: one ``--reason R …`` for the
    termination reasons other than ``ok`` that occur (most frequent first), ``--short`` when valid
    runs fell short of the target. Empty when every run reached it: a hint names only what happened."""
    counts: dict[str, int] = {}
    for r in rows:
        if r["reason"] != "ok":
            counts[r["reason"]] = counts.get(r["reason"], 0) + 1
    out = []
    if counts:
        order = sorted(counts, key=lambda k: (-counts[k], REASONS.index(k) if k in REASONS else len(REASONS)))
        n = sum(counts.values())
        out.append((" ".join(f"--reason {k}" for k in order),
                    f"the {n} failed run{'s' if n != 1 else ''}: {', '.join(f'{counts[k]} {k}' for k in order)}"))
    short = sum(1 for r in rows if is_short(r))
    if short:
        out.append(("--short", f"the {short} valid run{'s' if short != 1 else ''} short of the target"))
    return out


def _show(store: Store, args: argparse.Namespace) -> int:
    rows = store.query(run_id=args.id)
    if not rows:
        print(f"earthbench: error: no run with id {args.id} in {args.db}", file=sys.stderr)
        return 2
    r = rows[0]
    cfg = store.planner_config(r["planner_config_id"])
    env = store.environment(r["environment_id"])
    label = labels_of(store).get((r["planner"], r["config_hash"]), r["planner"])
    print(f"run {r['id']}: {r['scenario_id']} × {label} {r['planner_version']} (config {r['config_hash']})")
    print(f"  suite {r['suite']} ({r['suite_digest'][:12]}), scenario digest {r['scenario_digest'][:12]}")
    print(f"  reason {r['reason']}, success {bool(r['success'])} (threshold {r['threshold']})")
    violations = json.loads(r["violations"] or "[]")
    for v in violations:  # what broke comes first: it is why one looks at a run
        where = "plan" if v["action"] is None else f"action {v['action']}"
        print(f"  violation: {where}: {v['rule']} ({v['magnitude']:.3g}) {v['message']}")
    if r["error"]:
        print("  error:\n    " + r["error"].strip().replace("\n", "\n    "))
    print(f"  solve {_cell(r['solve_time_s'])} s wall, {_cell(r['solve_cpu_s'])} s CPU; start-up {_cell(r['startup_s'])} s; "
          f"peak RSS {_cell(r['peak_rss_mb'])} MB; cores {r['cores']}; {r['started_at']} → {r['finished_at']}")
    if cfg:
        print(f"  config {cfg['config']}")
    if env:
        print(f"  machine {env['cpu_model']} ({env['cores']} cores), {env['os']}, Python {env['python']}, "
              f"commit {env['project_commit']}, plugin commit {env['plugin_commit']}")
    if r["metrics"]:
        print("  metrics:")
        for k, v in json.loads(r["metrics"]).items():
            print(f"    {k:<28} {_cell(v)}")
    if r["log_tail"]:
        print("  output (tail):\n    " + r["log_tail"].strip().replace("\n", "\n    "))
    if args.plan_out:
        plan = store.plan_json(args.id)
        if plan is None:
            print(f"earthbench: run {args.id} has no plan ({r['reason']})", file=sys.stderr)
            return 1
        with open(args.plan_out, "w") as f:
            f.write(plan)
        print(f"plan written to {args.plan_out}")
    if args.scenario_out:
        store.scenario(r["scenario_digest"]).to_json(args.scenario_out)
        print(f"scenario written to {args.scenario_out}")
    if violations and not (args.plan_out and args.scenario_out):
        print(f"  to see it: earthbench runs{db_option(args.db)} --id {args.id} --plan-out P.json --scenario-out S.json, "
              "then earthbench show --scenario S.json --plan P.json", file=sys.stderr)
    return 0
