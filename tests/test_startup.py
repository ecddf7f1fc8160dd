"""Case start-up stays cheap: importing a built-in planner loads no heavy library it does not
need before its first solve (scipy, cvxpy, matplotlib, pandas, Dask; CasADi only for the
STL-TAMP planners, whose every plan builds a CasADi problem)."""

from __future__ import annotations

import json
import subprocess
import sys
from importlib.metadata import entry_points

import pytest

HEAVY = ("scipy", "cvxpy", "matplotlib", "pandas", "distributed", "dask", "casadi")
NEEDS = {"stl-tamp": {"casadi"}, "separate": {"casadi"}}
BUILT_IN = sorted((e.name, e.value) for e in entry_points(group="earthbench.planners") if e.value.startswith("earthbench_planners."))


def test_every_built_in_planner_is_checked():
    assert {"greedy", "singh-cannon-backhoe", "stl-tamp", "separate", "singh-cannon-loader", "greedy-loader"} <= {n for n, _ in BUILT_IN}


@pytest.mark.parametrize(("name", "target"), BUILT_IN)
def test_importing_a_planner_loads_no_heavy_library(name, target):
    module, _, attr = target.partition(":")
    code = (f"import importlib, json, sys; getattr(importlib.import_module({module!r}), {attr!r})(); "
            f"print(json.dumps(sorted({{m.split('.')[0] for m in sys.modules}} & set({list(HEAVY)!r}))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert set(json.loads(out.stdout)) <= NEEDS.get(name, set()), out.stdout
