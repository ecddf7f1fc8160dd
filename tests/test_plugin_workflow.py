"""The README's plugin tutorial, end to end: `earthbench new-planner NAME` → package → `earthbench run smoke --planner NAME`."""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from earthbench.cli import main
from earthbench.errors import EarthbenchError
from earthbench.results.store import load_runs


pytestmark = pytest.mark.usefixtures("forget_test_planners")


def test_new_planner_as_a_plugin_file(tmp_path, capsys):
    pkg = tmp_path / "pkg"
    assert main(["new-planner", "tutorial-demo", "--dir", str(pkg)]) == 0
    assert "pip install -e" in capsys.readouterr().out
    for rel in (
        "pyproject.toml",
        "README.md",
        "earthbench_tutorial_demo/__init__.py",
        "earthbench_tutorial_demo/planner.py",
        "tests/test_planner.py",
    ):
        assert (pkg / rel).is_file(), rel
    assert 'tutorial-demo = "earthbench_tutorial_demo.planner:TutorialDemoPlanner"' in (pkg / "pyproject.toml").read_text()
    # the package's own test passes
    test = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(pkg / "tests")],
                          cwd=pkg, env={**os.environ, "PYTHONPATH": str(pkg)}, capture_output=True, text=True)
    assert test.returncode == 0, test.stdout + test.stderr
    # and its planner runs on the smoke suite, loaded from its file
    db = str(tmp_path / "t.db")
    plugin = str(pkg / "earthbench_tutorial_demo" / "planner.py")
    assert main(["run", "smoke", "--planner", "tutorial-demo", "--plugin", plugin, "--db", db, "--quiet"]) == 0
    df = load_runs(db)
    assert len(df) == 4 and set(df.planner) == {"tutorial-demo"} and set(df.reason) == {"ok"}
    assert df.success.all()


def test_new_planner_refuses_bad_names_and_existing_dirs(tmp_path):
    with pytest.raises(EarthbenchError, match="lower case"):
        main_raise(["new-planner", "Bad Name", "--dir", str(tmp_path / "x")])
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "keep.txt").write_text("mine")
    with pytest.raises(EarthbenchError, match="already exists"):
        main_raise(["new-planner", "ok-name", "--dir", str(tmp_path / "full")])


def main_raise(argv):
    from earthbench.cli import build_parser

    args = build_parser().parse_args(argv)
    return args._run(args)


@pytest.mark.slow
def test_tutorial_with_pip_install_in_a_fresh_venv(tmp_path):
    """`pip install -e` registers the planner through its entry point; nothing else is needed."""
    pkg = tmp_path / "earthbench-venv-demo"
    assert main(["new-planner", "venv-demo", "--dir", str(pkg)]) == 0
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    py = venv / "bin" / "python"
    # the new venv sees this environment's packages (earthbench and its dependencies) like a user's would
    inner = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                           capture_output=True, text=True, check=True).stdout.strip()
    outer = [sysconfig.get_paths()["purelib"], *[p for p in sys.path if p.endswith("site-packages")]]
    Path(inner, "outer-env.pth").write_text("import site; " + "; ".join(f"site.addsitedir({p!r})" for p in dict.fromkeys(outer)) + "\n")
    pip = subprocess.run([sys.executable, "-m", "pip", "--python", str(py), "install", "--quiet", "--no-deps", "-e", str(pkg)],
                         capture_output=True, text=True)
    if pip.returncode != 0 and ("No matching distribution" in pip.stderr or "connection" in pip.stderr.lower()):
        pytest.skip(f"pip could not fetch the build backend: {pip.stderr.strip()[-200:]}")
    assert pip.returncode == 0, pip.stderr
    listing = subprocess.run([str(py), "-m", "earthbench", "list", "planners"], capture_output=True, text=True, cwd=tmp_path)
    assert "venv-demo" in listing.stdout, listing.stderr
    db = str(tmp_path / "v.db")
    run = subprocess.run([str(py), "-m", "earthbench", "run", "smoke", "--planner", "venv-demo", "--db", db],
                         capture_output=True, text=True, cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    df = load_runs(db)
    assert len(df) == 4 and set(df.planner) == {"venv-demo"} and set(df.reason) == {"ok"}
    assert df.planner_version.iloc[0] == "0.1.0"
