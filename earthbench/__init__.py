"""earthbench: a benchmark suite for earthmoving planners.

The data flows one way: suite → scenarios → planner → plan → referee → metrics → store →
leaderboard. This package holds the core; planners, terrains and metrics register as plugins
through entry points (docs/DESIGN.md §1–2); the core never imports them.
"""

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
from .world import (
    Budget,
    ExcavatorSpec,
    Heightmap,
    LoaderSpec,
    Machines,
    Pose,
    Scenario,
    Sensing,
    Site,
    Soil,
    Task,
    TruckSpec,
)

__version__ = "0.1.0"

__all__ = [
    "Budget", "Charge", "Dig", "Dump", "EarthbenchError", "ExcavatorSpec", "Heightmap", "LoaderSpec", "METRICS", "Machines",
    "Move", "NoConfig", "Observation", "PLANNERS", "PLAN_SCHEMA", "Plan", "PlanFormatError", "Planner", "PluginError",
    "Pose", "Prediction", "Scenario", "ScenarioError", "Sensing", "Site", "Soil", "StoreError", "SuiteError",
    "TERRAINS", "Task", "TruckSpec", "UnknownNameError", "Verdict", "Violation", "judge", "load_plugin_file",
    "observe", "register_planner",
]
