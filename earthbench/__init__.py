"""earthbench: a benchmark suite for earthmoving planners.

The data flows one way: suite → scenarios → planner → plan → referee → metrics → store →
leaderboard. This package holds the core; planners, terrains and metrics register as plugins
through entry points (docs/DESIGN.md §1–2); the core never imports them. At run time the face
imports two small modules: the lazy-export helper and the table of moved paths (earthbench.compat).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from . import compat
from .lazy import lazy_getattr

#: The public names, one list: type checkers read these imports as they are; at run time each
#: is imported on first use (:func:`earthbench.lazy.lazy_getattr`), so a case's process imports
#: only the world model, the plan format and what its planner uses, not the referee or the
#: registry's entry-point machinery (importlib.metadata, email, zipfile). Issue 18's start-up goal.
if TYPE_CHECKING:  # pragma: no cover
    from .errors import (
        EarthbenchError,
        PlanFormatError,
        PluginError,
        ScenarioError,
        StoreError,
        SuiteError,
        UnknownNameError,
    )
    from .plan import PLAN_SCHEMA, Charge, Dig, Dump, Move, Plan, Prediction
    from .planner import NoConfig, Observation, Planner
    from .referee import Verdict, Violation, judge
    from .registry import METRICS, PLANNERS, TERRAINS, load_plugin_file, register_planner
    from .sensing import observe
    from .world import Budget, ExcavatorSpec, Heightmap, LoaderSpec, Machines, Pose, Scenario, Sensing, Site, Soil, Task, TruckSpec

__version__ = "0.5.5"

__getattr__ = lazy_getattr(globals())
compat.install()  # the old paths of the modules that moved (earthbench.compat.MOVED_MODULES)
