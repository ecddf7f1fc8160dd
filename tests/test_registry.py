"""Registries: entry points, the decorator, plugin files, helpful errors for unknown names."""

from __future__ import annotations

from importlib.metadata import EntryPoint

import pytest

import earthbench.registry as registry
from earthbench import PLANNERS, TERRAINS, Plan, Planner, PluginError, UnknownNameError, load_plugin_file, register_planner


def test_builtins_register_through_entry_points():
    assert "greedy" in PLANNERS.names()
    assert "rbf" in TERRAINS.names()
    assert "entry point" in PLANNERS.origin("greedy")


def test_unknown_names_list_the_known_ones_and_close_matches():
    with pytest.raises(UnknownNameError) as err:
        PLANNERS.get("gredy")
    msg = str(err.value)
    assert "Did you mean 'greedy'" in msg and "Known planners:" in msg
    with pytest.raises(UnknownNameError, match="unknown terrain generator 'rbv'.*'rbf'"):
        TERRAINS.get("rbv")


def test_a_broken_plugin_is_reported_and_does_not_hide_the_others(monkeypatch):
    eps = [
        EntryPoint("broken", "earthbench_no_such_module:Planner", "earthbench.planners"),
        EntryPoint("notaplanner", "math:pi", "earthbench.planners"),
        EntryPoint("greedy", "earthbench_planners.greedy.backhoe:GreedyPlanner", "earthbench.planners"),
    ]
    monkeypatch.setattr(registry, "entry_points", lambda group: eps)
    monkeypatch.setattr(registry, "distribution_of", lambda ep: "earthbench")  # as if earthbench's own
    reg = registry.Registry("earthbench.planners", "planner", registry._check_planner)
    assert reg.names() == ["greedy"]
    assert "ModuleNotFoundError" in reg.failures["broken"]
    assert "not a subclass" in reg.failures["notaplanner"]
    with pytest.raises(PluginError, match="failed to load"):
        reg.get("broken")


def test_another_distributions_entry_points_are_never_imported_here(monkeypatch):
    """Its planners are probed in a fence (earthbench.running.harness.probe); its terrains and metrics are
    loaded only when $EARTHBENCH_TRUST names it (docs/DESIGN.md §6 "Plugin code")."""
    eps = [EntryPoint("theirs", "earthbench_no_such_module:Thing", "earthbench.metrics")]
    monkeypatch.setattr(registry, "entry_points", lambda group: eps)
    monkeypatch.setattr(registry, "distribution_of", lambda ep: "their-package")
    monkeypatch.delenv(registry.TRUST_ENV, raising=False)
    reg = registry.Registry("earthbench.metrics", "metric", registry._check_callable, trust=True)
    assert reg.names() == [] and reg.failures == {} and list(reg.foreign) == ["theirs"]
    with pytest.raises(PluginError, match="EARTHBENCH_TRUST=their-package"):
        reg.get("theirs")
    monkeypatch.setenv(registry.TRUST_ENV, "Their_Package")  # trusted: imported (and here it fails to import)
    reg = registry.Registry("earthbench.metrics", "metric", registry._check_callable, trust=True)
    assert reg.names() == [] and "ModuleNotFoundError" in reg.failures["theirs"]
    planners = registry.Registry("earthbench.planners", "planner", registry._check_planner)
    assert planners.names() == [] and list(planners.foreign) == ["theirs"]  # planners: never, trusted or not


@pytest.fixture
def forget():
    """Names to unregister after the test, so no test planner leaks into suite runs."""
    names: list[str] = []
    yield names
    for n in names:
        PLANNERS.unregister(n)


def test_register_planner_decorator(forget):
    forget.append("test-idle")

    @register_planner
    class Idle(Planner):
        """Does nothing."""

        name = "test-idle"

        def plan(self, scenario):
            return Plan()

    assert PLANNERS.get("test-idle") is Idle
    PLANNERS.unregister("test-idle")
    assert "test-idle" not in PLANNERS
    with pytest.raises(PluginError, match="not a subclass"):
        registry.PLANNERS.register("x", object)


PLUGIN = '''
from earthbench import Planner, Plan

class FilePlanner(Planner):
    """A planner that lives in one file."""
    name = "test-file-planner"
    version = "0.1"

    def plan(self, scenario):
        return Plan()
'''


def test_load_one_plugin_file(tmp_path, forget):
    forget.append("test-file-planner")
    path = tmp_path / "myplanner.py"
    path.write_text(PLUGIN)
    assert load_plugin_file(path) == ["test-file-planner"]
    assert PLANNERS.get("test-file-planner").version == "0.1"


@pytest.mark.parametrize(
    "text, words",
    [("def broken(:\n", "failed to import"), ("x = 1\n", "defines no Planner")],
)
def test_bad_plugin_files_get_clear_errors(tmp_path, text, words):
    path = tmp_path / "bad.py"
    path.write_text(text)
    with pytest.raises(PluginError, match=words):
        load_plugin_file(path)
    with pytest.raises(PluginError, match="not found"):
        load_plugin_file(tmp_path / "missing.py")


def test_the_harness_and_a_case_process_import_a_plugin_file_under_one_name(tmp_path, forget):
    """``--plugin FILE.py`` is imported in the harness (:func:`load_plugin_file`) and again in each
    case's process (:func:`earthbench.running.harness.child.load_planner_class`): one module name both
    times, the same in another process, and two files of one name in two folders never share it."""
    import subprocess
    import sys

    from earthbench.running.harness.child import load_planner_class

    body = ("from earthbench import Plan, Planner\n\n"
            "class Same(Planner):\n    name = 'same-name-{n}'\n    def plan(self, scenario):\n        return Plan(actions=())\n")
    files = []
    for n in (1, 2):
        (tmp_path / f"d{n}").mkdir()
        files.append(tmp_path / f"d{n}" / "mine.py")
        files[-1].write_text(body.format(n=n))
    names = [registry.plugin_module_name(f) for f in files]
    assert names[0] != names[1] and all(n.startswith("earthbench_plugin_mine_") for n in names)
    forget.append("same-name-1")
    assert load_plugin_file(files[0]) == ["same-name-1"]
    assert PLANNERS.get("same-name-1").__module__ == names[0]
    assert load_planner_class(str(files[0]), "same-name-1").__module__ == names[0]
    again = subprocess.run([sys.executable, "-c", "import sys; from earthbench.registry import plugin_module_name; "
                            "print(plugin_module_name(sys.argv[1]))", str(files[0])], capture_output=True, text=True, check=True)
    assert again.stdout.strip() == names[0]  # str hashes differ between processes; this name does not
