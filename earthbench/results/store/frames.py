"""Stored runs read for analysis: :func:`load_runs` (one row per run, metrics as flat columns),
:func:`suite_members` (every aggregate's denominators) and the checks a ranking makes on them
(:func:`check_one_rules`). A run's stored figures are read as they are; whether it succeeded
under another suite's threshold is the scoring rule's to say (:func:`earthbench.results.scoring.relabel`)."""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...errors import StoreError
from ..scoring import relabel, restate
from .database import DEFAULT_DB, LOAD_COLUMNS, Store
from .schema import columns

if TYPE_CHECKING:  # pragma: no cover
    import pandas as pd


def stored_steps(row: Any) -> tuple[tuple[int, float], ...] | None:
    """A ``runs`` row's closed-loop steps ``((actions, compute seconds), …)``, None for an open-loop run."""
    text = row["steps"] if "steps" in row.keys() else None
    return None if not text else tuple((int(n), float(c)) for n, c in json.loads(text))


def _suite_view(store: Store, suite: str) -> tuple[sqlite3.Row, dict[str, sqlite3.Row]]:
    ver = store.suite_version(suite)
    if ver is None:
        known = store.suite_names()
        raise StoreError(f"suite {suite!r} has no runs in {str(store.path)!r}; suites there: {', '.join(known) or '(none)'}")
    members = {r["scenario_digest"]: r for r in store.suite_members(ver["id"])}
    return ver, members


def _joined_runs(store: Store) -> list[sqlite3.Row]:
    """Every run joined with its configuration and environment, in the order stored; a column an
    older schema lacks reads as NULL (0 for ``sealed``)."""
    have_r, have_e = columns(store.db, "runs"), columns(store.db, "environments")
    sealed = "r.sealed" if "sealed" in have_r else "0 AS sealed"
    stamp = "r.isolation, r.processes" if "isolation" in have_r else "NULL AS isolation, NULL AS processes"
    newer = ", ".join([*((f"r.{c}" if c in have_r else f"NULL AS {c}") for c in LOAD_COLUMNS),
                       *((f"e.{c}" if c in have_e else f"NULL AS {c}") for c in ("earthbench_version", "plugin"))])
    prep = ", ".join(f"r.{c}" if c in have_r else f"NULL AS {c}" for c in ("prepare_s", "prepare_cpu_s"))
    prep += ", r.rules" if "rules" in have_r else ", 1 AS rules"
    return store.db.execute(
        f"""SELECT r.id, r.suite, r.suite_digest, r.scenario_id, r.scenario_digest, r.family, r.seed, r.track,
                  r.target_volume, r.planner, r.planner_version, r.config_hash, c.config, r.reason, r.success,
                  r.threshold, r.solve_time_s, r.solve_cpu_s, r.startup_s, r.peak_rss_mb, {prep}, r.metrics,
                  r.violations, r.error, r.log_tail, r.exit_status, r.cores, r.started_at, r.finished_at, r.rescored_at,
                  {stamp}, e.hostname, e.cpu_model, e.cores AS cpu_cores, e.os, e.python, e.packages,
                  e.project_commit, e.plugin_commit, {sealed}, {newer}
           FROM runs r LEFT JOIN planner_configs c ON c.id = r.planner_config_id
                       LEFT JOIN environments e ON e.id = r.environment_id
           ORDER BY r.id"""
    ).fetchall()


def load_runs(db: str | Path | Store = DEFAULT_DB, suite: str | None = None) -> pd.DataFrame:
    """Stored runs as a pandas DataFrame, one row per run, metrics as flat columns.

    Without ``suite``: every run, labelled with the suite it ran under. With ``suite``: the
    runs of that suite's scenarios (its most recently run version), whichever suite ran them,
    relabelled with the suite's name, digest, scenario ids and threshold, and ``success`` as the
    scoring rule says under that threshold (:func:`earthbench.results.scoring.relabel`).

    Columns: ``id``, ``suite``, ``suite_digest``, ``scenario_id``, ``scenario_digest``,
    ``family``, ``seed``, ``track``, ``target_volume``, ``planner``, ``planner_version``,
    ``config_hash``, ``config`` (JSON text), ``reason`` (ok | invalid | timeout | memory |
    error | crashed), ``success`` (bool), ``threshold``, ``solve_time_s``, ``solve_cpu_s``,
    ``startup_s``, ``peak_rss_mb``, ``prepare_s`` and ``prepare_cpu_s`` (the planner's preparation
    the run used, NaN without one), ``rules`` (the version of the referee's rules that judged it:
    1 for a run stored before versions were recorded), then every metric of :func:`earthbench.results.scoring.evaluate` — ``valid``,
    ``n_violations`` (the metric ``violations``, renamed), ``loaded_volume``,
    ``volume_ratio``, ``makespan_s``, ``time_per_m3``, ``time_per_m3_lower_bound``,
    ``time_per_m3_ratio``, ``digs``, ``dumps``, ``mean_bucket_fill``, ``travel_m``,
    ``volume_prediction_error``, ``makespan_prediction_error`` and any metric a plugin adds —
    then ``violation_rules`` (comma-separated rules broken), ``error``, ``log_tail`` (the end
    of the case's stdout/stderr), ``exit_status``,
    ``cores``, ``started_at``, ``finished_at``, ``rescored_at``, ``isolation`` (the fences the
    case ran in: ``namespaces+cgroup-v1`` …, or ``none``), ``processes`` (the most processes it
    held, from its cgroup) and the environment:
    ``hostname``, ``cpu_model``, ``cpu_cores``, ``os``, ``python``, ``packages`` (JSON text),
    ``project_commit`` (the commit the installed earthbench was built from, ``+dirty`` when its
    tree had changes), ``plugin_commit``, ``sealed`` (a run of a sealed draw, :mod:`earthbench.seal`),
    ``earthbench_version``, ``plugin`` (JSON text: the planner's distribution, version and source
    commit), and the machine's load around the case: ``load_before``, ``load_after``, ``steal_share``
    (missing in stores written before schema version 5). Metrics are NaN for runs without a plan
    (timeout, memory, error, crashed); ``time_per_m3`` and ``time_per_target_m3`` are ``inf`` when a
    plan loaded nothing or fell short of the target.
    """
    import pandas as pd

    store = db if isinstance(db, Store) else Store(db, create=False)
    try:
        view = _suite_view(store, suite) if suite else None
        rows = _joined_runs(store)
    finally:
        if not isinstance(db, Store):
            store.close()
    head = ["id", "suite", "suite_digest", "scenario_id", "scenario_digest", "family", "seed", "track", "target_volume",
            "planner", "planner_version", "config_hash", "config", "reason", "success", "threshold", "solve_time_s",
            "solve_cpu_s", "startup_s", "peak_rss_mb", "prepare_s", "prepare_cpu_s", "rules"]
    tail = ["violation_rules", "error", "log_tail", "exit_status", "cores", "started_at", "finished_at", "rescored_at",
            "isolation", "processes", "hostname", "cpu_model", "cpu_cores", "os", "python", "packages", "project_commit",
            "plugin_commit", "sealed", *LOAD_COLUMNS, "earthbench_version", "plugin"]
    metric_names: list[str] = []
    records = []
    for r in rows:
        d = {k: r[k] for k in head}
        d["success"] = bool(r["success"])
        metrics = restate(json.loads(r["metrics"])) if r["metrics"] else {}
        if view is not None:
            ver, members = view
            m = members.get(r["scenario_digest"])
            if m is None:
                continue
            d.update(suite=ver["name"], suite_digest=ver["digest"], scenario_id=m["scenario_id"], family=m["family"],
                     seed=m["seed"], threshold=ver["threshold"])
        for k, v in metrics.items():
            k = "n_violations" if k == "violations" else k
            if k in ("success", "solve_time_s", "solve_cpu_s", "target_volume"):
                continue
            if k not in metric_names:
                metric_names.append(k)
            d[k] = v
        d["violation_rules"] = ",".join(sorted({v["rule"] for v in json.loads(r["violations"] or "[]")}))
        for k in tail[1:]:
            d[k] = r[k]
        d["isolation"] = d["isolation"] or "none"  # stored before the stamp existed: per-process fences
        d["sealed"] = bool(r["sealed"])
        records.append(d)
    df = pd.DataFrame.from_records(records, columns=head + metric_names + tail).infer_objects()
    return df if view is None else relabel(df)


def rules_versions(runs: pd.DataFrame) -> list[int]:
    """The versions of the referee's rules that judged ``runs`` (a :func:`load_runs` frame), lowest first."""
    return sorted({int(v) for v in runs["rules"].dropna()}) if "rules" in runs and len(runs) else []


def check_one_rules(runs: pd.DataFrame, *stores: str | Path | Store) -> None:
    """Refuse to rank ``runs`` judged under more than one version of the referee's rules: a
    ranking never mixes them (docs/referee.md "Rules versions"). The error names the command that
    re-judges ``stores`` under this earthbench's rules."""
    versions = rules_versions(runs)
    if len(versions) > 1:
        from ...referee import RULES_VERSION

        counts = runs["rules"].value_counts()
        judged = ", ".join(f"{int(counts[v])} under rules {v}" for v in versions)
        fix = "; ".join(f"earthbench rescore --db {getattr(s, 'path', s)}" for s in stores)
        raise StoreError(f"these runs were judged under different versions of the referee's rules ({judged}); "
                         f"a ranking never mixes them: re-judge them under this earthbench's rules {RULES_VERSION} "
                         f"with `{fix}` (it reruns no planner)")


def suite_members(db: str | Path | Store, suites: Iterable[str]) -> pd.DataFrame:
    """The scenarios of each suite's most recently run version: ``suite``, ``scenario_digest``,
    ``scenario_id``, ``family``, ``target_volume``, ``seed`` (the denominators of every aggregate)."""
    import pandas as pd

    store = db if isinstance(db, Store) else Store(db, create=False)
    try:
        rows = []
        for name in suites:
            ver = store.suite_version(name)
            if ver is None:
                continue
            for r in store.db.execute(
                "SELECT m.scenario_digest, m.scenario_id, m.family, s.target_volume, m.seed FROM suite_scenarios m "
                "LEFT JOIN scenarios s ON s.digest = m.scenario_digest WHERE m.suite_id=?", (ver["id"],)
            ):
                target = r[3]
                if target is None:  # no run stored yet: the id's documented tail, SUITE/FAMILY/sSEED/vTARGET
                    tail = r[1].rsplit("/v", 1)
                    target = float(tail[1]) if len(tail) == 2 and tail[1].replace(".", "", 1).isdigit() else None
                rows.append((name, r[0], r[1], r[2], target, r[4]))
    finally:
        if not isinstance(db, Store):
            store.close()
    return pd.DataFrame(rows, columns=["suite", "scenario_digest", "scenario_id", "family", "target_volume", "seed"])
