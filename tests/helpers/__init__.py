"""Helpers the tests share: a small hand-made site where every referee rule is easy to reach, a
tiny suite for harness tests, and a loader for the figure scripts in ``scripts/``.

Tests import these by name (``from helpers import block_scenario``); ``conftest.py`` keeps only
fixtures. ``helpers.leaderboard`` builds stores of real runs for the publishing tests.
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path
from types import ModuleType

import numpy as np

from earthbench import Budget, Dig, Dump, Heightmap, Machines, Move, Pose, Scenario, Site, Task
from earthbench.world import ExcavatorSpec

SCRIPTS = Path(__file__).resolve().parents[2] / "scripts"


def block_scenario(height: float = 1.0, floor: float | None = 0.0, keep_outs=(), target: float = 0.56, **spec) -> Scenario:
    """An 8 m × 6 m slab of ``height`` at 0.05 m cells; the excavator north of it, the truck east.

    Excavator at (4, 9) facing south; a dig at (4, 5) dragging north is 4 m from the base.
    Truck at (9, 9): 5 m from the excavator, inside dump reach and outside the clearance.
    """
    z = np.full((120, 160), height)
    return Scenario(
        id="test/block",
        terrain=Heightmap((0.0, 0.0), 0.05, z),
        site=Site(((0, 0), (8, 0), (8, 6), (0, 6)), floor=floor, keep_outs=tuple(keep_outs)),
        machines=Machines(excavator=ExcavatorSpec(**spec), excavator_pose=Pose(4.0, 9.0, -math.pi / 2), truck_pose=Pose(9.0, 9.0, math.pi)),
        task=Task(target),
        budget=Budget(wall_s=60),
    )


def swing(base: Pose, turn: float, target: tuple[float, float], rate: float = 1.1) -> float:
    bearing = math.atan2(target[1] - base.y, target[0] - base.x)
    d = (bearing - base.yaw - turn + math.pi) % (2 * math.pi) - math.pi
    return abs(d) / rate


def dig_dump_plan(contact=(4.0, 5.0), depth=0.4, drag=1.0, t0=0.0, extra=0.0, heading=None) -> list:
    """A valid dig at ``contact`` (dragging toward the base by default) and a dump into the truck."""
    base = Pose(4.0, 9.0, -math.pi / 2)
    if heading is None:
        heading = math.atan2(base.y - contact[1], base.x - contact[0])
    d_dig = swing(base, 0.0, contact) + 3.0 + 1e-6 + extra
    turn = math.atan2(contact[1] - base.y, contact[0] - base.x) - base.yaw
    d_dump = swing(base, turn, (9.0, 9.0)) + 2.0 + 1e-6 + extra
    return [
        Dig("excavator", t0, t0 + d_dig, contact, heading, depth, drag),
        Dump("excavator", t0 + d_dig, t0 + d_dig + d_dump),
    ]


def straight_move(machine: str, start: Pose, goal: tuple[float, float], t0: float, speed: float) -> Move:
    """Drive straight (the machine already faces the goal or its reverse) at ``speed``."""
    d = math.hypot(goal[0] - start.x, goal[1] - start.y)
    return Move(machine, ((t0, start.x, start.y, start.yaw), (t0 + d / speed, goal[0], goal[1], start.yaw)))


def tiny_suite_toml(name: str = "tiny", *, wall_s: float = 20.0, memory_mb: int = 1024, seeds: str = "0-0",
                    target: float = 0.28, size: tuple[float, float] = (4.0, 3.0), n_bases: int = 3,
                    budget: str = "", config: str = "") -> str:
    """A suite of tiny rbf maps (4 m × 3 m, 3 bases, 0.1 m cells, a one-bucket target) for harness
    tests: every planner solves one in well under a second, so a test times the harness, not it.

    ``budget`` adds lines to ``[budget]`` (e.g. the closed-loop ``step_s``), ``config`` appends
    ``[config.PLANNER]`` tables; a larger ``size`` and ``target`` give a plan of a few dig cycles.
    """
    return f"""
name = "{name}"
track = "backhoe"
[budget]
wall_s = {wall_s}
cores = 2
memory_mb = {memory_mb}
{budget}
[[family]]
name = "small"
generator = "rbf"
targets = [{target}]
seeds = "{seeds}"
[family.params]
n_bases = {n_bases}
size = [{size[0]}, {size[1]}]
resolution = 0.1
{config}
"""


def load_script(name: str) -> ModuleType:
    """The figure script ``scripts/NAME.py`` as a module (``scripts/`` is not an installed package)."""
    spec = importlib.util.spec_from_file_location(f"scripts_{name}", SCRIPTS / f"{name}.py")
    assert spec is not None and spec.loader is not None, f"no script {name}"
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # before running it: a script's dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def case_processes() -> list[int]:
    """Live processes of this process's cases, found by the tag every case process carries
    (inside a sandbox too: its processes are ours to see, not the other way round)."""
    import psutil

    from earthbench.running.harness.sandbox import CASE_TAG, TAG_PREFIX

    mine = TAG_PREFIX
    out = []
    for p in psutil.process_iter():
        try:
            if p.environ().get(CASE_TAG, "").startswith(mine) and p.status() != psutil.STATUS_ZOMBIE:
                out.append(p.pid)
        except psutil.Error:
            continue
    return out


def published_sealed_scenario(key_file: str, part: str) -> Scenario:
    """The scenario whose id ends with ``part`` in the sealed draw of a key published under
    ``leaderboard/`` (``key_file`` relative to it): a board's own case, regenerated from its key."""
    from earthbench.results.suite import load_suite, open_sealed
    from earthbench.seal import SealKey

    key = SealKey.read(Path(__file__).resolve().parents[2] / "leaderboard" / key_file)
    return next(sc for sc in open_sealed(load_suite(key.suite), key).scenarios if sc.id.endswith(part))
