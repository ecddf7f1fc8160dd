"""The harness: every fault ends in the right termination reason and the rest still runs."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import psutil
import pytest

from earthbench.running.harness import LocalExecutor, build_cases, make_slots, run_case, run_cases
from earthbench.results.store import Store, load_runs
from earthbench.results.suite import parse_suite

from helpers import case_processes, tiny_suite_toml

PLUGIN = str(Path(__file__).parent / "plugins" / "faulty_planners.py")


pytestmark = pytest.mark.usefixtures("forget_test_planners")


def tiny_suite(wall_s: float = 20.0, memory_mb: int = 1024, seeds: str = "0-0", name: str = "tiny"):
    return parse_suite(tiny_suite_toml(name, wall_s=wall_s, memory_mb=memory_mb, seeds=seeds))


def run_all(suite, planners, db, **kw):
    from earthbench.registry import load_plugin_file

    load_plugin_file(PLUGIN)
    cases, notes = build_cases(suite, planners, plugins=[PLUGIN])
    with Store(db) as store:
        store.register_suite(suite)
        report = run_cases(cases, store, LocalExecutor(jobs=1, startup_s=kw.pop("startup_s", 60.0)), **kw)
    return report, load_runs(db)


def test_every_fault_gets_its_reason_and_the_rest_of_the_suite_runs(tmp_path):
    suite = tiny_suite(wall_s=1.5, memory_mb=1024)
    planners = ["t-raise", "t-nonplan", "t-invalid", "t-sleep", "t-memory", "t-kill", "t-exit", "t-fast", "t-abort-oom"]
    report, df = run_all(suite, planners, tmp_path / "r.db")
    assert report.stored == len(planners) and not report.interrupted
    got = dict(zip(df.planner, df.reason))
    assert got == {
        "t-raise": "error", "t-nonplan": "error", "t-invalid": "invalid", "t-sleep": "timeout",
        "t-memory": "memory", "t-kill": "crashed", "t-exit": "error", "t-fast": "ok", "t-abort-oom": "memory",
    }
    row = df.set_index("planner")
    assert "ValueError: planner bug: boom" in row.loc["t-raise", "error"]
    assert "not an earthbench.Plan" in row.loc["t-nonplan", "error"]
    assert "SIGKILL" in row.loc["t-kill", "error"]
    assert "SIGABRT" in row.loc["t-abort-oom", "error"] and "bad_alloc" in row.loc["t-abort-oom", "log_tail"]
    assert "SystemExit: 3" in row.loc["t-exit", "error"]
    assert {"cut_depth", "duration"} <= set(row.loc["t-invalid", "violation_rules"].split(","))
    assert not row.loc["t-invalid", "success"] and not row.loc["t-fast", "success"]
    # the harness measured the planner call even when it raised or ran out of time
    assert row.loc["t-raise", "solve_time_s"] >= 0 and row.loc["t-raise", "solve_cpu_s"] >= 0
    assert row.loc["t-sleep", "solve_time_s"] >= 1.5
    assert row.loc["t-sleep", "solve_cpu_s"] < 1.0  # sleeping costs no CPU
    assert "wall budget of 1.5 s" in row.loc["t-sleep", "error"]
    # a valid plan has its plan stored and metrics filled
    assert row.loc["t-fast", "volume_ratio"] == 0.0 and row.loc["t-fast", "valid"]


def test_case_runs_inside_its_fences(tmp_path, monkeypatch):
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")  # what a Dask nanny gives its worker
    suite = tiny_suite(memory_mb=1500)
    _, df = run_all(suite, ["t-probe"], tmp_path / "p.db")
    with Store(tmp_path / "p.db") as store:
        info = json.loads(store.plan_json(int(df.id[0])))["info"]
    assert info["omp"] == "2" and info["openblas"] == "2"
    assert info["allocator"] == []
    assert info["rlimit_as"] == 1500 * 1024 * 1024
    assert info["own_group"]
    assert set(info["affinity"]) <= set(os.sched_getaffinity(0))
    assert df.reason[0] == "ok" and df.startup_s[0] > 0 and df.peak_rss_mb[0] > 0


def test_timeout_ends_every_descendant(tmp_path, monkeypatch):
    pidfile = tmp_path / "grandchild.pid"
    monkeypatch.setenv("EARTHBENCH_TEST_PIDFILE", str(pidfile))
    suite = tiny_suite(wall_s=1.5)
    _, df = run_all(suite, ["t-spawn"], tmp_path / "s.db")
    assert df.reason[0] == "timeout"
    deadline = time.monotonic() + 5
    while case_processes() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not case_processes()
    if pidfile.exists():  # written without isolation (a sandboxed case cannot reach the folder)
        pid = int(pidfile.read_text())
        assert not psutil.pid_exists(pid) or psutil.Process(pid).status() == psutil.STATUS_ZOMBIE


def test_resume_skips_stored_cases_and_rerun_replaces_them(tmp_path):
    suite = tiny_suite(seeds="0-1")
    db = tmp_path / "r.db"
    r1, df1 = run_all(suite, ["t-fast"], db)
    assert (r1.stored, r1.skipped) == (2, 0)
    r2, df2 = run_all(suite, ["t-fast"], db)
    assert (r2.stored, r2.skipped) == (0, 2) and len(df2) == 2
    r3, df3 = run_all(suite, ["t-fast"], db, rerun=True)
    assert r3.stored == 2 and len(df3) == 2 and set(df3.id).isdisjoint(df1.id)


def test_a_union_suite_reuses_runs_of_its_parts(tmp_path):
    db = tmp_path / "u.db"
    part = tiny_suite(seeds="0-0", name="part")
    run_all(part, ["t-fast"], db)
    union = tiny_suite(seeds="0-1", name="union")
    report, _ = run_all(union, ["t-fast"], db)
    assert (report.stored, report.skipped) == (1, 1)
    df = load_runs(db, suite="union")
    assert sorted(df.scenario_id) == ["union/small/s0/v0.28", "union/small/s1/v0.28"]
    assert list(load_runs(db, suite="part").scenario_id) == ["part/small/s0/v0.28"]


def test_slots_split_the_allowed_cores():
    assert make_slots(2, None, range(5)) == [(0, 1), (2, 3)]
    assert make_slots(2, 1, range(8)) == [(0, 1)]
    assert make_slots(2, None, [3]) == [(3,)]
    assert make_slots(1, None, [0, 1]) == [(0,), (1,)]


def test_run_case_is_usable_alone(tmp_path):
    """The unit a distributed executor ships: a picklable case in, a picklable result out."""
    import pickle

    from earthbench.registry import load_plugin_file

    load_plugin_file(PLUGIN)
    suite = tiny_suite()
    (case,), _ = build_cases(suite, ["t-fast"], plugins=[PLUGIN])
    case = pickle.loads(pickle.dumps(case))
    result = pickle.loads(pickle.dumps(run_case(case)))
    assert result.reason == "ok" and result.key == case.key
    assert result.environment["cores"] == os.cpu_count() and result.environment["python"]


@pytest.mark.parametrize("bad", ["t-nonexistent"])
def test_unknown_planner_suggests_close_names(bad):
    from earthbench.errors import UnknownNameError
    from earthbench.registry import load_plugin_file

    load_plugin_file(PLUGIN)
    with pytest.raises(UnknownNameError, match="t-"):
        build_cases(tiny_suite(), [bad])


def test_start_up_is_bounded_too(tmp_path):
    _, df = run_all(tiny_suite(), ["t-fast"], tmp_path / "s.db", startup_s=0.01)
    assert df.reason[0] == "timeout" and "start-up" in df.error[0]


def test_progress_line_counts_reasons_and_gives_an_eta():
    import io

    from earthbench.results.progress import Progress
    from earthbench.running.harness import CaseResult

    (case,), _ = build_cases(tiny_suite(), ["greedy"])
    out = io.StringIO()
    p = Progress(3, stream=out, live=True)
    p.start()
    p.update(case, CaseResult(key=case.key, scenario_id=case.scenario.id, reason="ok", solve_time_s=0.5))
    p.update(case, CaseResult(key=case.key, scenario_id=case.scenario.id, reason="timeout", error="ran past\nits wall budget"))
    p.close()
    text = out.getvalue()
    assert "[2/3] ok 1 timeout 1" in text and "ETA" in text and "its wall budget" in text and "\r" in text
    assert text.endswith("\n")


def test_concurrent_cases_in_one_process_get_disjoint_slots():
    import threading

    from earthbench.running.harness import SlotPool

    pool = SlotPool([(0, 1), (2, 3)])
    held, now, clashes, lock = [], set(), [], threading.Lock()

    def grab():
        with pool.slot() as s:
            with lock:
                clashes.append(s in now)
                now.add(s)
                held.append(s)
            time.sleep(0.05)
            with lock:
                now.discard(s)

    threads = [threading.Thread(target=grab) for _ in range(4)]
    [t.start() for t in threads]
    [t.join() for t in threads]
    assert sorted(held) == [(0, 1), (0, 1), (2, 3), (2, 3)] and not any(clashes)
