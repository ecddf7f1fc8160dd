"""The plugin API stays put: every public name imports, the docs list the same names, moved names still work."""

from __future__ import annotations

import ast
import importlib
import json
import re
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

import earthbench
from earthbench.api import PUBLIC

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("module", sorted(PUBLIC))
def test_every_public_name_imports(module):
    mod = importlib.import_module(module)
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)  # a public name is never a deprecated alias
        missing = [name for name in PUBLIC[module] if not hasattr(mod, name)]
    assert not missing, f"{module} lacks {missing}"


def test_docs_list_the_same_names():
    text = (ROOT / "docs" / "plugins.md").read_text()
    table = text[text.index("## The public API"):]
    documented = {m.group(1): tuple(re.findall(r"`([^`]+)`", m.group(2)))
                  for m in re.finditer(r"^\| `([a-z_.]+)` \| (.+) \|$", table, re.M)}
    assert documented == PUBLIC


def test_builtin_plugins_import_only_public_names():
    """The built-in planners, terrains and metrics are plugins like any other: they use only the public API."""
    private = []
    for folder in ("planners", "terrains", "metrics"):
        for f in (ROOT / folder).rglob("*.py"):
            for node in ast.walk(ast.parse(f.read_text())):
                if isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").startswith("earthbench"):
                    private += [f"{f.relative_to(ROOT)}: {node.module}.{a.name}" for a in node.names
                                if a.name not in PUBLIC.get(node.module or "", ())]
    assert not private


@pytest.mark.parametrize("old, name, new", [
    ("earthbench.referee", "apply_cut", "earthbench.cut"), ("earthbench.referee", "charge_cut", "earthbench.cut"),
    ("earthbench.referee", "cut_level", "earthbench.cut"), ("earthbench.referee", "footprint", "earthbench.cut"),
    ("earthbench.referee", "LOADER_DUMP_HALF_ANGLE", "earthbench.motion"),
    ("earthbench.referee.replay", "bodies_touch", "earthbench.rules"),
    ("earthbench.referee.replay", "off_map_excess", "earthbench.rules"),
    ("earthbench.referee.backhoe", "track_level_and_tilt", "earthbench.rules"),
    ("earthbench.referee.backhoe", "undermining_excess", "earthbench.rules"),
    ("earthbench.referee.loader", "wheel_step_excess", "earthbench.rules"),
])
def test_names_documented_in_0_1_still_import_with_a_warning(old, name, new):
    """Every name the 0.1.0 README told plugins to import from a place it has left."""
    with pytest.warns(DeprecationWarning, match=rf"{re.escape(old)}\.{name} moved to {re.escape(new)}\.{name}"):
        exec(f"from {old} import {name} as got", ns := {})
    assert ns["got"] is getattr(importlib.import_module(new), name)


@pytest.mark.parametrize("old, new, name", [("earthbench.runner", "earthbench.running.harness", "run_suite"),
                                            ("earthbench.dask_executor", "earthbench.running.harness.dask_executor", "DaskExecutor"),
                                            ("earthbench.replay", "earthbench.running.playback", "replay_data"),
                                            ("earthbench.referee.replay", "earthbench.referee.state", "Replay"),
                                            ("earthbench.publish", "earthbench.publishing.publish", "publish"),
                                            ("earthbench.compare", "earthbench.publishing.compare", "compare"),
                                            ("earthbench.harness", "earthbench.running.harness", "run_suite"),
                                            ("earthbench.playback", "earthbench.running.playback", "replay_data"),
                                            ("earthbench.scoring", "earthbench.results.scoring", "time_to_target"),
                                            ("earthbench.store", "earthbench.results.store", "Store"),
                                            ("earthbench.suite", "earthbench.results.suite", "load_suite")])
def test_moved_modules_still_import_with_a_warning(old, new, name):
    code = (f"import warnings; warnings.simplefilter('always')\nfrom {old} import {name} as got\n"
            f"import {new} as m\nassert got is m.{name}")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert f"the module {old} moved to {new}" in res.stderr and "DeprecationWarning" in res.stderr


def test_a_moved_package_brings_its_modules_as_the_same_objects():
    """An old package path's submodules are the new modules themselves, each loaded once (a copy
    under the old name would hold a second module state), with one warning, for the package."""
    code = ("import sys, warnings; warnings.simplefilter('always')\n"
            "import earthbench.board.tables as old\nfrom earthbench.board import page\n"
            "import earthbench.publishing.board.tables as new, earthbench.publishing.board.page as new_page\n"
            "assert old is new and page is new_page and sys.modules['earthbench.board.tables'] is new\n"
            "files = [m.__file__ for m in {id(m): m for m in sys.modules.values()}.values() if getattr(m, '__file__', None)]\n"
            "assert len(files) == len(set(files)), 'a module loaded twice'")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert res.stderr.count("DeprecationWarning") == 1 and "the module earthbench.board moved to earthbench.publishing.board" in res.stderr


def test_a_plugin_written_against_the_previous_readme_runs(tmp_path):
    """The tutorial planner of 0.1.0 imported the cut model from the referee: it still plans, with a warning."""
    from earthbench.cli.new_planner import write_package
    from earthbench.registry import PLANNERS, load_plugin_file
    from earthbench_terrains.rbf import rbf

    pkg = write_package("old-api-demo", tmp_path / "pkg")
    src = pkg / "earthbench_old_api_demo" / "planner.py"
    text = src.read_text()
    assert "from earthbench.cut import apply_cut, cut_level, footprint" in text
    src.write_text(text.replace("from earthbench.cut import", "from earthbench.referee import"))
    try:
        with pytest.warns(DeprecationWarning) as caught:
            load_plugin_file(src)
        assert {str(w.message).split(" moved")[0] for w in caught} == {
            f"earthbench.referee.{n}" for n in ("apply_cut", "cut_level", "footprint")}
        scenario = rbf(0, 0.56, n_bases=14)
        verdict = earthbench.judge(scenario, PLANNERS.get("old-api-demo")().plan(scenario))
        assert verdict.valid and verdict.loaded_volume > 0
    finally:
        PLANNERS.unregister("old-api-demo")


def test_scenario_from_json_reads_a_file_name_with_a_warning(tmp_path):
    from earthbench_terrains.rbf import rbf

    scenario = rbf(0, 0.56, n_bases=14)
    path = tmp_path / "site.json"
    path.write_text(scenario.to_json())
    with pytest.warns(DeprecationWarning, match=r"Scenario.load"):
        assert earthbench.Scenario.from_json(str(path)).digest == scenario.digest
    assert earthbench.Scenario.load(path).digest == scenario.digest
    assert earthbench.Scenario.from_json(path).digest == scenario.digest
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert earthbench.Scenario.from_json(scenario.to_json()).digest == scenario.digest
    with pytest.raises(earthbench.ScenarioError, match="not valid JSON"):  # stored documents never name files
        earthbench.Scenario.from_text(str(path))


def test_version_is_real_and_the_changelog_names_it(capsys):
    from earthbench.cli import main

    with pytest.raises(SystemExit):
        main(["--version"])
    assert capsys.readouterr().out.strip() == f"earthbench {earthbench.__version__}"
    assert earthbench.__version__ != "0.1.0"
    changelog = (ROOT / "CHANGELOG.md").read_text()
    assert f"## {earthbench.__version__}" in changelog
    section = changelog[changelog.index(f"## {earthbench.__version__}"):]
    assert section.split("\n## ")[0].count("**Moves published results:**") == 1
    assert json.loads(json.dumps(earthbench.__version__))


def test_the_package_face_exports_one_list():
    """``earthbench`` and ``earthbench.running.harness`` name their exports once, in their
    ``TYPE_CHECKING`` imports (:func:`earthbench.lazy.lazy_getattr`); ``__all__`` is that list."""
    import earthbench.running.harness

    assert set(earthbench.__all__) | {"__version__"} == set(PUBLIC["earthbench"])
    assert {"LocalExecutor", "run_suite"} <= set(earthbench.running.harness.__all__)
    for name in earthbench.running.harness.__all__:
        assert getattr(earthbench.running.harness, name) is not None
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        earthbench.nothing  # noqa: B018


def test_every_moved_name_imports_from_its_old_place_with_a_warning_naming_its_removal():
    """One table of moved names (earthbench.compat), each still importable from its old place: the
    same object, with a DeprecationWarning naming its new place and the release that removes it
    (unless the old module still uses the name itself), and on CHANGELOG.md's removal schedule."""
    from earthbench import compat

    schedule = (ROOT / "CHANGELOG.md").read_text().split("### Removal schedule", 1)[1].split("\n## ", 1)[0]
    for old, names in compat.MOVED_NAMES.items():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a module that moved whole warns on import (the test above)
            module = importlib.import_module(old)
        for name, (new, removed_in) in names.items():
            assert f"`{old}`" in schedule and removed_in in schedule, (old, removed_in)
            target = getattr(importlib.import_module(new), name)
            if name in vars(module):  # the old module still imports it for its own use
                assert vars(module)[name] is target
                continue
            with pytest.warns(DeprecationWarning, match=rf"{re.escape(old)}\.{name} moved to {re.escape(new)}\.{name}.*{removed_in}"):
                assert getattr(module, name) is target
    for old, (new, removed_in) in compat.MOVED_MODULES.items():
        assert f"`{old}`" in schedule and f"`{new}`" in schedule and removed_in in schedule


def test_no_module_but_the_compatibility_table_forwards_a_moved_name():
    """History stays out of the code: a module that lost names has one hook into earthbench.compat."""
    for path in sorted((ROOT / "earthbench").rglob("*.py")):
        text = path.read_text()
        if path.name != "compat.py":
            assert "DeprecationWarning, stacklevel" not in text or path.name == "world.py", path  # world: a deprecated argument
            assert "moved_getattr" not in text and "moved_module" not in text, path
