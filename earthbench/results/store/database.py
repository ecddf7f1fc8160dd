"""The results store: one SQLite file (WAL mode), one row per run, one transaction per case
(docs/DESIGN.md §8). :class:`Store` opens, creates and migrates a store and reads and writes it
through named methods; the tables are those of :mod:`earthbench.results.store.schema`.

Why SQLite: embedded, a single file to copy or merge, safe against a killed writer (a run
killed mid-case loses only that case: its transaction never commits), and readable by
pandas. Tables:

* ``runs`` — one row per finished case: scenario id/digest/family/seed, the suite it ran
  under (provenance) and its digest, planner name/version/config hash, termination
  ``reason``, ``success`` (under that suite's threshold), the main metrics as real columns,
  every metric as JSON (``metrics``), the referee's ``violations`` (JSON), the plan itself
  (zlib-compressed JSON, so any run can be re-scored), the error text and the tail of the
  case's output, and for a closed-loop run its ``steps`` (JSON: ``[actions, compute seconds]``
  per planner call, in order, so the stored plan splits back into its steps; docs/DESIGN.md §6).
  ``UNIQUE(scenario_digest, planner, planner_version, config_hash)`` is the
  resume key: a case is stored once, whichever suite ran it (the budget is part of the
  scenario digest, so runs under different budgets never mix).
* ``suites`` and ``suite_scenarios`` — each suite version (name, digest, threshold) that was
  run, and its scenarios' ids and digests: how a suite finds its runs, including those stored
  while running another suite with the same scenarios (``standard`` includes ``paper-switch``).
* ``planner_configs`` — (name, version, config hash) → the full configuration as JSON.
* ``environments`` — CPU model, cores, OS, Python and package versions, the build of earthbench
  (version and the commit it was built from, :mod:`earthbench.results.provenance`) and of the planner's
  plugin (its distribution and source commit, or a plugin file's SHA-256), hostname;
  deduplicated by a hash of their content.
* ``scenarios`` — each scenario's JSON (compressed) by digest, so re-scoring needs no generator.
* ``spot_checks`` — each re-timing of ``earthbench verify --sample`` (:mod:`earthbench.publishing.verify`), so a
  leaderboard's stamp can say how its solve times held up on another machine.

Every SQL statement of earthbench is in this package (:mod:`earthbench.results.store`): the rest reads
and writes a store through :class:`Store`'s named methods and the readers of
:mod:`earthbench.results.store.frames`.

Sealed draws (:mod:`earthbench.seal`): a sealed suite version's row names the public suite it
was drawn from (``sealed_from``), that suite's digest (``public_digest``) and the draw's
``commitment``; its scenarios and runs carry ``sealed = 1``. Nothing of the key is stored.

The schema version is ``PRAGMA user_version`` and the file is tagged with
``PRAGMA application_id``; a database from a newer schema is refused, never altered. A store
from an older schema opened for writing is brought up to date by the named steps of
:data:`~earthbench.results.store.schema.MIGRATIONS`; read-only, it is read as it is, a column its
version lacks read as its default (docs/DESIGN.md §8, "Schema versions").
"""

from __future__ import annotations

import hashlib
import json
import os
import sqlite3
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from datetime import datetime, UTC
from pathlib import Path
from urllib.parse import quote
from typing import TYPE_CHECKING, Any, Protocol

from ...errors import StoreError
from ...world import Scenario
from .blobs import compress, decompress
from .schema import APPLICATION_ID, SCHEMA_VERSION, columns, migrate, write_schema

if TYPE_CHECKING:  # pragma: no cover
    from ..records import Case, CaseResult, SpotCheck


DEFAULT_DB = "earthbench.db"


def default_db() -> str:
    """The store every command uses unless told otherwise: ``$EARTHBENCH_DB``, else :data:`DEFAULT_DB`."""
    return os.environ.get("EARTHBENCH_DB", DEFAULT_DB)


#: Metrics kept as real columns of ``runs`` (all metrics are also in the ``metrics`` JSON).
#: The machine's load around a case (:mod:`earthbench.running.harness.load`), columns of ``runs`` since version 3.
LOAD_COLUMNS = ("load_before", "load_after", "steal_share")

METRIC_COLUMNS = (
    "valid", "volume_ratio", "loaded_volume", "makespan_s", "time_per_m3", "time_per_m3_ratio",
    "digs", "mean_bucket_fill", "travel_m",
)


def _rules_version() -> int:
    """The version of the rules this earthbench's referee judges by (loaded with the first run written)."""
    from ...referee import RULES_VERSION

    return RULES_VERSION


class SuiteRecord(Protocol):
    """What :meth:`Store.register_suite` reads of a suite: a loaded :class:`~earthbench.results.suite.Suite`,
    or a suite version read back from another store (:mod:`earthbench.publishing.merge`)."""

    @property
    def name(self) -> str: ...
    @property
    def digest(self) -> str: ...
    @property
    def track(self) -> str: ...
    @property
    def success_threshold(self) -> float: ...
    @property
    def description(self) -> str: ...
    @property
    def scenarios(self) -> Any: ...




def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def _json(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True)  # inf/nan as JSON extensions: Python reads them back


class Store:
    """An open results database. Use as a context manager; writes happen in :meth:`record`."""

    def __init__(self, path: str | Path = DEFAULT_DB, *, timeout: float = 10.0, create: bool = True, read_only: bool = False):
        """``read_only`` opens an existing store without ever writing to its file (an input to verify)."""
        self.path = Path(path)
        self.read_only = read_only
        if (read_only or not create) and not self.path.exists():
            raise StoreError(f"no results database at {str(self.path)!r}; run `earthbench run SUITE --db {self.path}` first")
        if self.path.is_dir():
            raise StoreError(f"{str(self.path)!r} is a directory, not a results database file")
        if create and not read_only and not self.path.exists():
            self._create(timeout)
        try:
            # read-only; without a write-ahead log beside it (no writer, nothing to replay) the file is
            # all there is, and `immutable` keeps SQLite from creating -wal/-shm files next to it
            ro = "mode=ro" + ("" if Path(f"{self.path}-wal").exists() else "&immutable=1")
            target = f"file:{quote(str(self.path.resolve()))}?{ro}" if read_only else str(self.path)
            self.db = sqlite3.connect(target, timeout=timeout, isolation_level=None, uri=read_only)
        except sqlite3.Error as exc:
            raise StoreError(f"cannot open results database {str(self.path)!r}: {exc}") from None
        self.db.row_factory = sqlite3.Row
        self._logged = False  # write-ahead logging switched on by this connection (see _begin)
        try:
            self._open()
        except sqlite3.DatabaseError as exc:
            self.db.close()
            raise StoreError(self._explain(exc)) from None
        except StoreError:
            self.db.close()
            raise

    def _create(self, timeout: float) -> None:
        """Make a new store safe to race: it is built complete beside its path, then linked into
        place; whoever links second keeps the first one's store and opens it as an existing one
        (waiting for its lock as any writer does). Where the file system has no hard links the
        store is created in place, as before."""
        tmp = self.path.with_name(f".{self.path.name}.new-{os.getpid()}-{os.urandom(4).hex()}")
        try:
            db = sqlite3.connect(tmp, timeout=timeout, isolation_level=None)
            try:
                db.execute("PRAGMA journal_mode=WAL")
                with db:
                    db.execute("BEGIN IMMEDIATE")
                    write_schema(db)
            finally:
                db.close()
            os.link(tmp, self.path)
        except FileExistsError:
            pass  # another process created it first: open theirs
        except (OSError, sqlite3.Error):
            pass  # no hard links (or no such folder): the in-place path below creates it or says why not
        finally:
            for p in (tmp, Path(f"{tmp}-wal"), Path(f"{tmp}-shm"), Path(f"{tmp}-journal")):
                p.unlink(missing_ok=True)

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
        if app == 0 and not tables and not self.read_only:
            self._begin()
            try:
                if not {r[0] for r in self.db.execute("SELECT name FROM sqlite_master WHERE type='table'")}:
                    write_schema(self.db)
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
        if not self.read_only and version < SCHEMA_VERSION:
            self._log_ahead()
            migrate(self.db, version)

    def _log_ahead(self) -> None:
        if not self._logged:
            self.db.execute("PRAGMA journal_mode=WAL")
            self._logged = True

    def _begin(self) -> None:
        """Start a write. A store turns on write-ahead logging (readers never wait for a writer) at its
        first write, not when it is opened: reading a published store (`leaderboard`, `merge`, `runs`)
        leaves its file byte for byte as committed."""
        self._log_ahead()
        self.db.execute("BEGIN IMMEDIATE")

    def check_writable(self) -> None:
        """Fail now, with a clear message, if another process holds the write lock."""
        try:
            self._begin()
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
    def finished_keys(self, *, reason: str | None = None, succeeded: bool = False) -> set[tuple[str, str, str, str]]:
        """Resume keys (scenario digest, planner, version, config hash) already stored; only those
        that ended with ``reason``, or that succeeded under their suite's threshold, when asked."""
        sql = "SELECT scenario_digest, planner, planner_version, config_hash FROM runs"
        if succeeded:
            rows = self.db.execute(sql + " WHERE success=1")
        elif reason is not None:
            rows = self.db.execute(sql + " WHERE reason=?", (reason,))
        else:
            rows = self.db.execute(sql)
        return {tuple(r) for r in rows}  # type: ignore[misc]

    def code_digests(self, planner: str, version: str) -> set[str]:
        """The code digests stored with ``planner``'s runs of ``version`` (unknown ones left out)."""
        rows = self.db.execute("SELECT DISTINCT code_digest FROM runs WHERE planner=? AND planner_version=? "
                               "AND code_digest IS NOT NULL", (planner, version))
        return {r[0] for r in rows}

    def register_suite(self, suite: SuiteRecord) -> int:
        """Record a suite version and its scenarios (once per digest), in one transaction."""
        row = self.db.execute("SELECT id FROM suites WHERE name=? AND digest=?", (suite.name, suite.digest)).fetchone()
        if row:
            return row[0]
        try:
            with self.db:
                self._begin()
                seal = sealed_origin(suite)
                cur = self.db.execute(
                    "INSERT INTO suites (name, digest, track, threshold, description, registered_at, sealed_from, public_digest,"
                    " commitment) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (suite.name, suite.digest, suite.track, suite.success_threshold, suite.description, _now(), *seal),
                )
                sid = cur.lastrowid
                assert sid is not None  # an INSERT always sets it
                self.db.executemany(
                    "INSERT INTO suite_scenarios (suite_id, scenario_id, scenario_digest, family, seed) VALUES (?, ?, ?, ?, ?)",
                    [(sid, sc.id, sc.digest, sc.meta.get("family"), sc.meta.get("seed")) for sc in suite.scenarios],
                )
            return sid
        except sqlite3.OperationalError as exc:
            raise StoreError(self._explain(exc)) from None

    def suite_version(self, name: str) -> sqlite3.Row | None:
        """The most recently registered version (id, digest, threshold, …) of a suite name."""
        return self.db.execute("SELECT * FROM suites WHERE name=? ORDER BY id DESC LIMIT 1", (name,)).fetchone()

    def record(self, case: Case, result: CaseResult, *, replace: bool = False, plan_blob: bytes | None = None) -> bool:
        """Store one finished case in one transaction. Returns False if it was already stored.

        ``plan_blob``: ``result.plan_json`` as another store keeps it, copied without compressing it again (merge).
        """
        if result.reason == "cancelled":
            raise ValueError("a cancelled case is never stored")
        sc = case.scenario
        m = result.metrics or {}
        try:
            self._begin()
            try:
                key_sql = "scenario_digest=? AND planner=? AND planner_version=? AND config_hash=?"
                if replace:
                    self.db.execute(f"DELETE FROM runs WHERE {key_sql}", case.key)
                elif self.db.execute(f"SELECT 1 FROM runs WHERE {key_sql}", case.key).fetchone():
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
                    "plan": plan_blob if plan_blob is not None else compress(result.plan_json) if result.plan_json is not None else None,
                    "error": result.error, "log_tail": result.log_tail, "exit_status": result.exit_status,
                    "cores": ",".join(map(str, result.cores)),
                    "started_at": result.started_at, "finished_at": result.finished_at,
                    "steps": _json([list(s) for s in result.steps]) if result.steps is not None else None,
                    "isolation": result.isolation, "processes": result.processes,
                    "sealed": int(bool(sc.meta.get("sealed"))),
                    **{c: result.machine_load.get(c) for c in LOAD_COLUMNS},
                    "prepare_s": result.prepare_s, "prepare_cpu_s": result.prepare_cpu_s,
                    "code_digest": case.planner.code_digest or None,
                    "rules": result.rules if result.rules is not None else _rules_version(),
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

    def copy_scenarios(self, src: Store, digests: Iterable[str]) -> None:
        """Copy stored scenario documents from ``src`` as they are (no re-encoding), in one transaction.

        For merging: the caller has checked that each document reproduces its digest.
        """
        sealed = "sealed" if "sealed" in columns(src.db, "scenarios") else "0"
        rows = [r for d in digests if (r := src.db.execute(
                f"SELECT digest, id, track, target_volume, doc, {sealed} FROM scenarios WHERE digest=?", (d,)).fetchone())]
        try:
            with self.db:
                self._begin()
                self.db.executemany("INSERT OR IGNORE INTO scenarios (digest, id, track, target_volume, doc, sealed)"
                                    " VALUES (?, ?, ?, ?, ?, ?)", [tuple(r) for r in rows])
        except sqlite3.OperationalError as exc:
            raise StoreError(self._explain(exc)) from None

    def _scenario(self, sc: Scenario) -> None:
        if not self.db.execute("SELECT 1 FROM scenarios WHERE digest=?", (sc.digest,)).fetchone():
            self.db.execute(
                "INSERT INTO scenarios (digest, id, track, target_volume, doc, sealed) VALUES (?, ?, ?, ?, ?, ?)",
                (sc.digest, sc.id, sc.track, sc.task.target_volume, compress(sc.to_json()), int(bool(sc.meta.get("sealed")))),
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
            "INSERT OR IGNORE INTO environments (hash, hostname, cpu_model, cores, os, python, packages, project_commit,"
            " plugin_commit, earthbench_version, plugin) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (h, env.get("hostname"), env.get("cpu_model"), env.get("cores"), env.get("os"), env.get("python"),
             _json(env.get("packages", {})), env.get("project_commit"), env.get("plugin_commit"), env.get("earthbench_version"),
             _json(env["plugin"]) if env.get("plugin") else None),
        )
        return self.db.execute("SELECT id FROM environments WHERE hash=?", (h,)).fetchone()[0]

    def update_score(self, run_id: int, reason: str, metrics: dict[str, Any], violations: Iterable[dict[str, Any]]) -> None:
        """Replace the referee's findings of one run (``earthbench rescore``), judged under this
        referee's rules (:data:`~earthbench.referee.RULES_VERSION`), in one transaction."""
        cols = {
            c: (None if c not in metrics else (int(metrics[c]) if isinstance(metrics[c], bool) else metrics[c])) for c in METRIC_COLUMNS
        }
        sets = ", ".join(f"{c}=:{c}" for c in cols)
        try:
            with self.db:
                self._begin()
                self.db.execute(
                    f"UPDATE runs SET reason=:reason, success=:success, metrics=:metrics, violations=:violations,"
                    f" rescored_at=:at, rules=:rules, {sets} WHERE id=:id",
                    {
                        **cols,
                        "reason": reason,
                        "success": int(bool(metrics.get("success"))),
                        "metrics": _json(metrics),
                        "violations": _json(list(violations)),
                        "at": _now(),
                        "rules": _rules_version(),
                        "id": run_id,
                    },
                )
        except sqlite3.OperationalError as exc:
            raise StoreError(self._explain(exc)) from None

    def mark_rules(self, run_ids: Iterable[int]) -> None:
        """Record that runs without a plan stand under this referee's rules too (``earthbench
        rescore``: their outcome is the harness's, which no rule changes), in one transaction."""
        ids = [(_rules_version(), i) for i in run_ids]
        try:
            with self.db:
                self._begin()
                self.db.executemany("UPDATE runs SET rules=? WHERE id=?", ids)
        except sqlite3.OperationalError as exc:
            raise StoreError(self._explain(exc)) from None

    def record_spot_checks(self, checks: Iterable[SpotCheck]) -> None:
        """Keep spot re-timings in the store they sampled, so the leaderboard's stamp can show them (one transaction)."""
        try:
            with self.db:
                self._begin()
                self.db.executemany(
                    "INSERT INTO spot_checks (checked_at, planner, planner_version, config_hash, run_ids, agree, ratios, "
                    "disagreements, machine, stored_machines, context) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    [(c.checked_at, c.planner, c.version, c.config_hash, json.dumps(c.run_ids), c.agree, json.dumps(c.ratios),
                      json.dumps(c.disagreements), c.machine, json.dumps(c.stored_machines),
                      json.dumps({"cpu_ratios": c.cpu_ratios, "load_stored": c.load_stored, "load_here": c.load_here,
                                  "steal": c.steal}))
                     for c in checks])
        except sqlite3.OperationalError as exc:
            raise StoreError(self._explain(exc)) from None

    @contextmanager
    def unsynced(self) -> Iterator[Store]:
        """Writes that skip the disk sync, for a file nobody reads before it is complete (a merge's new
        output); one synced checkpoint at the end makes them durable."""
        self.db.execute("PRAGMA synchronous=OFF")
        yield self
        self.db.execute("PRAGMA synchronous=FULL")
        self.db.execute("PRAGMA wal_checkpoint(TRUNCATE)")

    # -- reading -----------------------------------------------------------------------------
    def latest_spot_checks(self) -> list[dict[str, Any]]:
        """The most recent spot check of each planner version and configuration, its fields as
        :meth:`record_spot_checks` was given them (none in a store never spot-checked, read as it is)."""
        if not self.db.execute("SELECT 1 FROM sqlite_master WHERE type='table' AND name='spot_checks'").fetchone():
            return []
        rows = self.db.execute(
            "SELECT * FROM spot_checks WHERE id IN (SELECT MAX(id) FROM spot_checks GROUP BY planner, planner_version, config_hash) "
            "ORDER BY planner, planner_version, config_hash").fetchall()
        out = []
        for r in rows:
            ctx = json.loads(r["context"] or "{}") if "context" in r.keys() else {}
            out.append({"planner": r["planner"], "version": r["planner_version"], "config_hash": r["config_hash"],
                        "run_ids": tuple(json.loads(r["run_ids"])), "agree": r["agree"], "ratios": tuple(json.loads(r["ratios"])),
                        "disagreements": tuple(json.loads(r["disagreements"])), "machine": r["machine"],
                        "stored_machines": tuple(json.loads(r["stored_machines"])), "checked_at": r["checked_at"],
                        "cpu_ratios": tuple(ctx.get("cpu_ratios", ())), "load_stored": tuple(ctx.get("load_stored", ())),
                        "load_here": tuple(ctx.get("load_here", ())), "steal": ctx.get("steal")})
        return out

    def query(self, *, suite: str | None = None, planner: Iterable[str] | None = None, reason: Iterable[str] | None = None,
              scenario: str | None = None, run_id: int | None = None, limit: int | None = None) -> list[sqlite3.Row]:
        """Rows of ``runs`` (newest first) matching every given filter; ``scenario`` is a substring of the id."""
        where: list[str] = []
        args: list[Any] = []
        if suite:  # runs of the suite's scenarios, whichever suite ran them
            where.append("(suite = ? OR scenario_digest IN (SELECT ss.scenario_digest FROM suite_scenarios ss "
                         "JOIN suites s ON s.id = ss.suite_id WHERE s.name = ?))")
            args += [suite, suite]
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

    def run_suites(self) -> list[str]:
        """The names of the suites that runs were stored under, sorted (what ``load_runs`` labels them)."""
        return sorted(r[0] for r in self.db.execute("SELECT DISTINCT suite FROM runs WHERE suite IS NOT NULL"))

    def plan_json(self, run_id: int) -> str | None:
        row = self.db.execute("SELECT plan FROM runs WHERE id=?", (run_id,)).fetchone()
        return decompress(row[0]) if row else None

    def scenario(self, digest: str) -> Scenario:
        blob = self.scenario_blob(digest)
        if blob is None:
            raise StoreError(f"scenario {digest[:12]}… is not in {str(self.path)!r}")
        return Scenario.from_text(decompress(blob))

    def scenario_blob(self, digest: str) -> bytes | None:
        """A scenario's document as stored (compressed), unread: a verifier decides what an edited one means."""
        row = self.db.execute("SELECT doc FROM scenarios WHERE digest=?", (digest,)).fetchone()
        return None if row is None else row[0]

    def runs(self, *, labelled: str | None = None) -> list[sqlite3.Row]:
        """Every row of ``runs`` in the order stored; ``labelled``: only those run under that suite name."""
        if labelled is None:
            return self.db.execute("SELECT * FROM runs ORDER BY id").fetchall()
        return self.db.execute("SELECT * FROM runs WHERE suite=? ORDER BY id", (labelled,)).fetchall()

    def run_keys(self) -> list[tuple[int, tuple[str, str, str, str]]]:
        """(run id, resume key) of every run in the order stored: how a merge finds a run stored twice."""
        rows = self.db.execute("SELECT id, scenario_digest, planner, planner_version, config_hash FROM runs ORDER BY id")
        return [(r[0], (r[1], r[2], r[3], r[4])) for r in rows]

    def run_id(self, key: tuple[str, str, str, str]) -> int | None:
        """The id of the run stored under a resume key (scenario digest, planner, version, config hash)."""
        row = self.db.execute("SELECT id FROM runs WHERE scenario_digest=? AND planner=? AND planner_version=? AND config_hash=?",
                              key).fetchone()
        return None if row is None else int(row[0])

    def run_outcome(self, run_id: int) -> tuple[str, bytes | None]:
        """A run's termination reason and its plan as stored (compressed, None without a plan)."""
        row = self.db.execute("SELECT reason, plan FROM runs WHERE id=?", (run_id,)).fetchone()
        return row[0], row[1]

    def run_labels(self) -> list[tuple[str, str, int]]:
        """(suite name, suite digest, how many runs) for each suite label the runs carry."""
        rows = self.db.execute("SELECT suite, suite_digest, COUNT(*) FROM runs GROUP BY suite, suite_digest")
        return [(r[0], r[1], r[2]) for r in rows]

    def planner_names(self) -> list[str]:
        """The planners with a stored run, by name."""
        return [r[0] for r in self.db.execute("SELECT DISTINCT planner FROM runs ORDER BY planner")]

    def suite_names(self) -> list[str]:
        """Every suite name the store lists, by name."""
        return [r[0] for r in self.db.execute("SELECT DISTINCT name FROM suites ORDER BY name")]

    def suite_versions(self, name: str | None = None) -> list[sqlite3.Row]:
        """Every stored suite version (id, name, digest, threshold, seal columns …), or those of one name."""
        if name is None:
            return self.db.execute("SELECT * FROM suites ORDER BY id").fetchall()
        return self.db.execute("SELECT * FROM suites WHERE name=?", (name,)).fetchall()

    def suite_members(self, suite_id: int) -> list[sqlite3.Row]:
        """The scenarios of one suite version (scenario id and digest, family, seed), by scenario id."""
        return self.db.execute("SELECT * FROM suite_scenarios WHERE suite_id=? ORDER BY scenario_id", (suite_id,)).fetchall()

    def memberships(self) -> set[tuple[int, str]]:
        """(suite version id, scenario digest) of every member of every stored suite version."""
        return {(r[0], r[1]) for r in self.db.execute("SELECT suite_id, scenario_digest FROM suite_scenarios")}

    def planner_config(self, config_id: int | None) -> sqlite3.Row | None:
        """A run's configuration row (``config`` as JSON text, ``source``), None when it has none."""
        return self.db.execute("SELECT config, source FROM planner_configs WHERE id=?", (config_id,)).fetchone()

    def planner_configs(self) -> list[tuple[str, str, str]]:
        """(planner name, config hash, configuration as JSON text) of every stored configuration, each once."""
        return [(r[0], r[1], r[2]) for r in self.db.execute("SELECT DISTINCT name, config_hash, config FROM planner_configs")]

    def environment(self, env_id: int | None) -> sqlite3.Row | None:
        """A run's environment row (hostname, CPU model, cores, OS, Python, packages, commits …), None without one."""
        return None if env_id is None else self.db.execute("SELECT * FROM environments WHERE id=?", (env_id,)).fetchone()

    def environments(self) -> list[sqlite3.Row]:
        """Every stored environment row."""
        return self.db.execute("SELECT * FROM environments").fetchall()


def sealed_origin(suite: Any) -> tuple[str | None, str | None, str | None]:
    """(public suite name, its digest, commitment) of a sealed suite version; Nones for a public one.

    Reads a loaded :class:`~earthbench.results.suite.Suite` (its ``sealing`` key) or a stored version
    (:mod:`earthbench.publishing.merge`'s records: ``sealed_from``, ``public_digest``, ``commitment``)."""
    key = getattr(suite, "sealing", None)
    if key is not None:
        return key.suite, key.suite_digest, key.commitment
    return getattr(suite, "sealed_from", None), getattr(suite, "public_digest", None), getattr(suite, "commitment", None)
