"""The preparation phase (docs/DESIGN.md §6 "Preparation"): once per planner configuration and
machine, before the first case, in a fenced job with its own budget; cases see its folder read
only; its times are stored beside the solve times, never in them."""

from __future__ import annotations

import json
import os
import sqlite3
from pathlib import Path

import pytest

from earthbench.cli import main
from earthbench.running.harness import LocalExecutor, build_cases, run_cases
from earthbench.results.records import PlannerRef
from earthbench.running.harness.prepare import PrepareError, ensure, find, prepare_key
from earthbench.registry import load_plugin_file
from earthbench.results.store import SCHEMA_VERSION, Store, load_runs
from earthbench.results.suite import parse_suite
from earthbench.world import Budget

from helpers import tiny_suite_toml


PLUGIN = str(Path(__file__).parent / "plugins" / "preparing_planners.py")

pytestmark = pytest.mark.usefixtures("forget_test_planners", "prepared_root")


def _run(tmp_path, planners, seeds="0-1", budget="", config="", db="r.db"):
    suite = parse_suite(tiny_suite_toml(seeds=seeds, budget=budget, config=config))
    cases, _ = build_cases(suite, planners, plugins=[PLUGIN])
    log: list[str] = []
    with Store(tmp_path / db) as store:
        store.register_suite(suite)
        report = run_cases(cases, store, LocalExecutor(jobs=1), log=log.append)
    return report, load_runs(tmp_path / db), log


def _infos(db):
    with Store(db) as store:
        return [json.loads(store.plan_json(int(i)))["info"] for i in load_runs(db).id]


def test_a_planner_is_prepared_once_and_its_cases_read_the_folder(tmp_path, prepared_root):
    report, df, log = _run(tmp_path, ["t-prepares"])
    assert report.stored == 2 and set(df.reason) == {"ok"}
    assert sum(m.startswith("preparing t-prepares") for m in log) == 1  # one preparation for both cases
    assert any(m.startswith("prepared t-prepares") for m in log)
    ref = PlannerRef.resolve("t-prepares")
    folder = prepared_root / prepare_key(ref)
    for info in _infos(tmp_path / "r.db"):
        assert info["prepared"] == str(folder) and info["token"] == "a"
        assert info["mode"] == "0o444"  # read only (the isolation's mounts enforce it for root too)
    # the harness measured it and stored it beside the solve times, not in them
    assert (df.prepare_s > 0).all() and (df.prepare_cpu_s >= 0).all()
    assert df.prepare_s.nunique() == 1
    manifest = json.loads((folder / "prepare.json").read_text())
    assert manifest["summary"] == {"wrote": ["token.txt", "seen.json"]}
    assert manifest["machine"]["cpu_model"] and manifest["wall_s"] == pytest.approx(df.prepare_s.iloc[0])
    seen = json.loads((folder / "seen.json").read_text())
    assert seen["jobs"] == 2 and seen["pid"] != os.getpid()  # its own process, on the slot's cores
    # a second run on this machine finds it and does not prepare again
    _, df2, log2 = _run(tmp_path, ["t-prepares"], seeds="2-2", db="r2.db")
    assert not log2
    assert df2.prepare_s.iloc[0] == pytest.approx(df.prepare_s.iloc[0])


def test_another_configuration_is_prepared_apart(tmp_path):
    _run(tmp_path, ["t-prepares"], seeds="0-0")
    _, df, log = _run(tmp_path, ["t-prepares"], seeds="0-0", config='[config.t-prepares]\ntoken = "b"', db="b.db")
    assert sum(m.startswith("preparing t-prepares") for m in log) == 1
    assert _infos(tmp_path / "b.db")[0]["token"] == "b"
    assert prepare_key(PlannerRef.resolve("t-prepares")) != prepare_key(PlannerRef.resolve("t-prepares", {"token": "b"}))


def test_open_and_closed_loop_share_a_preparation():
    from earthbench.registry import PLANNERS

    open_loop, closed = PlannerRef.resolve("stl-tamp"), PlannerRef.resolve("stl-tamp", {"closed_loop": True})
    assert open_loop.config_hash != closed.config_hash and PLANNERS.get("stl-tamp").prepares()
    assert prepare_key(open_loop) == prepare_key(closed)


def test_a_failed_preparation_fails_the_planners_cases_once(tmp_path, prepared_root):
    report, df, log = _run(tmp_path, ["t-prepare-fails"])
    assert set(df.reason) == {"error"} and len(df) == 2
    assert all("failed: RuntimeError: no compiler here" in e for e in df.error)
    assert any("no compiler here" in m for m in log)
    assert not list(prepared_root.glob("t-prepare-fails*"))  # nothing half-made is left for a case
    with pytest.raises(PrepareError, match="no compiler here"):  # not run again in this process
        ensure(PlannerRef.resolve("t-prepare-fails"), Budget())


def test_a_preparation_has_its_own_budget(tmp_path):
    ref = PlannerRef.resolve("t-prepare-sleeps")
    with pytest.raises(PrepareError, match="ran past its budget of 1 s"):
        ensure(ref, Budget(prepare_s=1.0))
    assert find(ref) is None


def test_preparation_can_be_switched_off(tmp_path, monkeypatch):
    monkeypatch.setenv("EARTHBENCH_PREPARE", "off")
    _, df, log = _run(tmp_path, ["t-prepares"], seeds="0-0")
    assert not log and not list(tmp_path.glob("prepared/t-prepares*"))
    assert df.reason[0] == "error" and "NoneType" in df.error[0]  # this planner needs its folder
    assert df.prepare_s.isna().all()


def test_a_planner_without_preparation_has_none(tmp_path):
    from earthbench.registry import load_plugin_file as load

    load(str(Path(__file__).parent / "plugins" / "faulty_planners.py"))
    ref = PlannerRef.resolve("t-fast")
    assert not ref.prepares and ensure(ref, Budget()) is None


def test_prepare_command(tmp_path, capsys):
    assert main(["prepare", "t-prepares", "--plugin", PLUGIN]) == 0
    out = capsys.readouterr().out
    assert "ran now" in out and "wall" in out and "CPU" in out
    assert main(["prepare", "t-prepares", "--plugin", PLUGIN]) == 0
    assert "found on this machine" in capsys.readouterr().out
    assert main(["prepare", "t-prepares", "--plugin", PLUGIN, "--again"]) == 0
    assert "ran now" in capsys.readouterr().out
    assert main(["prepare", "t-prepare-fails", "--plugin", PLUGIN]) == 2
    assert "no compiler here" in capsys.readouterr().err
    load_plugin_file(str(Path(__file__).parent / "plugins" / "faulty_planners.py"))
    assert main(["prepare", "t-fast", "--plugin", str(Path(__file__).parent / "plugins" / "faulty_planners.py")]) == 1


def test_suite_budget_takes_the_preparation_limits():
    suite = parse_suite(tiny_suite_toml(budget="prepare_s = 600\nprepare_memory_mb = 2048"))
    assert suite.budget.prepare_s == 600.0 and suite.budget.prepare_memory_mb == 2048
    # at their defaults they stay out of the scenario documents (digests unchanged)
    plain = parse_suite(tiny_suite_toml())
    assert "prepare_s" not in json.dumps(plain.scenarios[0].to_dict()["budget"])


def test_a_version_4_store_gains_the_preparation_columns(tmp_path):
    db = tmp_path / "old.db"
    with Store(db):
        pass
    con = sqlite3.connect(db)
    con.execute("ALTER TABLE runs DROP COLUMN prepare_s")
    con.execute("ALTER TABLE runs DROP COLUMN prepare_cpu_s")
    con.execute("PRAGMA user_version = 4")
    con.commit()
    con.close()
    assert "prepare_s" in load_runs(Store(db, read_only=True)).columns  # read only: NULLs, untouched
    with Store(db) as store:
        cols = {r[1] for r in store.db.execute("PRAGMA table_info(runs)")}
        assert {"prepare_s", "prepare_cpu_s"} <= cols
        assert store.db.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION


def test_a_board_shows_the_preparation_beside_the_solve_times(tmp_path):
    from earthbench.publishing.publish import publish

    _run(tmp_path, ["t-prepares"], seeds="0-0")
    res = publish(tmp_path / "r.db", tmp_path / "lb", figures=False, generated="(fixed)")
    text = (res.out / "README.md").read_text()
    assert "| Prepare s |" in text
    line = next(ln for ln in text.splitlines() if "preparation of" in ln)
    assert "prepares" in line and "not in its solve times" in line and "s wall" in line


def test_a_suite_can_run_without_preparations(tmp_path):
    from earthbench.errors import SuiteError
    from earthbench.results.suite import load_suite

    toml = tiny_suite_toml().replace('track = "backhoe"', 'track = "backhoe"\nprepare = false')
    suite = parse_suite(toml)
    assert not suite.prepare and not load_suite("quick").prepare and load_suite("smoke").prepare
    cases, _ = build_cases(suite, ["t-prepares"], plugins=[PLUGIN])
    log: list[str] = []
    with Store(tmp_path / "n.db") as store:
        store.register_suite(suite)
        run_cases(cases, store, LocalExecutor(jobs=1), log=log.append)
    assert not log and not list(tmp_path.glob("prepared/t-prepares*"))
    assert load_runs(tmp_path / "n.db").prepare_s.isna().all()
    with pytest.raises(SuiteError, match="prepare must be true or false"):
        parse_suite(toml.replace("prepare = false", 'prepare = "no"'))


HOSTILE_PREPARATIONS = {
    "t-prep-links": "a symbolic link",
    "t-prep-fifo": "a FIFO (pipe)",
    "t-prep-hardlink": "a hard link (b, 2 links)",
    "t-prep-flood": "disk budget of 8 MB",
    "t-prep-bigfile": "File too large",
}


def test_a_preparation_folder_is_hostile_data(tmp_path, prepared_root, monkeypatch):
    """Links, special files, hard links and a folder over the disk budget: each an ``error`` of
    that planner alone (the suite goes on), no file of the host written or made readable through
    a link, the harness never waits on a FIFO, nothing of them kept for a case."""
    victim = tmp_path / "key"
    victim.write_text("secret")
    victim.chmod(0o600)
    monkeypatch.setenv("EARTHBENCH_TEST_VICTIM", str(victim))
    report, df, log = _run(tmp_path, [*HOSTILE_PREPARATIONS, "t-prepares"], seeds="0-0", budget="prepare_disk_mb = 8")
    df = df.set_index("planner")
    assert df.reason.to_dict() == {**{p: "error" for p in HOSTILE_PREPARATIONS}, "t-prepares": "ok"}, df.error.to_dict()
    for planner, why in HOSTILE_PREPARATIONS.items():
        assert why in df.error[planner], (planner, df.error[planner])
    assert "only plain files and folders are accepted" in df.error["t-prep-links"]
    assert victim.read_text() == "secret" and oct(victim.stat().st_mode & 0o777) == "0o600"
    assert [p.name for p in prepared_root.iterdir() if not p.name.startswith(".")] == [prepare_key(PlannerRef.resolve("t-prepares"))]
    assert not [p for p in prepared_root.iterdir() if p.name.endswith(".tmp")]  # no half-made folder left


def test_two_processes_prepare_a_key_once(tmp_path, prepared_root):
    """The second of two processes that prepare one key at once waits for the first and uses its
    folder; both report the one preparation's time (the one the folder's manifest holds)."""
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "earthbench", "prepare", "t-prepare-slow", "--plugin", PLUGIN]
    env = {**os.environ, "EARTHBENCH_PREPARED": str(prepared_root)}
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env) for _ in range(2)]
    outs = [p.communicate(timeout=300) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], outs
    said = sorted("ran now" in out for out, _ in outs)
    assert said == [False, True], outs
    assert sum("waiting for another process that is preparing t-prepare-slow" in err for _, err in outs) == 1, outs
    manifest = json.loads((prepared_root / prepare_key(PlannerRef.resolve("t-prepare-slow")) / "prepare.json").read_text())
    for out, _ in outs:
        assert f"wall     {manifest['wall_s']:.1f} s" in out
