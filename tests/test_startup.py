"""Case start-up stays cheap: importing a built-in planner loads no heavy library it does not
need before its first solve (scipy, cvxpy, matplotlib, pandas, Dask, CasADi: the STL-TAMP
planners load CasADi with their first NLP, not at import)."""

from __future__ import annotations

import json
import subprocess
import sys
from importlib.metadata import entry_points

import pytest

HEAVY = ("scipy", "cvxpy", "matplotlib", "pandas", "distributed", "dask", "casadi")
BUILT_IN = sorted((e.name, e.value) for e in entry_points(group="earthbench.planners") if e.value.startswith("earthbench_planners."))


def test_every_built_in_planner_is_checked():
    assert {"greedy", "singh-cannon-backhoe", "stl-tamp", "separate", "singh-cannon-loader", "greedy-loader"} <= {n for n, _ in BUILT_IN}


@pytest.mark.parametrize(("name", "target"), BUILT_IN)
def test_importing_a_planner_loads_no_heavy_library(name, target):
    module, _, attr = target.partition(":")
    code = (f"import importlib, json, sys; getattr(importlib.import_module({module!r}), {attr!r})(); "
            f"print(json.dumps(sorted({{m.split('.')[0] for m in sys.modules}} & set({list(HEAVY)!r}))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert json.loads(out.stdout) == [], out.stdout


@pytest.mark.parametrize(("name", "target"), BUILT_IN)
def test_a_case_process_loads_its_planner_without_the_registry_or_the_other_track(name, target):
    """The case bootstrap imports the planner's module only: not the entry-point machinery
    (importlib.metadata, ~0.1 s) and, for a backhoe planner, not the loader's rules (and back)."""
    code = ("import json, sys; from earthbench.running.harness.child import load_planner_class; "
            f"load_planner_class({target!r}, {name!r})(); print(json.dumps(sorted(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    loaded = set(json.loads(out.stdout))
    assert not loaded & {"importlib.metadata", "earthbench.registry", "earthbench.results.store", "earthbench.running.harness.sandbox"}
    other = "earthbench.referee.loader" if "loader" not in name else "earthbench.referee.backhoe"
    assert other not in loaded


def test_importing_earthbench_loads_nothing_but_its_namespace():
    code = "import json, sys, earthbench; print(json.dumps(sorted(m for m in sys.modules if m.startswith(('earthbench', 'numpy')))))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    # the lazy-export helper and the table of moved paths (its import finder), nothing else
    assert json.loads(out.stdout) == ["earthbench", "earthbench.compat", "earthbench.lazy"]
