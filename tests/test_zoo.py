"""The adversarial zoo: every faulty and hostile planner in one suite run.

Each case must end with the right reason and the harness's own times, the run must store
every case (no case stops the suite), and no process any case started may outlive it.
"""

from __future__ import annotations

import time
from pathlib import Path

import psutil
import pytest

from earthbench.running.harness import LocalExecutor, build_cases, run_cases
from earthbench.registry import load_plugin_file
from earthbench.results.store import Store, load_runs
from earthbench.results.suite import parse_suite

from helpers import case_processes, tiny_suite_toml

PLUGINS = [str(Path(__file__).parent / "plugins" / f) for f in ("faulty_planners.py", "hostile_planners.py")]

WALL_S = 5.0
EXPECTED = {
    # the existing faulty planners
    "t-raise": "error", "t-nonplan": "error", "t-invalid": "invalid", "t-sleep": "timeout", "t-memory": "memory",
    "t-kill": "crashed", "t-exit": "error", "t-fast": "ok", "t-abort-oom": "memory", "t-spawn": "timeout",
    # the hostile ones
    "h-forge-ready": "error", "h-forge-started": "error", "h-forge-done": "error", "h-plan-42": "error",
    "h-dict-plan": "error", "h-garbage": "error", "h-bloated": "error", "h-escape": "ok", "h-kill-warden": "crashed",
    "h-orphan-burn": "ok", "h-segv": "crashed", "h-log-flood": "error", "h-after-result": "error", "h-blank-lines": "error",
    "h-progress": "error",
}

pytestmark = pytest.mark.usefixtures("forget_test_planners")


def _alive(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False


def test_the_zoo_in_one_run(tmp_path, monkeypatch):
    monkeypatch.setenv("EARTHBENCH_TEST_PIDDIR", str(tmp_path))
    monkeypatch.setenv("EARTHBENCH_TEST_PIDFILE", str(tmp_path / "t-spawn.pids"))
    suite = parse_suite(tiny_suite_toml("zoo", wall_s=WALL_S, memory_mb=1024))
    for p in PLUGINS:
        load_plugin_file(p)
    cases, _ = build_cases(suite, list(EXPECTED), plugins=PLUGINS)
    with Store(tmp_path / "zoo.db") as store:
        store.register_suite(suite)
        t0 = time.monotonic()
        report = run_cases(cases, store, LocalExecutor(jobs=2))
        elapsed = time.monotonic() - t0
    df = load_runs(tmp_path / "zoo.db").set_index("planner")
    assert report.stored == len(EXPECTED) and not report.interrupted
    assert df.reason.to_dict() == EXPECTED

    # every time is the harness's, on its own clock, and never negative
    assert (df.solve_cpu_s.dropna() >= 0).all() and (df.solve_time_s.dropna() >= 0).all()
    for timed_out in ("t-sleep", "t-spawn"):
        assert WALL_S <= df.solve_time_s[timed_out] < WALL_S + 3.0 and df.solve_cpu_s[timed_out] < 1.0
    assert "nonce" in df.error["h-forge-done"]  # its own result, not its bootstrap's: refused
    assert df.solve_cpu_s["h-orphan-burn"] >= 0.5  # the kernel counts the process it left behind
    # forged or malformed messages end the case at once, with what was wrong
    assert df.solve_time_s["h-forge-ready"] < WALL_S and "'ready' twice" in df.error["h-forge-ready"]
    assert "not an earthbench message" in df.error["h-forge-started"] and df.solve_time_s["h-forge-started"] < WALL_S
    assert "plan of type int" in df.error["h-plan-42"] and "plan of type dict" in df.error["h-dict-plan"]
    assert "not JSON" in df.error["h-garbage"] and "plan-size limit" in df.error["h-bloated"]
    assert "SIGSEGV" in df.error["h-segv"] and df.peak_rss_mb["h-segv"] < 300
    # the log is a pipe with a byte budget (nothing on disk); after the result nothing may come
    assert "wrote more than 64 MB to its stdout" in df.error["h-log-flood"] and len(df.log_tail["h-log-flood"]) <= 4000
    assert "after its result" in df.error["h-after-result"] and df.solve_cpu_s["h-after-result"] < 1.0
    assert "empty line" in df.error["h-blank-lines"] and df.solve_time_s["h-blank-lines"] < WALL_S
    # progress is a preparation's message: from a case, even with the right nonce, a protocol fault
    assert "only a preparation reports progress" in df.error["h-progress"] and df.solve_time_s["h-progress"] < WALL_S
    # 0 orphans: every process a case started has ended (the pids the planners could write
    # down, without isolation; every process with a case's tag, in both modes)
    pids = [int(x) for f in tmp_path.glob("*.pids") for x in f.read_text().split()]
    deadline = time.monotonic() + 5
    while (any(_alive(p) for p in pids) or case_processes()) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not [p for p in pids if _alive(p)] and not case_processes()
    assert elapsed < 120  # a generous bound that only a hung harness misses


def test_memory_figures_are_the_cases_own_not_the_harness(tmp_path):
    """A segfault while the harness holds more than the case's budget is a crash, not ``memory``."""
    suite = parse_suite(tiny_suite_toml("fat", wall_s=WALL_S, memory_mb=300))
    load_plugin_file(PLUGINS[1])
    cases, _ = build_cases(suite, ["h-segv"], plugins=PLUGINS[1:])
    ballast = bytearray(400 * 2**20)  # resident: every page written
    for i in range(0, len(ballast), 4096):
        ballast[i] = 1
    with Store(tmp_path / "fat.db") as store:
        store.register_suite(suite)
        run_cases(cases, store, LocalExecutor(jobs=1))
    del ballast
    row = load_runs(tmp_path / "fat.db").iloc[0]
    assert row.reason == "crashed" and row.peak_rss_mb < 200


def test_case_folders_of_a_killed_harness_are_cleared_by_the_next(tmp_path):
    """A harness (or Dask worker) killed mid-case leaves its case folder; the next harness on the machine removes it."""
    import subprocess
    import sys

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f"earthbench-case-{dead.pid}-abc123"
    stale.mkdir()
    (stale / "case.json").write_text("{}")
    mine = tmp_path / "earthbench-case-1-notours"  # pid 1 is alive: not ours to remove
    mine.mkdir()
    script = (
        "import sys; sys.path.insert(0, sys.argv[1]); from helpers import case_processes, tiny_suite_toml\n"
        "from earthbench.running.harness import build_cases, run_case\n"
        "from earthbench.registry import load_plugin_file\n"
        "from earthbench.results.suite import parse_suite\n"
        "load_plugin_file(sys.argv[2])\n"
        "(case,), _ = build_cases(parse_suite(tiny_suite_toml('c')), ['t-fast'], plugins=[sys.argv[2]])\n"
        "print(run_case(case).reason)\n"
    )
    env = {**__import__("os").environ, "TMPDIR": str(tmp_path)}
    out = subprocess.run([sys.executable, "-c", script, str(Path(__file__).parent), PLUGINS[0]],
                         capture_output=True, text=True, env=env, timeout=120)
    assert out.stdout.strip() == "ok", out.stderr
    assert not stale.exists() and mine.exists()
    assert not list(tmp_path.glob(f"earthbench-case-{dead.pid}-*"))
