"""``earthbench new-planner NAME``: write a small installable planner package to start from.

The package registers its planner through the ``earthbench.planners`` entry point, exactly
as the built-ins do, so after ``pip install -e DIR`` it runs under
``earthbench run smoke --planner NAME``. The planner it contains is simple but valid: the
excavator stays put, the truck drives up, and the excavator digs the fullest stroke in reach
until the target is loaded. It comes with a test that checks the referee accepts its plan.
"""

from __future__ import annotations

import argparse
import keyword
import re
import shlex
from pathlib import Path

from ..errors import EarthbenchError
from ._common import plain

NAME_RE = re.compile(r"^[a-z][a-z0-9]*(?:[-_][a-z0-9]+)*$")


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("new-planner", help="write a planner plugin package to start from", description=plain(__doc__),
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("name", help="planner name: lower case letters, digits, '-' or '_' (e.g. my-planner)")
    p.add_argument("--dir", metavar="PATH", help="where to write the package (default: ./earthbench-NAME)")
    p.add_argument("--force", action="store_true", help="overwrite the files if the directory exists")
    return p


def names(name: str) -> tuple[str, str, str]:
    """(distribution, module, class) names for a planner name."""
    if not NAME_RE.fullmatch(name):
        raise EarthbenchError(
            f"planner name {name!r} must be lower case letters and digits, words joined by '-' or '_' (e.g. 'my-planner')"
        )
    module = "earthbench_" + name.replace("-", "_")
    words = re.split(r"[-_]", name)
    cls = "".join(w.capitalize() for w in words) + ("" if words[-1] == "planner" and len(words) > 1 else "Planner")
    if keyword.iskeyword(module):
        raise EarthbenchError(f"{name!r} gives a module name that is a Python keyword; choose another")
    return f"earthbench-{name}", module, cls


def write_package(name: str, directory: str | Path | None = None, *, force: bool = False) -> Path:
    """Write the package; returns its directory."""
    dist, module, cls = names(name)
    root = Path(directory or dist)
    if root.exists() and not root.is_dir():
        raise EarthbenchError(f"--dir {str(root)!r} is a file, not a folder; choose a new or empty folder")
    if root.exists() and any(root.iterdir()) and not force:
        raise EarthbenchError(f"{str(root)!r} already exists and is not empty; choose --dir or pass --force")
    files = {
        "pyproject.toml": PYPROJECT,
        "README.md": README,
        f"{module}/__init__.py": INIT,
        f"{module}/planner.py": PLANNER,
        "tests/test_planner.py": TEST,
    }
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text.format(name=name, dist=dist, module=module, cls=cls).lstrip())
    return root


def run(args: argparse.Namespace) -> int:
    root = write_package(args.name, args.dir, force=args.force)
    dist, module, cls = names(args.name)
    print(f"wrote {root}/ ({dist}: planner {args.name!r}, class {module}.planner.{cls})")
    print("next:")
    # each runnable as printed (a folder with a space in its name quoted)
    print(f"  pip install -e {shlex.quote(str(root))}")
    print(f"  pip install pytest && python -m pytest {shlex.quote(f'{root}/tests')}")
    print(f"  earthbench run smoke --planner {shlex.quote(args.name)}")
    return 0


PYPROJECT = '''
[build-system]
requires = ["setuptools>=68"]
build-backend = "setuptools.build_meta"

[project]
name = "{dist}"
version = "0.1.0"
description = "The {name} planner for earthbench."
requires-python = ">=3.11"
dependencies = ["earthbench", "numpy", "shapely"]

# This is how earthbench finds the planner: `earthbench list planners` shows it after install.
[project.entry-points."earthbench.planners"]
{name} = "{module}.planner:{cls}"

[tool.setuptools]
packages = ["{module}"]

# The package's own test settings: run from a folder whose pyproject.toml has others (the
# earthbench clone's asks for pytest-benchmark), pytest still uses these.
[tool.pytest.ini_options]
testpaths = ["tests"]
'''

README = '''
# {dist}

The `{name}` planner for earthbench, started with
`earthbench new-planner {name}`.

```sh
pip install -e .                               # registers the planner (entry point earthbench.planners)
pip install pytest && python -m pytest tests  # the referee accepts its plans
earthbench run smoke --planner {name}          # run it on the smoke suite; results go to earthbench.db
earthbench runs --planner {name}               # what was stored
```

Edit `{module}/planner.py`: keep the class attributes (`name`, `version`, `tracks`,
`Config`) and return an `earthbench.Plan` from `plan(scenario)`. Bump `version` whenever
the planner's results may change, so earthbench runs it again instead of reusing old results.
'''

INIT = '''
"""The {name} planner for earthbench."""

from .planner import {cls}

__all__ = ["{cls}"]
'''

PLANNER = '''
"""``{name}``: an earthbench planner plugin (written by ``earthbench new-planner``).

A working starting point, not a good planner: the excavator never moves. The truck drives
straight toward the excavator and stops ``truck_distance`` away, within dump reach; then the
excavator repeatedly digs the stroke in reach that fills the bucket most (dragging toward
itself, as deep as allowed and never below the floor), swings to the truck and dumps, until
the target volume is loaded or nothing worth a dig is left in reach.

It predicts volumes with the referee's own cut model (``earthbench.cut.apply_cut``), so
its claims match what the referee measures. Replace ``plan`` with your method.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from shapely.geometry import Polygon

from earthbench import Dig, Dump, Move, Plan, Planner, Prediction, Scenario
from earthbench.motion import min_dig_time, min_dump_time, turn_drive_turn
from earthbench.cut import apply_cut, cut_level, footprint

EPS_T = 1e-6  # seconds added to minimum durations so that rounding never makes them short


@dataclass(frozen=True)
class {cls}Config:
    truck_distance: float = 4.6
    """Centre distance (m) from the excavator to the truck while loading."""
    grid_step: float = 0.3
    """Spacing (m) of candidate contact points."""
    min_volume: float = 0.02
    """Stop when the best dig would remove less than this (m³)."""


class {cls}(Planner):
    """Stand still and dig the fullest stroke in reach (a template to start from)."""

    name = "{name}"
    version = "0.1.0"
    tracks = ("backhoe",)
    Config = {cls}Config

    def plan(self, scenario: Scenario) -> Plan:
        cfg = self.config
        m = scenario.machines
        exc, base = m.excavator, m.excavator_pose
        actions: list = []

        # 1. The truck drives straight toward the excavator and stops within dump reach.
        dx, dy = m.truck_pose.x - base.x, m.truck_pose.y - base.y
        d = math.hypot(dx, dy) or 1.0
        goal = (base.x + dx / d * cfg.truck_distance, base.y + dy / d * cfg.truck_distance)
        path = turn_drive_turn(m.truck_pose, goal, 0.0, m.truck.travel_speed, m.truck.yaw_rate)
        if len(path) > 1:
            actions.append(Move("truck", tuple(path)))
        t = path[-1][0]

        # 2. Candidate strokes: contacts in the dig area whose drag toward the base stays in reach.
        area = Polygon(scenario.site.dig_area)
        xmin, ymin, xmax, ymax = area.bounds
        strokes = []
        for x in np.arange(xmin, xmax, cfg.grid_step):
            for y in np.arange(ymin, ymax, cfg.grid_step):
                r = math.hypot(x - base.x, y - base.y)
                if r > exc.reach_max or r - exc.max_drag_length < exc.reach_min:
                    continue
                heading = math.atan2(base.y - y, base.x - x)
                if area.contains(footprint((x, y), heading, exc.bucket_width, exc.max_drag_length)):
                    strokes.append(((float(x), float(y)), heading))

        # 3. Dig the fullest stroke, dump, repeat.
        terrain, z = scenario.terrain, scenario.terrain.z.copy()
        floor = scenario.site.floor
        turn, loaded = 0.0, 0.0
        while loaded < scenario.task.target_volume - 1e-9:
            best = None
            for contact, heading in strokes:
                depth = exc.max_cut_depth
                if floor is not None:
                    depth = min(depth, terrain.height_at(*contact, z) - floor)
                if depth <= 1e-3:
                    continue
                level = cut_level(terrain, z, contact, depth)
                vol = apply_cut(terrain, z.copy(), contact, heading, exc.bucket_width, exc.max_drag_length, level, exc.bucket_capacity)
                if best is None or vol > best[0]:
                    best = (vol, contact, heading, depth, level)
            if best is None or best[0] < cfg.min_volume:
                break
            vol, contact, heading, depth, level = best
            apply_cut(terrain, z, contact, heading, exc.bucket_width, exc.max_drag_length, level, exc.bucket_capacity)
            dig_time = min_dig_time(base, turn, contact, exc) + EPS_T
            actions.append(Dig("excavator", t, t + dig_time, contact, heading, depth, exc.max_drag_length))
            t += dig_time
            turn = math.atan2(contact[1] - base.y, contact[0] - base.x) - base.yaw
            dump_time = min_dump_time(base, turn, goal, exc) + EPS_T
            actions.append(Dump("excavator", t, t + dump_time))
            t += dump_time
            turn = math.atan2(goal[1] - base.y, goal[0] - base.x) - base.yaw
            loaded += vol
        return Plan(tuple(actions), Prediction(volume=loaded, makespan=t))
'''

TEST = '''
"""The referee accepts the planner's plans (run with `pytest tests`)."""

from earthbench import judge
from earthbench.registry import TERRAINS

from {module}.planner import {cls}


def test_plan_is_valid_and_loads_material():
    scenario = TERRAINS.get("rbf")(0, 0.56)
    plan = {cls}().plan(scenario)
    verdict = judge(scenario, plan)
    assert verdict.valid, verdict.summary()
    assert verdict.loaded_volume > 0
    assert abs(plan.predicted.volume - verdict.loaded_volume) < 1e-6
'''
