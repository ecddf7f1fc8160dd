"""`earthbench run`, `runs`, `rescore`: resume after SIGKILL, a clean Ctrl-C, clear errors."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from earthbench.cli import main
from earthbench.results.store import load_runs

from helpers import tiny_suite_toml

PLUGIN = str(Path(__file__).parent / "plugins" / "faulty_planners.py")


pytestmark = pytest.mark.usefixtures("forget_test_planners")


def suite_file(tmp_path, n=6):
    f = tmp_path / "cli.toml"
    f.write_text(tiny_suite_toml("cli", seeds=f"0-{n - 1}"))
    return str(f)


def cli(*args, env=None):
    return subprocess.Popen(
        [sys.executable, "-m", "earthbench", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env={**os.environ, **(env or {})},
    )


def stored(db) -> int:
    if not Path(db).exists():
        return 0
    try:
        con = sqlite3.connect(db, timeout=5)
        try:
            return con.execute("SELECT count(*) FROM runs").fetchone()[0]
        finally:
            con.close()
    except sqlite3.OperationalError:
        return 0


def wait_for_rows(db, n, proc, limit=60.0):
    end = time.monotonic() + limit
    while stored(db) < n:
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < end, "no progress"
        time.sleep(0.05)


def test_sigkill_halfway_then_resume_stores_every_case_once(tmp_path):
    db, suite = str(tmp_path / "k.db"), suite_file(tmp_path, 6)
    args = ["run", suite, "--planner", "t-nap", "--plugin", PLUGIN, "--db", db]
    proc = cli(*args, env={"EARTHBENCH_TEST_NAP": "0.4"})
    wait_for_rows(db, 2, proc)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    halfway = stored(db)
    assert 2 <= halfway < 6
    again = cli(*args, env={"EARTHBENCH_TEST_NAP": "0"})
    out, err = again.communicate(timeout=120)
    assert again.returncode == 0, err
    assert f"{halfway} of the 6 cases already stored: skipped (--rerun runs them again); running {6 - halfway}" in err
    assert err.index("already stored: skipped") < err.index("[1/")  # said before counting to fewer than the header's 6
    df = load_runs(db)
    assert len(df) == 6 and df.scenario_digest.is_unique and set(df.reason) == {"ok"}
    assert "t-nap" in out and "6/6" in out


@pytest.mark.usefixtures("sigint_delivered")
def test_ctrl_c_stops_cleanly_and_keeps_finished_cases(tmp_path):
    db, suite = str(tmp_path / "c.db"), suite_file(tmp_path, 6)
    args = ["run", suite, "--planner", "t-nap", "--plugin", PLUGIN, "--db", db]
    proc = cli(*args, env={"EARTHBENCH_TEST_NAP": "0.6"})
    wait_for_rows(db, 1, proc)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert "interrupted" in err and "run the same command again to resume" in err
    n = stored(db)
    assert "the table above is partial" in err and "partial: not every scenario has a run (t-nap " in out and f" {n} of 6)" in out
    assert 1 <= n < 6
    con = sqlite3.connect(db)
    assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    assert con.execute("SELECT count(*) FROM runs WHERE reason != 'ok'").fetchone()[0] == 0  # nothing half-done stored
    con.close()
    assert main([*args, "--quiet"]) == 0
    assert len(load_runs(db)) == 6


def test_unknown_names_fail_with_suggestions(tmp_path, capsys):
    assert main(["run", "smok", "--db", str(tmp_path / "x.db")]) == 2
    assert "Did you mean 'smoke'" in capsys.readouterr().err
    assert main(["run", "smoke", "--planner", "gredy", "--db", str(tmp_path / "x.db")]) == 2
    assert "Did you mean 'greedy'" in capsys.readouterr().err
    bad = tmp_path / "typo.toml"
    bad.write_text(tiny_suite_toml("cli").replace("wall_s", "wall_sec"))
    assert main(["run", str(bad), "--db", str(tmp_path / "x.db")]) == 2
    assert "unknown key 'wall_sec'" in capsys.readouterr().err
    notdb = tmp_path / "notes.txt"
    notdb.write_text("hello\n" * 200)
    assert main(["run", "smoke", "--db", str(notdb)]) == 2
    assert "not an SQLite database" in capsys.readouterr().err


def test_runs_lists_and_shows_and_rescore_repairs(tmp_path, capsys):
    db, suite = str(tmp_path / "r.db"), suite_file(tmp_path, 2)
    assert main(["run", suite, "--planner", "t-fast", "--planner", "t-raise", "--plugin", PLUGIN, "--db", db, "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "t-fast 0" in out and "t-raise 0" in out
    assert main(["runs", "--db", db, "--reason", "error", "--format", "csv"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 3 and all("t-raise" in ln for ln in lines[1:])
    run_id = int(lines[1].split(",")[0])
    assert main(["runs", "--db", db, "--id", str(run_id)]) == 0
    assert "ValueError: planner bug: boom" in capsys.readouterr().out
    # a "referee fix": rescoring restores the referee's verdict on a tampered row
    con = sqlite3.connect(db)
    con.execute("UPDATE runs SET reason='invalid', volume_ratio=0.5 WHERE planner='t-fast' AND seed=0")
    con.commit()
    con.close()
    assert main(["rescore", "--db", db]) == 0
    assert "1 changed, 1 unchanged" in capsys.readouterr().out
    df = load_runs(db)
    fast = df[df.planner == "t-fast"]
    assert set(fast.reason) == {"ok"} and set(fast.volume_ratio) == {0.0} and fast.rescored_at.notna().all()
    plan = tmp_path / "plan.json"
    fast_id = int(fast.id.iloc[0])
    assert main(["runs", "--db", db, "--id", str(fast_id), "--plan-out", str(plan)]) == 0
    assert '"earthbench.plan/1"' in plan.read_text()


def test_smoke_runs_from_the_command_line(tmp_path, capsys):
    db = str(tmp_path / "s.db")
    assert main(["run", "smoke", "--db", db, "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "greedy" in out and "4/4" in out
    df = load_runs(db, suite="smoke")
    assert len(df) == 4 and df.success.all()


def test_suites_command(capsys):
    assert main(["suites"]) == 0
    out = capsys.readouterr().out
    assert "smoke" in out and "quick" in out
    assert main(["suites", "smoke"]) == 0
    out = capsys.readouterr().out
    assert "smoke/rbf14/s0/v0.56" in out and "digest" in out
