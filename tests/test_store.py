"""The results store: bad files, locks, newer schemas, one row per key, pandas view."""

from __future__ import annotations

import math
import sqlite3
from dataclasses import replace

import pytest

from earthbench.errors import StoreError
from earthbench.running.harness import Case, CaseResult, PlannerRef
from earthbench.results.store import MIGRATIONS, SCHEMA_VERSION, Store, load_runs
from earthbench.results.suite import parse_suite

SUITE = """
name = "st"
[budget]
wall_s = 5
[[family]]
name = "f"
generator = "rbf"
targets = [0.28]
seeds = [0, 1]
[family.params]
n_bases = 2
size = [3.0, 2.0]
resolution = 0.1
"""


@pytest.fixture(scope="module")
def suite():
    return parse_suite(SUITE)


def case_of(suite, n=0):
    return Case(suite.name, suite.digest, 0.9, suite.scenarios[n], PlannerRef.resolve("greedy"))


def result_of(case, reason="ok", **kw):
    metrics = {"valid": True, "violations": 0, "volume_ratio": 0.0, "loaded_volume": 0.0, "time_per_m3": math.inf,
               "success": False, "solve_time_s": 0.1, "solve_cpu_s": 0.1, "my_plugin_metric": 7.5}
    base = dict(key=case.key, scenario_id=case.scenario.id, reason=reason, solve_time_s=0.1, solve_cpu_s=0.1,
                metrics=metrics if reason in ("ok", "invalid") else None,
                plan_json='{"schema": "earthbench.plan/1", "actions": []}' if reason in ("ok", "invalid") else None,
                environment={"hostname": "h", "cpu_model": "cpu", "cores": 2, "packages": {"numpy": "2"}})
    base.update(kw)
    return CaseResult(**base)


def test_not_sqlite_is_refused(tmp_path):
    f = tmp_path / "notes.db"
    f.write_text("these are my notes, not a database\n" * 100)
    with pytest.raises(StoreError, match="not an SQLite database"):
        Store(f)
    assert f.read_text().startswith("these are my notes")


def test_foreign_sqlite_is_refused(tmp_path):
    f = tmp_path / "other.db"
    con = sqlite3.connect(f)
    con.execute("CREATE TABLE t (x)")
    con.commit()
    con.close()
    with pytest.raises(StoreError, match="not an earthbench results store"):
        Store(f)


def test_newer_schema_is_refused_and_left_untouched(tmp_path):
    f = tmp_path / "new.db"
    Store(f).close()
    con = sqlite3.connect(f)
    con.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    con.commit()
    con.close()
    before = f.read_bytes()
    with pytest.raises(StoreError, match="newer than this earthbench"):
        Store(f)
    assert f.read_bytes() == before


def test_locked_database_gives_a_clear_error(tmp_path, suite):
    f = tmp_path / "locked.db"
    Store(f).close()
    holder = sqlite3.connect(f, isolation_level=None)
    holder.execute("BEGIN EXCLUSIVE")
    try:
        with pytest.raises(StoreError, match="locked by another process"):
            with Store(f, timeout=0.2) as store:
                store.check_writable()
        with Store(f, timeout=0.2) as store:  # opening to read works; the first write fails clearly
            with pytest.raises(StoreError, match="locked"):
                store.record(case_of(suite), result_of(case_of(suite)))
    finally:
        holder.execute("ROLLBACK")
        holder.close()


def test_missing_database_for_reading(tmp_path):
    with pytest.raises(StoreError, match="no results database"):
        Store(tmp_path / "absent.db", create=False)


def test_one_row_per_key_and_a_flat_dataframe(tmp_path, suite):
    f = tmp_path / "r.db"
    with Store(f) as store:
        store.register_suite(suite)
        c0, c1 = case_of(suite, 0), case_of(suite, 1)
        assert store.record(c0, result_of(c0))
        assert not store.record(c0, result_of(c0, reason="invalid"))  # already stored: nothing counted twice
        assert store.record(c1, result_of(c1, reason="timeout", error="ran past its budget"))
        assert store.finished_keys() == {c0.key, c1.key}
        assert store.record(c0, result_of(c0, reason="invalid"), replace=True)
        assert store.scenario(c0.scenario.digest) == c0.scenario
        assert store.db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    df = load_runs(f)
    assert len(df) == 2
    by = df.set_index("scenario_id")
    ok = by.loc["st/f/s0/v0.28"]
    assert ok.reason == "invalid" and ok.time_per_m3 == math.inf and ok.my_plugin_metric == 7.5
    assert ok.planner == "greedy" and ok.cpu_model == "cpu" and '"min_fill"' in ok.config
    t = by.loc["st/f/s1/v0.28"]
    assert t.reason == "timeout" and math.isnan(t.volume_ratio) and not t.success and t.error == "ran past its budget"
    for col in ("suite", "suite_digest", "scenario_digest", "planner_version", "config_hash", "solve_time_s",
                "solve_cpu_s", "n_violations", "violation_rules", "project_commit", "threshold", "seed", "family"):
        assert col in df.columns


def test_cancelled_results_are_never_stored(tmp_path, suite):
    with Store(tmp_path / "c.db") as store:
        c = case_of(suite)
        with pytest.raises(ValueError):
            store.record(c, result_of(c, reason="cancelled"))
        assert store.finished_keys() == set()


def _columns(path) -> dict[str, list[str]]:
    con = sqlite3.connect(path)
    tables = [r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table' ORDER BY name")]
    out = {t: sorted(r[1] for r in con.execute(f"PRAGMA table_info({t})")) for t in tables}
    con.close()
    return out


def test_a_store_of_every_older_schema_version_is_brought_up_to_the_fresh_schema(tmp_path):
    """Each migration step undone in reverse gives the store of that older version; opened for
    writing, each catches up to exactly the tables and columns of a fresh store."""
    fresh = tmp_path / "fresh.db"
    Store(fresh).close()
    want = _columns(fresh)
    for version in range(1, SCHEMA_VERSION):
        old = tmp_path / f"v{version}.db"
        old.write_bytes(fresh.read_bytes())
        con = sqlite3.connect(old)
        for _, statements in reversed(MIGRATIONS[version - 1:]):
            for stmt in reversed(statements):  # undone last first
                w = stmt.split()
                if w[:2] == ["ALTER", "TABLE"] and w[3:5] == ["ADD", "COLUMN"]:
                    con.execute(f"ALTER TABLE {w[2]} DROP COLUMN {w[5]}")
                elif w[:2] == ["CREATE", "TABLE"]:
                    name = w[5] if w[2:5] == ["IF", "NOT", "EXISTS"] else w[2]
                    con.execute(f"DROP TABLE {name.split('(')[0]}")
        con.execute(f"PRAGMA user_version = {version}")
        con.commit()
        con.close()
        assert _columns(old) != want
        with Store(old, read_only=True):  # read-only: read as it is, never altered
            pass
        assert sqlite3.connect(old).execute("PRAGMA user_version").fetchone()[0] == version
        Store(old).close()
        assert _columns(old) == want, f"a version-{version} store does not catch up to a fresh one"
        assert sqlite3.connect(old).execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION


def test_a_spot_check_table_made_before_it_was_versioned_keeps_its_rows(tmp_path):
    """``earthbench verify --sample`` created ``spot_checks`` itself before schema version 7, at
    first without ``context``: such a store catches up without losing a check, and its checks
    read back as they were written."""
    from earthbench.results.labels import latest_spot_checks

    path = tmp_path / "v6.db"
    Store(path).close()
    con = sqlite3.connect(path)
    con.execute("DROP TABLE spot_checks")
    con.execute("CREATE TABLE spot_checks (id INTEGER PRIMARY KEY, checked_at TEXT NOT NULL, planner TEXT NOT NULL, "
                "planner_version TEXT NOT NULL, config_hash TEXT NOT NULL, run_ids TEXT NOT NULL, agree INTEGER NOT NULL, "
                "ratios TEXT NOT NULL, disagreements TEXT NOT NULL, machine TEXT NOT NULL, stored_machines TEXT NOT NULL)")
    con.execute("INSERT INTO spot_checks (checked_at, planner, planner_version, config_hash, run_ids, agree, ratios, "
                "disagreements, machine, stored_machines) VALUES ('2026-01-01T00:00:00+00:00', 'greedy', '1', 'abc', '[1, 2]', "
                "2, '[1.5, 0.5]', '[]', 'here', '[\"there\"]')")
    con.execute("PRAGMA user_version = 6")
    con.commit()
    con.close()
    with Store(path, read_only=True) as st:  # read as it is: no context, no CPU ratios
        (old,) = latest_spot_checks(st)
        assert (old.planner, old.run_ids, old.ratios, old.cpu_ratios, old.steal) == ("greedy", (1, 2), (1.5, 0.5), (), None)
    with Store(path) as st:
        assert latest_spot_checks(st) == [old]
        st.record_spot_checks([replace(old, checked_at="2026-02-01T00:00:00+00:00", cpu_ratios=(1.25,), steal=0.01)])
        (new,) = latest_spot_checks(st)
    assert (new.checked_at, new.cpu_ratios, new.steal, new.ratios) == ("2026-02-01T00:00:00+00:00", (1.25,), 0.01, (1.5, 0.5))
    Store(tmp_path / "fresh.db").close()
    assert _columns(path)["spot_checks"] == _columns(tmp_path / "fresh.db")["spot_checks"]


def test_reading_a_published_store_leaves_its_file_as_committed(tmp_path, capsys):
    """A committed board's store is a VACUUM'd copy without write-ahead logging; `runs`, `leaderboard`
    and a merge's inputs only read it, so its bytes stay as git has them. The first write turns the
    log on, as before."""
    import shutil
    from pathlib import Path

    from earthbench.cli import main
    from earthbench.publishing.merge import merge

    db = tmp_path / "pile.db"
    shutil.copyfile(Path(__file__).parents[1] / "leaderboard" / "pile" / "pile.db", db)
    before = db.read_bytes()
    assert before[18:20] == b"\x01\x01"  # rollback journal, as VACUUM INTO writes it
    assert main(["runs", "--db", str(db), "--short"]) == 0
    assert main(["leaderboard", "--db", str(db), "--out", str(tmp_path / "board"), "--no-figures"]) == 0
    merge(tmp_path / "merged.db", [db])
    with Store(db, create=False) as store:
        assert len(store.run_suites()) == 1
    capsys.readouterr()
    assert db.read_bytes() == before
    with Store(db, create=False) as store:
        store.check_writable()  # a writer: the log goes on
    assert db.read_bytes()[18:20] == b"\x02\x02"
