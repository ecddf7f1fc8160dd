"""Versioned rules (docs/referee.md "Rules versions"): every run records the version of the
referee's rules that judged it; a store written before reads as version 1; verify says when a
run was judged under other rules, rescore re-judges and sets the version (``--dry-run`` only
reports), and the leaderboard and compare refuse to rank runs judged under different rules."""

from __future__ import annotations

import sqlite3

import pytest

from earthbench.cli import main
from earthbench.cli.rescore import Account
from earthbench.referee import RULES_VERSION
from earthbench.results.store import SCHEMA_VERSION, Store, load_runs


@pytest.fixture(scope="module")
def smoke_db(tmp_path_factory):
    db = str(tmp_path_factory.mktemp("rules") / "r.db")
    assert main(["run", "smoke", "--planner", "greedy", "--planner", "singh-cannon-backhoe", "--db", db, "--quiet"]) == 0
    return db


def _copy(src: str, dst) -> str:
    with sqlite3.connect(src) as a, sqlite3.connect(str(dst)) as b:
        a.backup(b)
    return str(dst)


def _rules(db: str) -> dict[str, set[int]]:
    runs = load_runs(db)
    return {p: set(g["rules"]) for p, g in runs.groupby("planner")}


def test_every_run_records_the_rules_that_judged_it(smoke_db):
    assert _rules(smoke_db) == {"greedy": {RULES_VERSION}, "singh-cannon-backhoe": {RULES_VERSION}}


def test_a_store_written_before_reads_as_rules_1_and_rescore_moves_it(smoke_db, tmp_path, capsys):
    db = _copy(smoke_db, tmp_path / "old.db")
    with sqlite3.connect(db) as con:  # as the release before wrote it: no column, the schema version before
        con.execute("ALTER TABLE runs DROP COLUMN rules")
        con.execute(f"PRAGMA user_version = {SCHEMA_VERSION - 1}")
    assert set(load_runs(db)["rules"]) == {1}
    Store(db).close()  # migrates: the column, every row at 1
    assert set(load_runs(db)["rules"]) == {1}
    capsys.readouterr()
    main(["verify", db])
    out = capsys.readouterr().out
    assert "judged under other rules than this referee's" in out and f"earthbench rescore --db {db}" in out
    assert main(["rescore", "--db", db, "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("would rescore") and "under rules 1" in out and "| planner" in out and "newly invalid" in out
    assert set(load_runs(db)["rules"]) == {1}  # a dry run writes nothing
    assert main(["rescore", "--db", db]) == 0
    assert set(load_runs(db)["rules"]) == {RULES_VERSION}


def test_rankings_never_mix_rules(smoke_db, tmp_path, capsys):
    db = _copy(smoke_db, tmp_path / "mixed.db")
    with sqlite3.connect(db) as con:
        con.execute("UPDATE runs SET rules = 1 WHERE planner = 'greedy'")
    capsys.readouterr()
    assert main(["leaderboard", "--db", db, "--out", str(tmp_path / "board"), "--no-figures"]) != 0
    err = capsys.readouterr().err
    assert "different versions of the referee's rules" in err and f"earthbench rescore --db {db}" in err
    assert main(["compare", db, "--a", "greedy", "--b", "singh-cannon-backhoe"]) != 0
    assert f"earthbench rescore --db {db}" in capsys.readouterr().err
    assert main(["rescore", "--db", db, "--planner", "greedy"]) == 0
    assert main(["compare", db, "--a", "greedy", "--b", "singh-cannon-backhoe"]) == 0


def test_the_board_stamp_names_the_rules(smoke_db, tmp_path):
    out = tmp_path / "board"
    assert main(["leaderboard", "--db", smoke_db, "--out", str(out), "--no-figures"]) == 0
    assert f"referee rules: version {RULES_VERSION}" in (out / "README.md").read_text()


def test_the_account_counts_runs_made_invalid_by_rule():
    a = Account()
    a.add(("greedy", "s"), "ok", "invalid", {"truck_step", "truck_tilt"})
    a.add(("greedy", "s"), "ok", "ok", set())
    a.add(("greedy", "s"), "invalid", "invalid", {"reach"})  # invalid before: not moved by the new rules
    rows = a.table().splitlines()
    assert rows[0].split("|")[1:-1] == [" planner ", " suite ", " plans ", " valid before ", " valid now ", " newly invalid ",
                                        " truck_step ", " truck_tilt "]
    assert [c.strip() for c in rows[2].split("|")[1:-1]] == ["greedy", "s", "3", "2", "1", "1", "1", "1"]
