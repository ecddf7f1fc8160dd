"""The traps a newcomer met on the plugin route (issue 37): each ends in a clear one-line error or a note, never silence."""

from __future__ import annotations

import json
import os
import sqlite3
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from earthbench.cli import COMMANDS, main
from earthbench.running.harness import Case, PlannerRef, run_case
from earthbench.results.store import load_runs
from earthbench.results.suite import load_suite
from helpers.leaderboard import Behaviour, fill_store, ref, suite_of

pytestmark = pytest.mark.usefixtures("forget_test_planners")
ROOT = Path(__file__).resolve().parent.parent

SCRIPT_HEAD = '''
import earthbench
from earthbench import Plan, Planner
from earthbench.running.harness import run_suite
from earthbench.results.store import Store
from earthbench.results.suite import load_suite


@earthbench.register_planner
class Idle(Planner):
    name = "idle-script"
    version = "1"
    tracks = ("backhoe",)

    def plan(self, scenario):
        return Plan()

'''
RUN = 'with Store("s.db") as store:\n    run_suite(load_suite("smoke"), store, planners=["idle-script"], seeds=[0])\nprint("done")\n'


def _script(tmp_path: Path, body: str) -> subprocess.CompletedProcess:
    (tmp_path / "mine.py").write_text(SCRIPT_HEAD + body)
    return subprocess.run([sys.executable, "mine.py"], cwd=tmp_path, capture_output=True, text=True, timeout=300)


def test_a_script_that_runs_a_suite_without_a_main_guard_is_told_why(tmp_path):
    """Each case process imports the script to find its planner: unguarded, it would start the suite again in every case."""
    res = _script(tmp_path, RUN)
    assert res.returncode != 0 and "done" not in res.stdout
    last = res.stderr.strip().splitlines()[-1]
    assert "line 19" in last and "if __name__ == \"__main__\":" in last
    assert not (tmp_path / "s.db").exists() or load_runs(tmp_path / "s.db").empty  # nothing stored


def test_the_same_script_under_a_main_guard_runs(tmp_path):
    res = _script(tmp_path, 'if __name__ == "__main__":\n' + textwrap.indent(RUN, "    "))
    assert res.returncode == 0, res.stderr
    runs = load_runs(tmp_path / "s.db")
    assert len(runs) == 2 and set(runs.planner) == {"idle-script"} and "timeout" not in set(runs.reason)


def test_a_planner_file_that_starts_a_suite_when_imported_fails_its_case_at_once(tmp_path):
    """The case-side guard: whatever imports a suite run into a case process gets an error, not a 60 s wait."""
    plugin = tmp_path / "reentrant.py"
    plugin.write_text(SCRIPT_HEAD.replace("idle-script", "reentrant") + RUN.replace("idle-script", "reentrant"))
    scenario = load_suite("smoke").scenarios[0]
    planner = PlannerRef(name="reentrant", version="1", source=str(plugin), config={}, config_hash="x")
    res = run_case(Case("smoke", "d", 0.9, scenario, planner), cores=(0, 1))
    assert res.reason == "error"
    assert "started a suite run while a case process imported it" in res.error


SHADOW = '''
from earthbench import Plan, Planner


class Mine(Planner):
    name = "greedy"
    version = "9"
    tracks = ("backhoe",)

    def plan(self, scenario):
        return Plan()
'''


@pytest.mark.parametrize("decorated", [False, True])
def test_a_plugin_file_cannot_silently_lose_to_an_installed_planner_of_its_name(tmp_path, capsys, decorated):
    plugin = tmp_path / "shadow.py"
    text = SHADOW.replace("class Mine", "@earthbench.register_planner\nclass Mine").replace(
        "from earthbench import", "import earthbench\nfrom earthbench import") if decorated else SHADOW
    plugin.write_text(text)
    db = tmp_path / "x.db"
    assert main(["run", "smoke", "--planner", "greedy", "--plugin", str(plugin), "--db", str(db), "--seeds", "0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "already registered" in err and "entry point" in err
    assert not db.exists()
    from earthbench.registry import PLANNERS

    assert PLANNERS.get("greedy").version != "9"  # the installed one is still the one registered


def test_a_plugin_class_without_plan_gets_the_real_reason(tmp_path, capsys):
    plugin = tmp_path / "noplan.py"
    no_plan = SHADOW.replace('"greedy"', '"no-plan"').replace("    def plan(self, scenario):\n        return Plan()\n", "    pass\n")
    plugin.write_text(no_plan)
    assert main(["plan", "no-plan", "--plugin", str(plugin), "--terrain", "rbf", "-o", str(tmp_path / "p.json")]) == 2
    err = capsys.readouterr().err
    assert "does not implement plan()" in err and "did you mean" not in err.lower()


FILE_PLANNER = '''
from earthbench_planners.greedy.backhoe import GreedyPlanner


class FileGreedy(GreedyPlanner):
    name = "file-greedy"
    version = "1"
'''


def test_verify_takes_plugin_files(tmp_path, capsys):
    plugin = tmp_path / "fg.py"
    plugin.write_text(FILE_PLANNER)
    db = str(tmp_path / "v.db")
    assert main(["run", "smoke", "--planner", "file-greedy", "--plugin", str(plugin), "--db", db, "--seeds", "0", "--quiet"]) == 0
    capsys.readouterr()
    assert main(["verify", db, "--sample", "2", "--plugin", str(plugin)]) == 0
    assert "2/2" in capsys.readouterr().out
    from earthbench.registry import PLANNERS

    PLANNERS.unregister("file-greedy")  # as in a new process, where only --plugin registers it
    assert main(["verify", db, "--sample", "2"]) == 2  # without the file: the error says how to give it
    assert "--plugin FILE.py" in capsys.readouterr().err


def test_merge_skips_identical_duplicates_on_request_only(tmp_path, capsys):
    suite = suite_of(2)
    a = fill_store(tmp_path / "a.db", suite, [Behaviour(ref("greedy"))])
    b = fill_store(tmp_path / "b.db", suite, [Behaviour(ref("greedy"), slow=2.0), Behaviour(ref("half"), keep=0.5)])
    out = tmp_path / "out.db"
    assert main(["merge", str(out), str(a), str(b)]) == 2
    assert "--skip-duplicates" in capsys.readouterr().err
    assert main(["merge", str(out), str(a), str(b), "--skip-duplicates"]) == 0
    assert "left out 4 run(s)" in capsys.readouterr().out
    runs = load_runs(out)
    assert sorted(runs.planner.value_counts().items()) == [("greedy", 4), ("half", 4)]
    assert set(runs[runs.planner == "greedy"].solve_time_s) == set(load_runs(a).solve_time_s)  # the first store's
    # a duplicate with another plan still refuses the merge
    c = fill_store(tmp_path / "c.db", suite, [Behaviour(ref("greedy"), keep=0.5)])
    assert main(["merge", str(tmp_path / "out2.db"), str(a), str(c), "--skip-duplicates"]) == 2
    assert "with a different plan or outcome" in capsys.readouterr().err
    assert not (tmp_path / "out2.db").exists()


@pytest.fixture
def scenario_and_plan(tmp_path):
    s, p = tmp_path / "s.json", tmp_path / "p.json"
    assert main(["plan", "greedy", "--terrain", "rbf", "--target", "0.56", "--save-scenario", str(s), "-o", str(p)]) == 0
    return s, p


def test_show_checks_its_outputs_before_any_work(tmp_path, capsys, scenario_and_plan, monkeypatch):
    s, p = scenario_and_plan
    capsys.readouterr()
    assert main(["show", "--scenario", str(s), "--plan", str(p), "-o", str(tmp_path / "missing" / "dir" / "x.png")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("earthbench: error:") and "does not exist" in err and "Traceback" not in err
    from matplotlib import animation

    monkeypatch.setattr(animation.FFMpegWriter, "isAvailable", classmethod(lambda cls: False))
    png = tmp_path / "x.png"
    assert main(["show", "--scenario", str(s), "--plan", str(p), "-o", str(png), "--animate", str(tmp_path / "x.mp4")]) == 2
    assert "ffmpeg" in capsys.readouterr().err and not png.exists()  # nothing written before the error


def test_show_with_only_animate_writes_only_the_animation_and_says_where(tmp_path, capsys, scenario_and_plan, monkeypatch):
    s, p = scenario_and_plan
    monkeypatch.chdir(tmp_path)
    capsys.readouterr()
    assert main(["show", "--scenario", str(s), "--plan", str(p), "--animate", "a.gif", "--frames", "3"]) == 0
    out = capsys.readouterr().out
    assert str(tmp_path / "a.gif") in out and (tmp_path / "a.gif").is_file()
    assert not (tmp_path / "earthbench-show.png").exists()
    assert main(["show", "--scenario", str(s), "--plan", str(p)]) == 0
    out = capsys.readouterr().out
    assert str(tmp_path / "earthbench-show.png") in out and "no -o given" in out


def test_run_says_when_jobs_is_more_than_the_machine_runs_at_once(tmp_path, capsys):
    db = str(tmp_path / "j.db")
    assert main(["run", "smoke", "--db", db, "--seeds", "0", "--jobs", "999"]) == 0
    err = capsys.readouterr().err
    assert "note: --jobs 999: only" in err and "cores of its own" in err


def test_a_local_suite_file_named_like_a_registered_suite_is_refused(tmp_path, capsys):
    builtin = load_suite("smoke").path
    copy = tmp_path / "smoke.toml"
    copy.write_text(Path(builtin).read_text())
    assert load_suite(copy).digest == load_suite("smoke").digest  # an identical copy is the same suite
    copy.write_text(Path(builtin).read_text().replace("seeds = [0, 1]", "seeds = [0, 1, 2]"))
    assert main(["run", str(copy), "--db", str(tmp_path / "l.db")]) == 2
    err = capsys.readouterr().err
    assert "like the registered suite" in err and "name" in err
    assert not (tmp_path / "l.db").exists()


def test_a_new_board_removes_the_figures_of_the_old_one(tmp_path):
    from earthbench.publishing.publish import publish

    a = fill_store(tmp_path / "a.db", suite_of(2, name="one"), [Behaviour(ref("greedy"))])
    b = fill_store(tmp_path / "b.db", suite_of(2, name="two"), [Behaviour(ref("greedy"))])
    out = tmp_path / "board"
    publish(a, out, terrain=False, replays=0, workers=1)
    old = {f.name for f in (out / "figures").iterdir()}
    assert old and all(n.startswith("one-") for n in old)
    res = publish(b, out, terrain=False, replays=0, workers=1)
    now = {f.name for f in (out / "figures").iterdir()}
    assert now and all(n.startswith("two-") for n in now)
    assert {p.name for p in res.removed} == old


@pytest.mark.parametrize("command", [c.rstrip("_").replace("_", "-") for c in COMMANDS])
def test_help_texts_are_plain_text(command, capsys):
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = capsys.readouterr().out
    assert "``" not in text and not any(role in text for role in (":func:", ":class:", ":mod:", ":meth:"))


def test_validate_a_time_too_large_for_a_float_is_an_invalid_plan(tmp_path, capsys, scenario_and_plan):
    s, p = scenario_and_plan
    doc = json.loads(p.read_text())
    doc["actions"][-1]["t_end"] = int("9" * 401)
    big = tmp_path / "big.json"
    big.write_text(json.dumps(doc))
    capsys.readouterr()
    assert main(["validate", str(big), "--scenario", str(s)]) == 1
    out = capsys.readouterr().out
    assert "malformed" in out and "must be finite" in out and "401 digits" in out and "not valid JSON" not in out


def test_generator_parameters_are_bounded_by_the_cell_cap(tmp_path, capsys):
    suite = tmp_path / "big.toml"
    suite.write_text(textwrap.dedent('''
        name = "big"
        track = "backhoe"
        [budget]
        wall_s = 60
        cores = 2
        memory_mb = 4096
        [[family]]
        name = "f"
        generator = "rbf"
        targets = [1.0]
        seeds = [0]
        [family.params]
        n_bases = 100000000
    '''))
    assert main(["suites", str(suite)]) == 2
    err = capsys.readouterr().err
    assert "n_bases = 100000000 is out of range" in err and "28,800" in err
    assert main(["plan", "greedy", "--terrain", "rbf", "--param", "n_bases=1e8", "-o", str(tmp_path / "p.json")]) == 2
    assert "out of range" in capsys.readouterr().err


def test_the_tutorial_commands_work_in_the_quick_start_environment():
    """The README's step 1 installs pytest before the tutorial's test: the Quick start's environment has none."""
    readme = (ROOT / "README.md").read_text()
    step = readme[readme.index("## 1. Write a planner plugin"):readme.index("## 2.")]
    assert "pip install pytest && python -m pytest earthbench-my-planner/tests" in step
    assert os.path.isfile(ROOT / ".ci" / "run")


def test_scenario_documents_with_huge_integers_are_refused_cleanly(tmp_path, capsys, scenario_and_plan):
    s, p = scenario_and_plan
    doc = json.loads(s.read_text())
    doc["task"]["target_volume"] = int("9" * 401)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    capsys.readouterr()
    assert main(["validate", str(p), "--scenario", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("earthbench: error:") and "Traceback" not in err


def test_stored_scenarios_are_never_read_as_file_names(tmp_path):
    """A forged store's scenario document that names a file on the verifying machine is not read."""
    import zlib

    from earthbench.results.store import Store

    db = fill_store(tmp_path / "f.db", suite_of(1), [Behaviour(ref("greedy"))])
    target = tmp_path / "elsewhere.json"
    with Store(db) as store:
        digest, = store.db.execute("SELECT digest FROM scenarios LIMIT 1").fetchone()
        target.write_text(store.scenario(digest).to_json())
    con = sqlite3.connect(db)
    con.execute("UPDATE scenarios SET doc=? WHERE digest=?", (zlib.compress(str(target).encode()), digest))
    con.commit()
    con.close()
    with Store(db) as store, pytest.raises(Exception, match="not valid JSON"):
        store.scenario(digest)


@pytest.mark.slow
def test_the_documented_dask_script_runs_as_written(tmp_path):
    """docs/running.md's LocalCluster block, saved as a script: its workers re-import it, so it needs its guard."""
    pytest.importorskip("distributed")
    text = (ROOT / "docs" / "running.md").read_text()
    block = text[text.index("```python\nfrom distributed import Client, LocalCluster"):]
    code = block[len("```python\n"):block.index("```", 10)]
    (tmp_path / "cluster.py").write_text(code)
    res = subprocess.run([sys.executable, "cluster.py"], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    runs = load_runs(tmp_path / "earthbench.db")
    assert len(runs) == 4 and set(runs.reason) == {"ok"}


def test_the_tutorial_package_tests_run_from_inside_a_project_with_other_pytest_settings(tmp_path):
    """The README runs `python -m pytest earthbench-my-planner/tests` in the earthbench clone, whose
    pyproject.toml asks for pytest-benchmark's --benchmark-skip: the package's own settings must win."""
    from earthbench.cli.new_planner import write_package

    (tmp_path / "pyproject.toml").write_text('[tool.pytest.ini_options]\naddopts = "--an-option-only-the-clone-knows"\n')
    write_package("clone-demo", tmp_path / "earthbench-clone-demo")
    res = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "earthbench-clone-demo/tests"],
                         cwd=tmp_path, capture_output=True, text=True, timeout=300,
                         env={**os.environ, "PYTHONPATH": str(tmp_path / "earthbench-clone-demo")})
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
