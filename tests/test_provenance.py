"""The stamp names the code that ran: the installed build's version and commit, the plugin's distribution
or file — never the git of a checkout at run time (issue 35)."""

from __future__ import annotations

import json
import os
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

import earthbench
from earthbench.results.provenance import build_text, plugin

ROOT = Path(__file__).parents[1]


def _git(cwd: Path, *args: str) -> str:
    env = {**os.environ, "GIT_AUTHOR_NAME": "t", "GIT_AUTHOR_EMAIL": "t@t", "GIT_COMMITTER_NAME": "t",
           "GIT_COMMITTER_EMAIL": "t@t"}
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True, text=True, env=env).stdout.strip()


def test_a_plugin_file_is_named_by_its_text_and_a_distribution_by_its_build(tmp_path):
    f = tmp_path / "mine.py"
    f.write_text("x = 1\n")
    a = plugin(str(f))
    f.write_text("x = 2\n")
    plugin.cache_clear()
    b = plugin(str(f))
    assert a["file"] == b["file"] == "mine.py" and a["sha256"] != b["sha256"] and "commit" not in a
    built_in = plugin("earthbench_planners.greedy.backhoe:GreedyPlanner")
    assert built_in["name"] == "earthbench" and built_in["version"] == earthbench.__version__
    assert build_text("1.2", "abc+dirty") == "earthbench 1.2 (commit abc, uncommitted changes)"


@pytest.mark.slow
def test_a_non_editable_install_is_stamped_with_the_commit_it_was_built_from(tmp_path):
    """The Quick start's layout: a virtual environment inside the checkout. Install the project from
    commit 1 (not editable), commit again, run: the stamp names commit 1, clean, and the version."""
    checkout = tmp_path / "checkout"
    files = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                           check=True, capture_output=True).stdout.decode().split("\0")
    for name in filter(None, files):
        src = ROOT / name
        if src.is_file() and not name.startswith(("leaderboard/", ".venv")):
            dst = checkout / name
            dst.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dst)
    _git(checkout, "init", "-q")
    _git(checkout, "add", "-A")
    _git(checkout, "commit", "-qm", "one")
    first = _git(checkout, "rev-parse", "HEAD")
    venv = checkout / ".venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    py = venv / "bin" / "python"
    subprocess.run([str(py), "-m", "pip", "install", "--quiet", str(checkout)], check=True, capture_output=True)
    (checkout / "NOTES.txt").write_text("a later change\n")
    _git(checkout, "add", "NOTES.txt")
    _git(checkout, "commit", "-qm", "two")
    assert _git(checkout, "rev-parse", "HEAD") != first
    (checkout / "README.md").write_text("uncommitted\n")  # the checkout is dirty now; the installed build is not
    plugin_file = checkout / "tests" / "plugins" / "truncating_planners.py"
    db = tmp_path / "p.db"
    for planner, extra in (("greedy", []), ("h-truncated-greedy", ["--plugin", str(plugin_file)])):
        subprocess.run([str(venv / "bin" / "earthbench"), "run", "smoke", "--planner", planner, "--seeds", "0", "--quiet",
                        "--db", str(db), *extra], cwd=checkout, check=True, capture_output=True)
    with sqlite3.connect(db) as con:
        rows = con.execute("SELECT r.planner, e.project_commit, e.earthbench_version, e.plugin, e.plugin_commit FROM runs r "
                           "JOIN environments e ON e.id = r.environment_id").fetchall()
    by = {r[0]: r for r in rows}
    for planner in ("greedy", "h-truncated-greedy"):
        assert by[planner][1] == first and by[planner][2] == earthbench.__version__
    assert json.loads(by["greedy"][3]) == {"name": "earthbench", "version": earthbench.__version__, "commit": first}
    foreign = json.loads(by["h-truncated-greedy"][3])
    assert foreign["file"] == "truncating_planners.py" and len(foreign["sha256"]) == 64
    assert by["h-truncated-greedy"][4] is None  # a file that is no distribution has no commit: not earthbench's
