"""The README's plugin route end to end, in a fresh environment: a script, a single file, an installed package.

A new virtual environment is made for the test; it sees earthbench and its dependencies through
a ``.pth`` file adding this interpreter's site-packages (the "installs" are the test
environment's, so the test takes seconds, not minutes), and nothing else: no ``PYTHONPATH``,
a scratch home and working directory. In it, as a newcomer following the README would:

1. a script registers a planner with ``@earthbench.register_planner`` and runs a suite from
   Python, under its ``__main__`` guard;
2. a single file is run with ``earthbench run smoke --plugin FILE``;
3. ``earthbench new-planner`` writes a package, ``pip install -e`` installs it, its own test
   passes, and ``earthbench run`` finds it by its entry point;

then ``earthbench leaderboard`` ranks all three against greedy.
"""

from __future__ import annotations

import os
import shlex
import sqlite3
import subprocess
import sys
import sysconfig
import venv
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

SCRIPT = '''
import earthbench
from earthbench import Plan, Planner
from earthbench.running.harness import run_suite
from earthbench.results.store import Store
from earthbench.results.suite import load_suite
from earthbench_planners.greedy.backhoe import GreedyPlanner


@earthbench.register_planner
class ScriptGreedy(GreedyPlanner):
    name = "script-greedy"
    version = "1"


if __name__ == "__main__":
    with Store("route.db") as store:
        run_suite(load_suite("smoke"), store, planners=["script-greedy"])
'''

FILE_PLUGIN = '''
from earthbench_planners.greedy.backhoe import GreedyPlanner


class FileGreedy(GreedyPlanner):
    name = "file-greedy"
    version = "1"
'''


@pytest.fixture(scope="module")
def fresh(tmp_path_factory):
    root = tmp_path_factory.mktemp("newcomer")
    env_dir = root / "venv"
    venv.EnvBuilder(with_pip=False).create(env_dir)
    python = env_dir / "bin" / "python"
    site = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          capture_output=True, text=True, check=True).stdout.strip()
    # addsitedir, not a bare path: the test environment's own .pth files (its editable install of earthbench) must run
    Path(site, "test-environment.pth").write_text(f"import site; site.addsitedir({sysconfig.get_paths()['purelib']!r})\n")
    work = root / "work"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")}
    env.update(HOME=str(root), PATH=f"{env_dir / 'bin'}{os.pathsep}{env['PATH']}")

    def run(*args: str, check: bool = True) -> subprocess.CompletedProcess:
        res = subprocess.run([str(python), *args], cwd=work, env=env, capture_output=True, text=True, timeout=600)
        if check:
            assert res.returncode == 0, f"{args}: {res.stdout[-1500:]}\n{res.stderr[-3000:]}"
        return res

    return run, work


def test_script_file_and_package_reach_a_ranked_table(fresh):
    run, work = fresh
    # 1. a script, run from Python under its guard
    (work / "mine.py").write_text(SCRIPT)
    run("mine.py")
    # 2. a single file with --plugin
    (work / "file_greedy.py").write_text(FILE_PLUGIN)
    run("-m", "earthbench", "run", "smoke", "--planner", "file-greedy", "--plugin", "file_greedy.py", "--db", "route.db")
    # 3. the tutorial package, installed into the fresh environment
    run("-m", "earthbench", "new-planner", "route-demo")
    run("-m", "pip", "install", "--quiet", "--no-deps", "-e", "earthbench-route-demo")  # its build backend from the index
    run("-m", "pytest", "-q", "-p", "no:cacheprovider", "earthbench-route-demo/tests")
    run("-m", "earthbench", "run", "smoke", "--db", "route.db", "--planner", "route-demo", "--planner", "greedy")
    # the board ranks all four
    run("-m", "earthbench", "leaderboard", "--db", "route.db", "--out", "board", "--no-terrain", "--replays", "2")
    table = (work / "board" / "README.md").read_text()
    # the suite's ranked table ("Rank ‡" when the suite is too small for a paired test to separate planners)
    main = table[table.index("| Rank"):].split("\n\n")[0].splitlines()[2:]
    assert sorted(row.split("|")[2].strip() for row in main) == ["file-greedy", "greedy", "route-demo", "script-greedy"]
    assert all(row.split("|")[1].strip().rstrip("=").isdigit() for row in main), main  # every one ranked
    # the package went into the fresh environment, not the test's
    where = run("-c", "import earthbench_route_demo, sys; print(earthbench_route_demo.__file__, sys.prefix)").stdout
    assert sys.prefix not in where
    with sqlite3.connect(work / "route.db") as db:
        reasons = dict(db.execute("SELECT planner, group_concat(DISTINCT reason) FROM runs GROUP BY planner").fetchall())
    assert reasons == {"script-greedy": "ok", "file-greedy": "ok", "route-demo": "ok", "greedy": "ok"}



def test_the_readme_route_and_every_printed_command_run_as_written(tmp_path):
    """``scripts/newcomer_route.py --reuse``: the README's steps 1–4 as written in a fresh environment, then every
    command earthbench printed for the user (``see:``, ``next:``, the new package's steps), each as printed."""
    from helpers import load_script

    route_script = load_script("newcomer_route")
    lines: list[str] = []
    route = route_script.walk(tmp_path, reuse=True, say=lines.append)
    assert not route.failed, "\n".join(lines) + "\n" + "\n".join(s.output[-2000:] for s in route.failed)
    readme = route_script.readme_commands((route_script.ROOT / "README.md").read_text())
    ran = [s.command for s in route.steps]
    assert all(c in ran for c in readme), "a README command did not run"
    printed = {s.command: s.source for s in route.steps if s.source != "README"}
    # the package's own steps, the runs filter and the board of each run, a submission's merge
    assert "pip install -e earthbench-my-planner" in printed and "earthbench run smoke --planner my-planner" in printed
    assert any(c.startswith("earthbench runs --suite quick") for c in printed)
    assert "earthbench leaderboard --suite quick" in printed and any(c.startswith("earthbench merge ") for c in printed)
    assert "passed" in next(s.output for s in route.steps if "python -m pytest earthbench-my-planner/tests" in s.command)
    # step 4: the new planner ranked beside the published board's planners, none of which ran here
    ranked = (route.workdir / "ranked" / "README.md").read_text()
    assert all(f"| {name} " in ranked for name in ("my-planner", "greedy", "singh-cannon-backhoe", "stl-tamp")), ranked[:2000]
    runs = [shlex.split(c) for c in ran if c.startswith("earthbench run ")]
    assert runs and all({w for a, w in zip(r, r[1:]) if a == "--planner"} == {"my-planner"} for r in runs), runs
    assert "greedy" in next(s.output for s in route.steps if s.command.startswith("earthbench compare ranked.db"))


def test_hints_are_read_as_printed():
    """The route's reader of printed commands: inline ones stop where their explanation starts; a `next:`
    block's indented lines are whole commands; placeholders are not run."""
    from helpers import load_script

    hints = load_script("newcomer_route").hints
    text = ("[1/2] ok 1 | t: invalid — cut_depth; see: earthbench runs --db 'a b.db' --id 7\n"
            "next: earthbench runs --suite s --reason error --short  (the 2 failed runs; then --id N for one run)\n"
            "      earthbench leaderboard --suite s --seeds 0-2,7  (tables)\n"
            "  to see it: earthbench runs --id 7 --plan-out P.json --scenario-out S.json, then earthbench show --plan P.json\n"
            "merge it with `earthbench merge ALL.db m.db`; the command: earthbench runs --id N\n"
            "next:\n  pip install -e pkg\n  earthbench run smoke --planner p  (first run)\n\n  earthbench not-this\n")
    assert hints(text) == [
        "earthbench runs --db 'a b.db' --id 7", "earthbench runs --suite s --reason error --short",
        "earthbench leaderboard --suite s --seeds 0-2,7", "earthbench runs --id 7 --plan-out P.json --scenario-out S.json",
        "earthbench show --plan P.json", "earthbench merge ALL.db m.db", "pip install -e pkg", "earthbench run smoke --planner p",
        "earthbench not-this"]
