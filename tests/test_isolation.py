"""Isolation (docs/isolation.md): the channels a case had into the harness, the store, other
cases and the machine, each tried by a hostile planner that raises once it gets through.

Each test states the reason the case must end with and the true figures the harness must
store. They need what the kernel gives on CI's machines (root or delegated cgroups, user
namespaces); where a fence is missing they are skipped, saying which and why.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from earthbench.running.harness import LocalExecutor, build_cases, cgroups, isolation, run_cases
from earthbench.publishing.board.tables import stamp
from earthbench.registry import load_plugin_file
from earthbench.results.store import Store, load_runs
from earthbench.results.suite import parse_suite

from helpers import tiny_suite_toml

PLUGINS = Path(__file__).parent / "plugins"
HOSTILE = str(PLUGINS / "hostile_planners.py")
FAULTY = str(PLUGINS / "faulty_planners.py")
STEPS = str(PLUGINS / "step_planners.py")

pytestmark = pytest.mark.usefixtures("forget_test_planners")
fenced = pytest.mark.skipif(not isolation.support().full, reason=isolation.describe())


def run(tmp_path: Path, suite_text: str, planners: list[str], plugin: str, db: Path | None = None):
    suite = parse_suite(suite_text)
    load_plugin_file(plugin)
    cases, _ = build_cases(suite, planners, plugins=[plugin])
    db = db or tmp_path / f"{suite.name}.db"
    with Store(db) as store:
        store.register_suite(suite)
        report = run_cases(cases, store, LocalExecutor(jobs=2, cores_per_case=suite.budget.cores))
    assert report.stored == len(planners) and not report.interrupted
    return load_runs(db).set_index("planner"), db


def one_core(text: str) -> str:
    return text.replace("cores = 2", "cores = 1")


@fenced
def test_the_channels_into_the_harness_and_other_cases_are_shut(tmp_path):
    db = tmp_path / "hostile.db"
    before, _ = run(tmp_path, tiny_suite_toml("first", wall_s=10.0), ["t-fast"], FAULTY, db)
    planners = ["h-read-store", "h-read-mem", "h-rewrite-other", "h-forge-report", "h-tree-memory", "h-affinity"]
    df, _ = run(tmp_path, one_core(tiny_suite_toml("hostile", wall_s=60.0, memory_mb=1024)), planners, HOSTILE, db)
    assert df.reason.drop("t-fast").to_dict() == {
        "h-read-store": "ok", "h-read-mem": "ok", "h-rewrite-other": "ok", "h-forge-report": "ok",
        "h-tree-memory": "memory", "h-affinity": "ok",
    }, df.error.to_dict()
    # 0 store rows changed by a case
    after = load_runs(db).set_index("planner").loc["t-fast"]
    assert after.reason == "ok" and after.solve_time_s == before.solve_time_s["t-fast"]
    # the kernel's figures, not the forged report: 2 s of CPU and 300 MB held
    assert df.solve_cpu_s["h-forge-report"] >= 1.8 and df.peak_rss_mb["h-forge-report"] >= 290
    # the memory budget holds for the tree: 1.8 GB asked, never more than the budget held
    assert df.peak_rss_mb["h-tree-memory"] <= 1024 + 1 and "memory budget of 1024 MB" in df.error["h-tree-memory"]
    assert df.processes["h-tree-memory"] >= 4  # counted in the cgroup: bubblewrap's two, the warden, the planner at least
    # the cores of the slot, whatever sched_setaffinity asked for
    with Store(db) as store:
        run_id = int(load_runs(db).set_index("planner").id["h-affinity"])
        info = json.loads(store.plan_json(run_id))["info"]
    assert info["affinity"] == [int(df.cores["h-affinity"])]
    assert set(load_runs(db).isolation) == {isolation.support().label}


@fenced
def test_no_compute_between_steps_and_no_prewritten_steps(tmp_path):
    text = tiny_suite_toml("steps", wall_s=20.0, target=1.2, size=(8.0, 6.0), n_bases=5, budget="step_s = 3.0\nmax_steps = 40")
    df, _ = run(tmp_path, one_core(text), ["s-helper", "s-prewritten"], STEPS)
    assert df.reason.to_dict() == {"s-helper": "ok", "s-prewritten": "error"}
    # the helper ran only while a step was being computed: on one core, CPU ≤ the calls' time
    assert df.steps["s-helper"] == 40
    assert df.solve_cpu_s["s-helper"] <= df.solve_time_s["s-helper"] + 0.1
    # an answer to an observation the planner never read ends the case, with nothing of it executed
    assert "not asked for" in df.error["s-prewritten"] or "nonce" in df.error["s-prewritten"]
    assert df.steps.fillna(0)["s-prewritten"] <= 1


def test_the_cpu_budget_ends_a_case_that_uses_more(tmp_path):
    df, _ = run(tmp_path, tiny_suite_toml("cpu", wall_s=20.0, budget="cpu_s = 1.0"), ["h-forge-report"], HOSTILE)
    assert df.reason["h-forge-report"] == "timeout"
    assert "CPU budget of 1 s" in df.error["h-forge-report"]
    assert 1.0 <= df.solve_cpu_s["h-forge-report"] < 2.0


@pytest.mark.usefixtures("isolation_off")
def test_without_isolation_a_run_says_so_and_is_stamped_none(tmp_path):
    import io

    from earthbench.results.progress import Progress

    suite = parse_suite(tiny_suite_toml("bare", seeds="0-1"))
    load_plugin_file(FAULTY)
    cases, _ = build_cases(suite, ["t-fast"], plugins=[FAULTY])
    out = io.StringIO()
    with Store(tmp_path / "bare.db") as store:
        store.register_suite(suite)
        run_cases(cases, store, LocalExecutor(jobs=2), progress=Progress(len(cases), stream=out, live=False))
    said = [line for line in out.getvalue().splitlines() if line.startswith("isolation:")]
    assert said == ["isolation: none — EARTHBENCH_ISOLATION=off; cases run with per-process fences only "
                    "(docs/isolation.md says how to enable it)"]  # once, for two cases
    df = load_runs(tmp_path / "bare.db").set_index("planner")
    assert set(df.reason) == {"ok"} and set(df.isolation) == {"none"} and df.processes.isna().all()
    # the leaderboard's stamp says how many of a table's runs had no fences
    lines = stamp(df.reset_index(), "bare", "backhoe", "now").lines()
    assert any(line.startswith("isolation: none for 2 of 2 runs") for line in lines)


@pytest.mark.skipif(isolation.support().cgroup is None, reason=isolation.describe())
def test_case_cgroups_of_a_killed_harness_are_removed_by_the_next(tmp_path):
    import subprocess
    import sys

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    probe = isolation.CaseCgroup.create(isolation.support().cgroup, cores=(), memory_bytes=64 * 2**20)
    stale = [os.path.join(os.path.dirname(d), f"earthbench-{dead.pid}-0") for d in probe.dirs.values()]
    probe.remove()
    for d in stale:
        os.mkdir(d)
    cgroups._clear_stale.cache_clear()
    isolation.CaseCgroup.create(isolation.support().cgroup, cores=(), memory_bytes=64 * 2**20).remove()
    assert not [d for d in stale if os.path.exists(d)]


PEEKER = '''
import os
from earthbench import Plan, Planner


class Peeks(Planner):
    """A plugin file run from a folder that also holds the store: raises if it sees anything but itself."""

    name = "h-peek-folder"

    def plan(self, scenario):
        beside = sorted(os.listdir(os.path.dirname(os.path.abspath(__file__))))
        if beside != [os.path.basename(__file__)]:
            raise RuntimeError(f"sees its folder: {beside}")
        return Plan()
'''


@fenced
def test_a_plugin_file_sees_itself_not_the_folder_it_sits_in(tmp_path):
    plugin = tmp_path / "peek.py"
    plugin.write_text(PEEKER)
    (tmp_path / "secret.toml").write_text("[budget]\n")
    df, _ = run(tmp_path, tiny_suite_toml("peek"), ["h-peek-folder"], str(plugin), tmp_path / "earthbench.db")
    assert df.reason["h-peek-folder"] == "ok", df.error["h-peek-folder"]


SIBLINGS = '''
import os
from earthbench import Plan, Planner


class Siblings(Planner):
    """A script-registered planner that imports a module and a package beside it, inside its case."""

    name = "h-siblings"

    def plan(self, scenario):
        import helper_mod
        from helper_pkg import VALUE

        here = sorted(os.listdir(os.path.dirname(os.path.abspath(__file__))))
        return Plan(info={"helper": helper_mod.VALUE, "pkg": VALUE, "here": here})
'''


def test_a_plugin_file_imports_its_sibling_modules_but_sees_nothing_else_beside_it(tmp_path):
    plugin = tmp_path / "siblings.py"
    plugin.write_text(SIBLINGS)
    (tmp_path / "helper_mod.py").write_text("VALUE = 1\n")
    (tmp_path / "helper_pkg").mkdir()
    (tmp_path / "helper_pkg" / "__init__.py").write_text("VALUE = 2\n")
    (tmp_path / "notes.toml").write_text("[budget]\n")
    df, db = run(tmp_path, tiny_suite_toml("siblings"), ["h-siblings"], str(plugin), tmp_path / "earthbench.db")
    assert df.reason["h-siblings"] == "ok", df.error["h-siblings"]
    with Store(db) as store:
        info = json.loads(store.plan_json(int(df.id["h-siblings"])))["info"]
    assert (info["helper"], info["pkg"]) == (1, 2)
    if isolation.support().bwrap:  # the modules, not the store beside them nor anything else
        assert info["here"] == ["helper_mod.py", "helper_pkg", "siblings.py"]


def test_a_run_refuses_a_store_its_cases_could_read(tmp_path):
    """A plugin inside a package folder sees the whole package: a store in it is refused, saying why."""
    from earthbench.errors import StoreError

    pkg = tmp_path / "mypkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    plugin = pkg / "siblings.py"
    plugin.write_text(SIBLINGS)
    with pytest.raises(StoreError, match=r"lies inside .*mypkg, which the cases of .* can read; keep the store out"):
        run(tmp_path, tiny_suite_toml("exposed"), ["h-siblings"], str(plugin), pkg / "earthbench.db")


@pytest.mark.skipif(isolation.support().cgroup is None, reason=isolation.describe())
def test_a_cgroup_without_namespaces_still_holds_the_budgets(tmp_path, monkeypatch):
    """Where user namespaces are not allowed but cgroups are (e.g. root in a container without
    them), the kernel still counts and enforces the budgets of the whole tree."""
    cg = isolation.support().cgroup
    monkeypatch.setattr(isolation, "support", lambda: isolation.Support(None, cg, ("no namespaces (test)",)))
    df, _ = run(tmp_path, tiny_suite_toml("bare-cg", wall_s=60.0, memory_mb=1024), ["h-forge-report", "h-tree-memory"], HOSTILE)
    assert df.reason.to_dict() == {"h-forge-report": "ok", "h-tree-memory": "memory"}
    assert df.solve_cpu_s["h-forge-report"] >= 1.8 and df.peak_rss_mb["h-forge-report"] >= 290
    assert df.peak_rss_mb["h-tree-memory"] <= 1024 + 1
    assert set(df.isolation) == {f"cgroup-{cg}"}


def test_no_variable_of_the_harness_reaches_a_case(tmp_path, monkeypatch):
    """A secret of the harness's environment, its HOME, OLDPWD and working folders: none reach a
    case (which sends back all it was given, in its plan's info and in its log)."""
    secret = "s3cr3t-" + os.urandom(8).hex()
    monkeypatch.setenv("EARTHBENCH_PUBLISH_TOKEN", secret)
    monkeypatch.setenv("OLDPWD", str(tmp_path / "where-the-operator-was"))
    df, db = run(tmp_path, tiny_suite_toml("env"), ["h-env-leak"], HOSTILE)
    assert df.reason["h-env-leak"] == "ok", df.error["h-env-leak"]
    with Store(db) as store:
        info = json.loads(store.plan_json(int(df.id["h-env-leak"])))["info"]
        tail = df.log_tail["h-env-leak"]
    env = info["env"]
    assert secret not in json.dumps(info) and secret not in tail
    assert "OLDPWD" not in env and env.get("PWD") in (None, info["cwd"]) and env.get("HOME") != os.environ.get("HOME"), env
    assert "where-the-operator-was" not in tail
    if isolation.support().full:  # nothing of the host's paths with the harness's pid either
        import re

        assert env["HOME"] == "/tmp" and info["cwd"] == "/tmp"
        assert not [k for k, v in env.items() if re.search(rf"(?<![0-9a-z]){os.getpid()}(?![0-9a-z])", v)], env


UNPRIVILEGED = r'''
import json, sys
sys.path.insert(0, sys.argv[1])
from helpers import tiny_suite_toml
from earthbench.running.harness import build_cases, isolation, run_case
from earthbench.registry import load_plugin_file
from earthbench.results.suite import parse_suite
load_plugin_file(sys.argv[2])
out = {"isolation": isolation.describe()}
for name in ("h-forge-report", "h-tree-memory", "h-env-leak"):
    (case,), _ = build_cases(parse_suite(tiny_suite_toml("u", wall_s=60.0, memory_mb=1024)), [name], plugins=[sys.argv[2]])
    r = run_case(case, (0,))
    out[name] = [r.reason, r.solve_cpu_s, r.peak_rss_mb, r.isolation]
print(json.dumps(out))
'''


def _hidden_folder(path: str) -> str:
    """The folder under the first ancestor of ``path`` that other users cannot enter ('' if none)."""
    parts = Path(path).parts
    for i in range(1, len(parts) - 1):
        if not os.stat(Path(*parts[:i + 1])).st_mode & 0o001:
            return str(Path(*parts[:i + 2]))
    return ""


@pytest.mark.slow
@pytest.mark.skipif(os.getuid() != 0 or isolation.support().cgroup != "v1" or not isolation.support().bwrap,
                    reason="needs root to delegate a cgroup v1 subtree, and user namespaces")
def test_an_unprivileged_harness_keeps_the_fences(tmp_path):
    """As ``nobody`` owning a delegated cgroup subtree (docs/isolation.md "Without root"), the
    harness has every fence: the kernel's CPU figure, not the forged one; the memory budget of
    the whole tree; an allow-listed environment."""
    import shutil
    import subprocess
    import sys

    if not (shutil.which("setpriv") and shutil.which("unshare")):
        pytest.skip("needs setpriv and unshare (util-linux)")
    # a venv inside a 0700 folder (a clone under mktemp -d) and a pyenv under /root: both made visible
    hidden = {_hidden_folder(p) for p in (os.path.realpath(sys.executable), os.path.abspath(sys.executable), __file__)} - {""}
    script = Path(__file__).resolve().parents[1] / "scripts" / "unprivileged_harness.sh"
    env = {**os.environ, "EB_BIND": ":".join(sorted(hidden))}
    out = subprocess.run([str(script), sys.executable, "-c", UNPRIVILEGED, str(Path(__file__).parent), HOSTILE],
                         capture_output=True, text=True, env=env, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["isolation"] == "isolation: namespaces+cgroup-v1"
    assert got["h-forge-report"][0] == "ok" and got["h-forge-report"][1] >= 1.8 and got["h-forge-report"][2] >= 290
    assert got["h-tree-memory"][0] == "memory" and got["h-tree-memory"][2] <= 1024 + 1
    assert got["h-env-leak"][0] == "ok" and {g[3] for k, g in got.items() if k != "isolation"} == {"namespaces+cgroup-v1"}
