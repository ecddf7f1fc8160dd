"""The results store: one SQLite file (WAL mode), one row per run, one transaction per case.

Why SQLite: embedded, a single file to copy or merge, safe against a killed writer (a run
killed mid-case loses only that case: its transaction never commits), and readable by
pandas. Tables:

* ``runs`` — one row per finished case: suite and suite digest, scenario id/digest/family/
  seed, planner name/version/config hash, termination ``reason``, ``success``, the main
  metrics as real columns, every metric as JSON (``metrics``), the referee's ``violations``
  (JSON), the plan itself (zlib-compressed JSON, so any run can be re-scored), the error
  text and the tail of the case's output. ``UNIQUE(suite, scenario_digest, planner,
  planner_version, config_hash)`` is the resume key: a case is stored at most once per suite.
  The suite is part of the key because a run is scored under its suite's threshold.
* ``planner_configs`` — (name, version, config hash) → the full configuration as JSON.
* ``environments`` — CPU model, cores, OS, Python and package versions, git commits of the
  project and of the planner's plugin, hostname; deduplicated by a hash of their content.
* ``scenarios`` — each scenario's JSON (compressed) by digest, so re-scoring needs no generator.

The schema version is ``PRAGMA user_version`` and the file is tagged with
``PRAGMA application_id``; a database from a newer schema is refused, never altered.
"""

from __future__ import annotations

import hashlib
import json
import math
import sqlite3
import zlib
from collections.abc import Iterable
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .errors import StoreError
from .world import Scenario

if TYPE_CHECKING:  # pragma: no cover
    import pandas as pd

    from .runner import Case, CaseResult

SCHEMA_VERSION = 1
APPLICATION_ID = 0x45424E43  # "EBNC"
DEFAULT_DB = "earthbench.db"

#: Metrics kept as real columns of ``runs`` (all metrics are also in the ``metrics`` JSON).
METRIC_COLUMNS = (
    "valid", "volume_ratio", "loaded_volume", "makespan_s", "time_per_m3", "time_per_m3_ratio",
    "digs", "mean_bucket_fill", "travel_m",
)

_SCHEMA = """
CREATE TABLE environments (
    id INTEGER PRIMARY KEY,
    hash TEXT NOT NULL UNIQUE,
    hostname TEXT, cpu_model TEXT, cores INTEGER, os TEXT, python TEXT,
    packages TEXT, project_commit TEXT, plugin_commit TEXT
);
CREATE TABLE planner_configs (
    id INTEGER PRIMARY KEY,
    name TEXT NOT NULL, version TEXT NOT NULL, config_hash TEXT NOT NULL,
    config TEXT NOT NULL, source TEXT,
    UNIQUE (name, version, config_hash)
);
CREATE TABLE scenarios (
    digest TEXT PRIMARY KEY,
    id TEXT NOT NULL, track TEXT NOT NULL, target_volume REAL NOT NULL,
    doc BLOB NOT NULL
);
CREATE TABLE runs (
    id INTEGER PRIMARY KEY,
    suite TEXT NOT NULL, suite_digest TEXT NOT NULL,
    scenario_id TEXT NOT NULL, scenario_digest TEXT NOT NULL REFERENCES scenarios(digest),
    family TEXT, seed INTEGER, track TEXT, target_volume REAL,
    planner TEXT NOT NULL, planner_version TEXT NOT NULL, config_hash TEXT NOT NULL,
    planner_config_id INTEGER REFERENCES planner_configs(id),
    environment_id INTEGER REFERENCES environments(id),
    reason TEXT NOT NULL, success INTEGER NOT NULL, threshold REAL NOT NULL,
    solve_time_s REAL, solve_cpu_s REAL, startup_s REAL, peak_rss_mb REAL,
    valid INTEGER, volume_ratio REAL, loaded_volume REAL, makespan_s REAL, time_per_m3 REAL,
    time_per_m3_ratio REAL, digs INTEGER, mean_bucket_fill REAL, travel_m REAL,
    metrics TEXT, violations TEXT, plan BLOB, error TEXT, log_tail TEXT,
    exit_status INTEGER, cores TEXT, started_at TEXT, finished_at TEXT, rescored_at TEXT,
    UNIQUE (suite, scenario_digest, planner, planner_version, config_hash)
);
CREATE INDEX runs_planner ON runs (planner, planner_version);
"""


def _compress(text: str) -> bytes:
    return zlib.compress(text.encode(), 6)


def _decompress(blob: bytes | None) -> str | None:
    return None if blob is None else zlib.decompress(blob).decode()


def _json(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True)  # inf/nan as JSON extensions: Python reads them back


class Store:
    """An open results database. Use as a context manager; writes happen in :meth:`record`."""

    def __init__(self, path: str | Path = DEFAULT_DB, *, timeout: float = 10.0, create: bool = True):
        self.path = Path(path)
        if not create and not self.path.exists():
            raise StoreError(f"no results database at {str(self.path)!r}; run `earthbench run SUITE --db {self.path}` first")
        if self.path.is_dir():
            raise StoreError(f"{str(self.path)!r} is a directory, not a results database file")
        try:
            self.db = sqlite3.connect(str(self.path), timeout=timeout, isolation_level=None)
        except sqlite3.Error as exc:
            raise StoreError(f"cannot open results database {str(self.path)!r}: {exc}") from None
        self.db.row_factory = sqlite3.Row
        try:
            self._open()
        except sqlite3.DatabaseError as exc:
            self.db.close()
            raise StoreError(self._explain(exc)) from None
        except StoreError:
            self.db.close()
            raise

    def _explain(self, exc: sqlite3.Error) -> str:
        msg = str(exc)
        if "locked" in msg or "busy" in msg:
            return (f"results database {str(self.path)!r} is locked by another process (another `earthbench run`?); "
                    "wait for it to finish or use another --db")
        if "not a database" in msg or "malformed" in msg:
            return f"{str(self.path)!r} is not an SQLite database (not an earthbench results file?); choose another --db"
        return f"results database {str(self.path)!r}: {msg}"

    def _open(self) -> None:
        app = self.db.execute("PRAGMA application_id").fetchone()[0]
        version = self.db.execute("PRAGMA user_version").fetchone()[0]
        tables = {r[0] for r in self.db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if app == 0 and not tables:
            self.db.execute("PRAGMA journal_mode=WAL")
            self.db.execute("BEGIN IMMEDIATE")
            try:
                if not {r[0] for r in self.db.execute("SELECT name FROM sqlite_master WHERE type='table'")}:
                    for stmt in _SCHEMA.strip().split(";"):
                        if stmt.strip():
                            self.db.execute(stmt)
                    self.db.execute(f"PRAGMA application_id = {APPLICATION_ID}")
                    self.db.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
                self.db.execute("COMMIT")
            except BaseException:
                self.db.execute("ROLLBACK")
                raise
            return
        if app != APPLICATION_ID:
            raise StoreError(f"{str(self.path)!r} is an SQLite database but not an earthbench results store; choose another --db")
        if version > SCHEMA_VERSION:
            raise StoreError(
                f"results database {str(self.path)!r} has schema version {version}, newer than this earthbench "
                f"understands ({SCHEMA_VERSION}); upgrade earthbench to use it (it was left untouched)"
            )
        self.db.execute("PRAGMA journal_mode=WAL")

    def check_writable(self) -> None:
        """Fail now, with a clear message, if another process holds the write lock."""
        try:
            self.db.execute("BEGIN IMMEDIATE")
            self.db.execute("COMMIT")
        except sqlite3.OperationalError as exc:
            raise StoreError(self._explain(exc)) from None

    def close(self) -> None:
        self.db.close()

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- writing -----------------------------------------------------------------------------
    def finished_keys(self, suite: str | None = None) -> set[tuple[str, str, str, str, str]]:
        """Resume keys (suite, scenario digest, planner, version, config hash) already stored."""
        sql = "SELECT suite, scenario_digest, planner, planner_version, config_hash FROM runs"
        rows = self.db.execute(sql + " WHERE suite = ?", (suite,)) if suite else self.db.execute(sql)
        return {tuple(r) for r in rows}  # type: ignore[misc]

    def record(self, case: Case, result: CaseResult, *, replace: bool = False) -> bool:
        """Store one finished case in one transaction. Returns False if it was already stored."""
        if result.reason == "cancelled":
            raise ValueError("a cancelled case is never stored")
        sc = case.scenario
        m = result.metrics or {}
        try:
            self.db.execute("BEGIN IMMEDIATE")
            try:
                if replace:
                    self.db.execute(
                        "DELETE FROM runs WHERE suite=? AND scenario_digest=? AND planner=? AND planner_version=? AND config_hash=?",
                        case.key,
                    )
                elif self.db.execute(
                    "SELECT 1 FROM runs WHERE suite=? AND scenario_digest=? AND planner=? AND planner_version=? AND config_hash=?",
                    case.key,
                ).fetchone():
                    self.db.execute("ROLLBACK")
                    return False
                self._scenario(sc)
                cfg = self._planner_config(case)
                env = self._environment(result.environment)
                row: dict[str, Any] = {
                    "suite": case.suite, "suite_digest": case.suite_digest,
                    "scenario_id": sc.id, "scenario_digest": sc.digest,
                    "family": sc.meta.get("family"), "seed": sc.meta.get("seed"),
                    "track": sc.track, "target_volume": sc.task.target_volume,
                    "planner": case.planner.name, "planner_version": case.planner.version,
                    "config_hash": case.planner.config_hash, "planner_config_id": cfg, "environment_id": env,
                    "reason": result.reason, "success": int(result.success), "threshold": case.threshold,
                    "solve_time_s": result.solve_time_s, "solve_cpu_s": result.solve_cpu_s,
                    "startup_s": result.startup_s, "peak_rss_mb": result.peak_rss_mb,
                    **{c: (None if c not in m else (int(m[c]) if isinstance(m[c], bool) else m[c])) for c in METRIC_COLUMNS},
                    "metrics": _json(m) if result.metrics is not None else None,
                    "violations": _json(list(result.violations)),
                    "plan": _compress(result.plan_json) if result.plan_json is not None else None,
                    "error": result.error, "log_tail": result.log_tail, "exit_status": result.exit_status,
                    "cores": ",".join(map(str, result.cores)),
                    "started_at": result.started_at, "finished_at": result.finished_at,
                }
                cols = ", ".join(row)
                marks = ", ".join(f":{c}" for c in row)
                self.db.execute(f"INSERT INTO runs ({cols}) VALUES ({marks})", row)
                self.db.execute("COMMIT")
                return True
            except BaseException:
                if self.db.in_transaction:
                    self.db.execute("ROLLBACK")
                raise
        except sqlite3.OperationalError as exc:
            raise StoreError(self._explain(exc)) from None

    def _scenario(self, sc: Scenario) -> None:
        if not self.db.execute("SELECT 1 FROM scenarios WHERE digest=?", (sc.digest,)).fetchone():
            self.db.execute(
                "INSERT INTO scenarios (digest, id, track, target_volume, doc) VALUES (?, ?, ?, ?, ?)",
                (sc.digest, sc.id, sc.track, sc.task.target_volume, _compress(sc.to_json())),
            )

    def _planner_config(self, case: Case) -> int:
        p = case.planner
        self.db.execute(
            "INSERT OR IGNORE INTO planner_configs (name, version, config_hash, config, source) VALUES (?, ?, ?, ?, ?)",
            (p.name, p.version, p.config_hash, _json(p.config), p.source),
        )
        return self.db.execute(
            "SELECT id FROM planner_configs WHERE name=? AND version=? AND config_hash=?", (p.name, p.version, p.config_hash)
        ).fetchone()[0]

    def _environment(self, env: dict[str, Any]) -> int | None:
        if not env:
            return None
        h = hashlib.sha256(_json(env).encode()).hexdigest()
        self.db.execute(
            "INSERT OR IGNORE INTO environments (hash, hostname, cpu_model, cores, os, python, packages, project_commit, plugin_commit)"
            " VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (h, env.get("hostname"), env.get("cpu_model"), env.get("cores"), env.get("os"), env.get("python"),
             _json(env.get("packages", {})), env.get("project_commit"), env.get("plugin_commit")),
        )
        return self.db.execute("SELECT id FROM environments WHERE hash=?", (h,)).fetchone()[0]

    def update_score(self, run_id: int, reason: str, metrics: dict[str, Any], violations: Iterable[dict[str, Any]]) -> None:
        """Replace the referee's findings of one run (``earthbench rescore``), in one transaction."""
        cols = {c: (None if c not in metrics else (int(metrics[c]) if isinstance(metrics[c], bool) else metrics[c])) for c in METRIC_COLUMNS}
        sets = ", ".join(f"{c}=:{c}" for c in cols)
        try:
            with self.db:
                self.db.execute("BEGIN IMMEDIATE")
                self.db.execute(
                    f"UPDATE runs SET reason=:reason, success=:success, metrics=:metrics, violations=:violations, rescored_at=:at, {sets} WHERE id=:id",
                    {**cols, "reason": reason, "success": int(bool(metrics.get("success"))), "metrics": _json(metrics),
                     "violations": _json(list(violations)), "at": datetime.now(timezone.utc).isoformat(timespec="seconds"), "id": run_id},
                )
        except sqlite3.OperationalError as exc:
            raise StoreError(self._explain(exc)) from None

    # -- reading -----------------------------------------------------------------------------
    def query(self, *, suite: str | None = None, planner: Iterable[str] | None = None, reason: Iterable[str] | None = None,
              scenario: str | None = None, run_id: int | None = None, limit: int | None = None) -> list[sqlite3.Row]:
        """Rows of ``runs`` (newest first) matching every given filter; ``scenario`` is a substring of the id."""
        where, args = [], []
        if suite:
            where.append("suite = ?")
            args.append(suite)
        if planner:
            pl = list(planner)
            where.append(f"planner IN ({', '.join('?' * len(pl))})")
            args += pl
        if reason:
            rs = list(reason)
            where.append(f"reason IN ({', '.join('?' * len(rs))})")
            args += rs
        if scenario:
            where.append("instr(scenario_id, ?) > 0")
            args.append(scenario)
        if run_id is not None:
            where.append("id = ?")
            args.append(run_id)
        sql = "SELECT * FROM runs" + (" WHERE " + " AND ".join(where) if where else "") + " ORDER BY id DESC"
        if limit:
            sql += f" LIMIT {int(limit)}"
        return self.db.execute(sql, args).fetchall()

    def plan_json(self, run_id: int) -> str | None:
        row = self.db.execute("SELECT plan FROM runs WHERE id=?", (run_id,)).fetchone()
        return _decompress(row[0]) if row else None

    def scenario(self, digest: str) -> Scenario:
        row = self.db.execute("SELECT doc FROM scenarios WHERE digest=?", (digest,)).fetchone()
        if row is None:
            raise StoreError(f"scenario {digest[:12]}… is not in {str(self.path)!r}")
        return Scenario.from_json(_decompress(row[0]))


def load_runs(db: str | Path | Store = DEFAULT_DB) -> pd.DataFrame:
    """Every stored run as a pandas DataFrame, one row per run, metrics as flat columns.

    Columns: ``id``, ``suite``, ``suite_digest``, ``scenario_id``, ``scenario_digest``,
    ``family``, ``seed``, ``track``, ``target_volume``, ``planner``, ``planner_version``,
    ``config_hash``, ``config`` (JSON text), ``reason`` (ok | invalid | timeout | memory |
    error | crashed), ``success`` (bool), ``threshold``, ``solve_time_s``, ``solve_cpu_s``,
    ``startup_s``, ``peak_rss_mb``, then every metric of :func:`metrics.evaluate` — ``valid``,
    ``n_violations`` (the metric ``violations``, renamed), ``loaded_volume``,
    ``volume_ratio``, ``makespan_s``, ``time_per_m3``, ``time_per_m3_lower_bound``,
    ``time_per_m3_ratio``, ``digs``, ``dumps``, ``mean_bucket_fill``, ``travel_m``,
    ``volume_prediction_error``, ``makespan_prediction_error`` and any metric a plugin adds —
    then ``violation_rules`` (comma-separated rules broken), ``error``, ``exit_status``,
    ``cores``, ``started_at``, ``finished_at``, ``rescored_at`` and the environment:
    ``hostname``, ``cpu_model``, ``cpu_cores``, ``os``, ``python``, ``packages`` (JSON text),
    ``project_commit``, ``plugin_commit``. Metrics are NaN for runs without a plan (timeout,
    memory, error, crashed); ``time_per_m3`` is ``inf`` when a plan loaded nothing.
    """
    import pandas as pd

    store = db if isinstance(db, Store) else Store(db, create=False)
    try:
        rows = store.db.execute(
            """SELECT r.id, r.suite, r.suite_digest, r.scenario_id, r.scenario_digest, r.family, r.seed, r.track,
                      r.target_volume, r.planner, r.planner_version, r.config_hash, c.config, r.reason, r.success,
                      r.threshold, r.solve_time_s, r.solve_cpu_s, r.startup_s, r.peak_rss_mb, r.metrics,
                      r.violations, r.error, r.exit_status, r.cores, r.started_at, r.finished_at, r.rescored_at,
                      e.hostname, e.cpu_model, e.cores AS cpu_cores, e.os, e.python, e.packages,
                      e.project_commit, e.plugin_commit
               FROM runs r LEFT JOIN planner_configs c ON c.id = r.planner_config_id
                           LEFT JOIN environments e ON e.id = r.environment_id
               ORDER BY r.id"""
        ).fetchall()
    finally:
        if not isinstance(db, Store):
            store.close()
    head = ["id", "suite", "suite_digest", "scenario_id", "scenario_digest", "family", "seed", "track", "target_volume",
            "planner", "planner_version", "config_hash", "config", "reason", "success", "threshold", "solve_time_s",
            "solve_cpu_s", "startup_s", "peak_rss_mb"]
    tail = ["violation_rules", "error", "exit_status", "cores", "started_at", "finished_at", "rescored_at", "hostname",
            "cpu_model", "cpu_cores", "os", "python", "packages", "project_commit", "plugin_commit"]
    metric_names: list[str] = []
    records = []
    for r in rows:
        d = {k: r[k] for k in head if k not in ("success",)}
        d["success"] = bool(r["success"])
        metrics = json.loads(r["metrics"]) if r["metrics"] else {}
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
        records.append(d)
    df = pd.DataFrame.from_records(records, columns=head + metric_names + tail)
    return df.infer_objects()


def summary_rows(store: Store, suite: str, planners: Iterable[str] | None = None) -> list[dict[str, Any]]:
    """Per-planner counts and central values of one suite, for the table after a run."""
    import statistics

    out = []
    for (name,) in store.db.execute("SELECT DISTINCT planner FROM runs WHERE suite=? ORDER BY planner", (suite,)).fetchall():
        if planners is not None and name not in planners:
            continue
        rows = store.db.execute(
            "SELECT reason, success, volume_ratio, time_per_m3, solve_time_s FROM runs WHERE suite=? AND planner=?", (suite, name)
        ).fetchall()
        counts = {}
        for r in rows:
            counts[r["reason"]] = counts.get(r["reason"], 0) + 1
        vr = [r["volume_ratio"] for r in rows if r["volume_ratio"] is not None]
        tpm = [r["time_per_m3"] for r in rows if r["time_per_m3"] is not None and r["reason"] == "ok" and math.isfinite(r["time_per_m3"])]
        st = [r["solve_time_s"] for r in rows if r["solve_time_s"] is not None]
        out.append({
            "planner": name, "runs": len(rows), "success": sum(r["success"] for r in rows) / len(rows),
            "counts": counts,
            "volume_ratio_mean": statistics.fmean(vr) if vr else None,
            "volume_ratio_sd": statistics.stdev(vr) if len(vr) > 1 else None,
            "time_per_m3_median": statistics.median(tpm) if tpm else None,
            "solve_time_median": statistics.median(st) if st else None,
        })
    return out
