"""The store's schema: the tables of a new store (:data:`SCHEMA`), and the named steps by which
a store from an older schema catches up (:data:`MIGRATIONS`). What each version added:
docs/DESIGN.md §8, "Schema versions"."""

from __future__ import annotations

import sqlite3

#: The columns of ``spot_checks`` before ``context`` (the CPU ratios and load, issue 35) joined them.
_SPOT_CHECK_COLUMNS = """
    id INTEGER PRIMARY KEY, checked_at TEXT NOT NULL, planner TEXT NOT NULL, planner_version TEXT NOT NULL,
    config_hash TEXT NOT NULL, run_ids TEXT NOT NULL, agree INTEGER NOT NULL, ratios TEXT NOT NULL,
    disagreements TEXT NOT NULL, machine TEXT NOT NULL, stored_machines TEXT NOT NULL"""

#: How an older store catches up, one step per schema version: step ``k`` (0-based) takes a
#: store from version ``k + 1`` to ``k + 2``. Each feature that adds a column or a table appends
#: its own named step (never edits an old one); a new store is created at the latest version
#: by :data:`SCHEMA`, which already holds every step's columns and tables. A statement that would
#: add a column the table already has is skipped, so a step is safe to re-run.
MIGRATIONS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("2: the closed-loop steps of a run", ("ALTER TABLE runs ADD COLUMN steps TEXT",)),
    ("3: sealed draws (earthbench.seal): a suite version's public origin and commitment, a sealed mark on scenarios and runs", (
        "ALTER TABLE suites ADD COLUMN sealed_from TEXT",
        "ALTER TABLE suites ADD COLUMN public_digest TEXT",
        "ALTER TABLE suites ADD COLUMN commitment TEXT",
        "ALTER TABLE scenarios ADD COLUMN sealed INTEGER NOT NULL DEFAULT 0",
        "ALTER TABLE runs ADD COLUMN sealed INTEGER NOT NULL DEFAULT 0",
    )),
    ("4: the isolation stamp and process count of a run",
     ("ALTER TABLE runs ADD COLUMN isolation TEXT", "ALTER TABLE runs ADD COLUMN processes INTEGER")),
    ("5: the machine's load around each case and the build of the code that ran it (issue 35)", (
        "ALTER TABLE runs ADD COLUMN load_before REAL", "ALTER TABLE runs ADD COLUMN load_after REAL",
        "ALTER TABLE runs ADD COLUMN steal_share REAL", "ALTER TABLE environments ADD COLUMN earthbench_version TEXT",
        "ALTER TABLE environments ADD COLUMN plugin TEXT")),
    ("6: the planner's preparation a run used, its wall and CPU seconds (docs/DESIGN.md §6 \"Preparation\")",
     ("ALTER TABLE runs ADD COLUMN prepare_s REAL", "ALTER TABLE runs ADD COLUMN prepare_cpu_s REAL")),
    # `earthbench verify --sample` created this table on its own before it was versioned, at first
    # without ``context``: a store that has it keeps its rows, one without it gains it empty
    ("7: the spot re-timings of `earthbench verify --sample`, kept in the store they sampled", (
        "CREATE TABLE IF NOT EXISTS spot_checks (" + _SPOT_CHECK_COLUMNS + ")",
        "ALTER TABLE spot_checks ADD COLUMN context TEXT")),
    ("8: the digest of the code that provided a run's planner (docs/DESIGN.md §6 \"Plugin code\"); NULL: unknown",
     ("ALTER TABLE runs ADD COLUMN code_digest TEXT",)),
    # a run stored before it read as judged under rules version 1 (docs/referee.md "Rules versions")
    ("9: the version of the referee's rules a run was judged under", ("ALTER TABLE runs ADD COLUMN rules INTEGER NOT NULL DEFAULT 1",)),
)
SCHEMA_VERSION = 1 + len(MIGRATIONS)
APPLICATION_ID = 0x45424E43  # "EBNC"

SCHEMA = """
CREATE TABLE environments (
    id INTEGER PRIMARY KEY,
    hash TEXT NOT NULL UNIQUE,
    hostname TEXT, cpu_model TEXT, cores INTEGER, os TEXT, python TEXT,
    packages TEXT, project_commit TEXT, plugin_commit TEXT, earthbench_version TEXT, plugin TEXT
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
    doc BLOB NOT NULL, sealed INTEGER NOT NULL DEFAULT 0
);
CREATE TABLE suites (
    id INTEGER PRIMARY KEY,
    name TEXT NOT NULL, digest TEXT NOT NULL, track TEXT NOT NULL, threshold REAL NOT NULL,
    description TEXT, registered_at TEXT, sealed_from TEXT, public_digest TEXT, commitment TEXT,
    UNIQUE (name, digest)
);
CREATE TABLE suite_scenarios (
    suite_id INTEGER NOT NULL REFERENCES suites(id),
    scenario_id TEXT NOT NULL, scenario_digest TEXT NOT NULL, family TEXT, seed INTEGER,
    PRIMARY KEY (suite_id, scenario_id)
);
CREATE INDEX suite_scenarios_digest ON suite_scenarios (scenario_digest);
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
    exit_status INTEGER, cores TEXT, started_at TEXT, finished_at TEXT, rescored_at TEXT, steps TEXT,
    sealed INTEGER NOT NULL DEFAULT 0,
    isolation TEXT, processes INTEGER,
    load_before REAL, load_after REAL, steal_share REAL,
    prepare_s REAL, prepare_cpu_s REAL, code_digest TEXT,
    rules INTEGER NOT NULL DEFAULT 1,
    UNIQUE (scenario_digest, planner, planner_version, config_hash)
);
CREATE INDEX runs_planner ON runs (planner, planner_version);
CREATE TABLE spot_checks (""" + _SPOT_CHECK_COLUMNS + """, context TEXT);
"""


def columns(db: sqlite3.Connection, table: str) -> set[str]:
    return {r[1] for r in db.execute(f"PRAGMA table_info({table})")}


def write_schema(db: sqlite3.Connection) -> None:
    """The tables of a new store at the latest version, inside the caller's transaction."""
    for stmt in SCHEMA.strip().split(";"):
        if stmt.strip():
            db.execute(stmt)
    db.execute(f"PRAGMA application_id = {APPLICATION_ID}")
    db.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")


def migrate(db: sqlite3.Connection, version: int) -> None:
    """Bring a store of schema ``version`` up to date: the :data:`MIGRATIONS` steps after it, all in one transaction."""
    with db:
        db.execute("BEGIN IMMEDIATE")
        for _, statements in MIGRATIONS[version - 1:]:
            for stmt in statements:
                words = stmt.split()
                if words[:2] == ["ALTER", "TABLE"] and words[3:5] == ["ADD", "COLUMN"]:
                    if words[5] in {r[1] for r in db.execute(f"PRAGMA table_info({words[2]})")}:
                        continue
                db.execute(stmt)
        db.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
