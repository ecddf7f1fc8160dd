"""The Dask executor on a real LocalCluster: same results as locally, lost workers, failed tasks."""

from __future__ import annotations

import _thread
import json
import os
import signal
import sqlite3
import threading
import time
import zlib
from pathlib import Path

import psutil
import pytest

distributed = pytest.importorskip("distributed")
dask = pytest.importorskip("dask")

from earthbench.cli import main  # noqa: E402
from earthbench.running.harness.dask_executor import DaskError, DaskExecutor, host_slot  # noqa: E402
from earthbench.registry import load_plugin_file  # noqa: E402
from earthbench.running.harness import LocalExecutor, build_cases, run_cases, run_suite  # noqa: E402
from earthbench.results.store import Store  # noqa: E402
from earthbench.results.suite import load_suite, parse_suite  # noqa: E402

from helpers import tiny_suite_toml  # noqa: E402

PLUGINS = Path(__file__).parent / "plugins"
FAULTY = str(PLUGINS / "faulty_planners.py")
DASK_PLANNERS = str(PLUGINS / "dask_planners.py")
TIMES = {"solve_time_s", "solve_cpu_s"}


def nap_suite(n: int):
    return parse_suite(tiny_suite_toml("nap", wall_s=30, memory_mb=2048, seeds=f"0-{n - 1}"))


def run_one_case_on(client, plugin: str, planner: str, db: Path):
    """One seed of the nap suite by ``planner`` (from the plugin file) through the cluster."""
    load_plugin_file(plugin)
    suite = nap_suite(1)
    cases, _ = build_cases(suite, [planner], plugins=[plugin])
    with Store(db) as store:
        store.register_suite(suite)
        return run_cases(cases, store, DaskExecutor(client))


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """Two worker processes with one slot each; a lost task is tried on at most two workers."""
    slots = tmp_path_factory.mktemp("slots")
    env = {"EARTHBENCH_SLOT_DIR": str(slots), "EARTHBENCH_TEST_NAP": "1.0"}
    # a restarted worker may take long to come back on a loaded machine: keep its nanny meanwhile
    config = {"distributed.scheduler.allowed-failures": 1, "distributed.deploy.lost-worker-timeout": "300s"}
    with dask.config.set(config):
        with distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, resources={"slots": 1},
            dashboard_address=":0", env=env,
        ) as lc, distributed.Client(lc) as client:
            yield lc, client


def stored(db) -> dict[tuple, dict]:
    """Every run row by resume key, with metrics minus the harness's times and the plan decoded."""
    con = sqlite3.connect(str(db))
    con.row_factory = sqlite3.Row
    out = {}
    for r in con.execute("SELECT r.*, e.hostname, e.cpu_model, e.cores AS cpu_cores FROM runs r "
                         "LEFT JOIN environments e ON e.id = r.environment_id"):
        key = (r["scenario_digest"], r["planner"], r["planner_version"], r["config_hash"])
        assert key not in out, "a case was stored twice"
        d = dict(r)
        d["metrics"] = {k: v for k, v in json.loads(r["metrics"] or "{}").items() if k not in TIMES}
        d["plan"] = zlib.decompress(r["plan"]).decode() if r["plan"] else None
        out[key] = d
    con.close()
    return out


def test_smoke_on_a_local_cluster_equals_the_local_executor(cluster, tmp_path):
    lc, client = cluster
    suite = load_suite("smoke")
    local_db, dask_db = tmp_path / "local.db", tmp_path / "dask.db"
    with Store(local_db) as store:
        rep = run_suite(suite, store, LocalExecutor(cores_per_case=2))
    assert rep.stored == len(suite.scenarios)
    # the command line, pointed at the cluster's scheduler
    assert main(["run", "smoke", "--db", str(dask_db), "--executor", "dask", "--scheduler", lc.scheduler_address, "--quiet"]) == 0
    local, remote = stored(local_db), stored(dask_db)
    assert set(local) == set(remote) and len(remote) == len(suite.scenarios)
    same = ["reason", "success", "valid", "volume_ratio", "loaded_volume", "makespan_s", "time_per_m3", "time_per_m3_ratio",
            "digs", "mean_bucket_fill", "travel_m", "metrics", "violations", "plan", "error", "suite", "scenario_id"]
    for key, row in remote.items():
        assert {c: row[c] for c in same} == {c: local[key][c] for c in same}
        assert row["reason"] == "ok" and row["solve_time_s"] is not None and row["solve_cpu_s"] is not None
        # the worker stamped its machine and pinned the case to a 2-core slot of it
        assert row["hostname"] and row["cpu_model"] and row["cpu_cores"] == os.cpu_count()
        assert len(row["cores"].split(",")) == min(2, len(os.sched_getaffinity(0)))
    # resume: a second run through the cluster stores nothing more
    assert main(["run", "smoke", "--db", str(dask_db), "--scheduler", lc.scheduler_address, "--quiet"]) == 0
    assert len(stored(dask_db)) == len(suite.scenarios)


def _kill_a_worker_mid_case(pids: dict[str, int], done: threading.Event, killed: list) -> None:
    """SIGKILL the first worker seen supervising a case process; remember that case process."""
    while not done.is_set():
        for addr, pid in pids.items():
            try:
                kids = [k for k in psutil.Process(pid).children() if "earthbench.running.harness.child" in " ".join(k.cmdline())]
            except psutil.Error:
                continue
            if kids:
                time.sleep(0.3)  # let the case get going
                os.kill(pid, signal.SIGKILL)
                killed.append((addr, kids[0]))
                return
        time.sleep(0.05)


def test_a_worker_killed_mid_case_still_stores_every_case_exactly_once(cluster, tmp_path):
    lc, client = cluster
    load_plugin_file(FAULTY)
    suite = nap_suite(3)
    cases, _ = build_cases(suite, ["t-nap"], plugins=[FAULTY])
    pids = client.run(os.getpid)
    done, killed = threading.Event(), []
    killer = threading.Thread(target=_kill_a_worker_mid_case, args=(pids, done, killed), daemon=True)
    killer.start()
    try:
        with Store(tmp_path / "k.db") as store:
            store.register_suite(suite)
            report = run_cases(cases, store, DaskExecutor(client))
    finally:
        done.set()
        killer.join(5)
    assert killed, "no worker was seen running a case"
    assert report.stored == len(cases) and report.counts == {"ok": len(cases)} and not report.interrupted
    rows = stored(tmp_path / "k.db")
    assert set(rows) == {c.key for c in cases}
    assert all(r["reason"] == "ok" for r in rows.values())
    # the case process of the killed worker died with it
    _, child = killed[0]
    assert not child.is_running() or child.status() == psutil.STATUS_ZOMBIE
    client.wait_for_workers(2, timeout=120)  # the nanny restarted the worker


def test_a_case_on_a_worker_runs_in_the_same_environment_as_locally(cluster, tmp_path):
    """The nanny tunes its worker's allocator; the case must not inherit that (nor be slower for it)."""
    lc, client = cluster
    assert any("MALLOC_TRIM_THRESHOLD_" in env for env in client.run(lambda: dict(os.environ)).values())
    report = run_one_case_on(client, FAULTY, "t-probe", tmp_path / "e.db")
    assert report.counts == {"ok": 1}
    (row,) = stored(tmp_path / "e.db").values()
    info = json.loads(row["plan"])["info"]
    assert info["allocator"] == [] and info["omp"] == str(len(info["affinity"]))  # the slot's thread cap


def _case_processes(pids: dict[str, int]) -> list[psutil.Process]:
    out = []
    for pid in pids.values():
        try:
            out += [k for k in psutil.Process(pid).children() if "earthbench.running.harness.child" in " ".join(k.cmdline())]
        except psutil.Error:
            pass
    return out


@pytest.mark.usefixtures("sigint_delivered")
def test_ctrl_c_ends_the_cases_in_flight_on_the_workers_and_stores_nothing_of_them(cluster, tmp_path):
    lc, client = cluster
    load_plugin_file(FAULTY)
    suite = nap_suite(2)
    cases, _ = build_cases(suite, ["t-sleep"], plugins=[FAULTY])
    pids = client.run(os.getpid)

    def interrupt_once_a_case_runs():
        for _ in range(600):
            if _case_processes(pids):
                _thread.interrupt_main()
                return
            time.sleep(0.05)

    watcher = threading.Thread(target=interrupt_once_a_case_runs, daemon=True)
    watcher.start()
    with Store(tmp_path / "i.db") as store:
        store.register_suite(suite)
        report = run_cases(cases, store, DaskExecutor(client))
    watcher.join(5)
    assert report.interrupted and report.stored == 0
    assert stored(tmp_path / "i.db") == {}
    for _ in range(100):  # the worker ended the case's process group (SIGTERM, then SIGKILL)
        if not _case_processes(pids):
            break
        time.sleep(0.1)
    assert not _case_processes(pids)


def test_cases_cancelled_by_the_cluster_are_an_error_not_a_silent_gap(cluster, tmp_path):
    lc, client = cluster
    load_plugin_file(FAULTY)
    suite = nap_suite(2)
    cases, _ = build_cases(suite, ["t-nap"], plugins=[FAULTY])
    pids = client.run(os.getpid)
    ex = DaskExecutor(client)

    def cancel_behind_its_back():
        for _ in range(600):
            if _case_processes(pids):
                client.cancel(list(ex._futures))
                return
            time.sleep(0.05)

    watcher = threading.Thread(target=cancel_behind_its_back, daemon=True)
    watcher.start()
    with Store(tmp_path / "x.db") as store:
        store.register_suite(suite)
        with pytest.raises(DaskError, match="cancelled by the Dask cluster.*run the same command again"):
            run_cases(cases, store, ex)
    watcher.join(5)
    assert len(stored(tmp_path / "x.db")) < len(cases)


def _isolation_switch(value: str | None):
    """A function setting ``EARTHBENCH_ISOLATION`` where it runs (a nanny's restarted worker inherits it)."""
    def switch() -> None:
        if value is None:
            os.environ.pop("EARTHBENCH_ISOLATION", None)
        else:
            os.environ["EARTHBENCH_ISOLATION"] = value
        __import__("earthbench.running.harness.isolation", fromlist=["support"]).support.cache_clear()
    return switch


def test_a_case_that_keeps_killing_its_worker_is_stored_as_crashed(cluster, tmp_path):
    """A sandboxed case cannot see its worker (docs/isolation.md); to test how the executor
    takes a worker's death, the cluster runs this case without isolation."""
    lc, client = cluster
    for nanny in (True, False):
        client.run(_isolation_switch("off"), nanny=nanny)
    try:
        report = run_one_case_on(client, DASK_PLANNERS, "t-kill-worker", tmp_path / "c.db")
        assert report.counts == {"crashed": 1} and report.stored == 1
        rows = {r["planner"]: r for r in stored(tmp_path / "c.db").values()}
        assert rows["t-kill-worker"]["reason"] == "crashed" and "died" in rows["t-kill-worker"]["error"]
        client.wait_for_workers(2, timeout=120)
    finally:
        for nanny in (True, False):
            client.run(_isolation_switch(None), nanny=nanny)


def test_a_task_that_raises_is_recorded_as_error(cluster):
    lc, client = cluster
    load_plugin_file(FAULTY)
    case = build_cases(nap_suite(1), ["t-fast"], plugins=[FAULTY])[0][0]
    ex = DaskExecutor(client)

    def broken():
        raise RuntimeError("earthbench is not installed on this worker")

    fut = client.submit(broken, pure=False)
    distributed.wait(fut)
    res = ex._collect(fut, case)
    assert res.reason == "error" and res.key == case.key
    assert "RuntimeError: earthbench is not installed on this worker" in res.error


class FakeClient:
    """Answers the executor's questions about two workers like a Client would."""

    def __init__(self, resources=({}, {}), reports=None):
        self.workers = {f"tcp://w{i}:1": {"resources": r} for i, r in enumerate(resources)}
        self.reports = reports

    def scheduler_info(self, n_workers=5):
        return {"workers": self.workers}

    def run(self, function, on_error="raise"):
        return self.reports if self.reports is not None else {a: function() for a in self.workers}


def test_workers_without_slots_are_refused_with_a_recipe():
    ex = DaskExecutor(FakeClient())
    with pytest.raises(DaskError, match='--resources "slots=K"'):
        ex.check()
    assert ex.slots == []
    assert len(DaskExecutor(FakeClient(({"slots": 2}, {"slots": 1}))).slots) == 3


def test_workers_that_cannot_import_earthbench_or_have_another_version_are_refused():
    broken = FakeClient(reports={"tcp://w0:1": ModuleNotFoundError("No module named 'earthbench'")})
    with pytest.raises(DaskError, match="tcp://w0:1 cannot run earthbench cases.*install earthbench"):
        DaskExecutor(broken).check()
    old = FakeClient(reports={"tcp://w0:1": {"earthbench": "0.0.1", "cpus": 2}})
    with pytest.raises(DaskError, match="has earthbench 0.0.1"):
        DaskExecutor(old).check()


def test_an_unreachable_scheduler_is_a_clear_error():
    with pytest.raises(DaskError, match="cannot reach the Dask scheduler"):
        DaskExecutor(scheduler="tcp://127.0.0.1:9", connect_timeout=1)


def test_the_host_slot_pool_hands_out_disjoint_cores(tmp_path, monkeypatch):
    if len(os.sched_getaffinity(0)) < 2:
        pytest.skip("needs two cores")
    monkeypatch.setenv("EARTHBENCH_SLOT_DIR", str(tmp_path))
    stop = threading.Event()
    with host_slot(1) as a, host_slot(1) as b:
        assert a and b and not set(a) & set(b)
        stop.set()
        with host_slot(1, stop) as c:
            assert c is None  # every core is taken and the run was stopped
    with host_slot(2) as d:
        assert len(d) == 2  # the locks were released


def test_each_worker_prepares_before_its_first_case_at_most_once(cluster, tmp_path):
    """A planner with a preparation: a worker that finds none on disk prepares before its first case."""
    lc, client = cluster
    prepared = str(tmp_path / "prepared")

    def setenv(**kw):
        os.environ.update(kw)

    def unsetenv(*names):
        for n in names:
            os.environ.pop(n, None)

    client.run(setenv, EARTHBENCH_PREPARED=prepared)
    try:
        plugin = str(PLUGINS / "preparing_planners.py")
        load_plugin_file(plugin)
        suite = nap_suite(4)
        cases, _ = build_cases(suite, ["t-prepares"], plugins=[plugin])
        with Store(tmp_path / "p.db") as store:
            store.register_suite(suite)
            report = run_cases(cases, store, DaskExecutor(client))
    finally:
        client.run(unsetenv, "EARTHBENCH_PREPARED")
    assert report.counts == {"ok": 4}
    assert len(list(Path(prepared).glob("t-prepares-*"))) == 1  # one folder, whichever worker made it
    rows = stored(tmp_path / "p.db").values()
    assert all(r["prepare_s"] > 0 for r in rows)
    assert all(json.loads(r["plan"])["info"]["prepared"].startswith(prepared) for r in rows)
