"""The public API: every name a planner, metric, terrain generator or script may import.

One list, here and in docs/plugins.md ("The public API"); ``tests/test_api.py`` imports every
name, checks that the two lists agree and that the built-in plugins import nothing else from
earthbench. A name on this list keeps working for at least one release after it moves or is
renamed, with a :class:`DeprecationWarning` (the table of :mod:`earthbench.compat`), and
``CHANGELOG.md`` says so. Import each name from the module it is listed under.
"""

from __future__ import annotations

#: Module → its public names.
PUBLIC: dict[str, tuple[str, ...]] = {
    # the world, the plan, the planner's base class (also re-exported by ``earthbench``)
    "earthbench": (
        "Budget", "Charge", "Dig", "Dump", "EarthbenchError", "ExcavatorSpec", "Heightmap", "LoaderSpec", "METRICS",
        "Machines", "Move", "NoConfig", "Observation", "PLANNERS", "PLAN_SCHEMA", "Plan", "PlanFormatError", "Planner",
        "PluginError", "Pose", "Prediction", "Scenario", "ScenarioError", "Sensing", "Site", "Soil", "StoreError",
        "SuiteError", "TERRAINS", "Task", "TruckSpec", "UnknownNameError", "Verdict", "Violation", "judge",
        "load_plugin_file", "observe", "register_planner", "__version__",
    ),
    "earthbench.world": ("Budget", "ExcavatorSpec", "Heightmap", "LoaderSpec", "Machines", "Pose", "Scenario", "Sensing",
                         "Site", "Soil", "Task", "TruckSpec"),
    "earthbench.plan": ("PLAN_SCHEMA", "Charge", "Dig", "Dump", "Move", "Plan", "Prediction"),
    "earthbench.planner": ("NoConfig", "Observation", "Planner", "PrepareProgress", "SharedFolder", "closed_loop_setting"),
    "earthbench.errors": ("EarthbenchError", "PlanFormatError", "PluginError", "ScenarioError", "StoreError", "SuiteError",
                          "UnknownNameError"),
    "earthbench.registry": ("METRICS", "PLANNERS", "TERRAINS", "load_plugin_file", "register_planner"),
    # the referee's contract, for planners that call the rules instead of re-deriving them
    "earthbench.motion": ("ABS_TOL", "RATE_TOL", "LOADER_DUMP_HALF_ANGLE", "arcs", "dense_poses", "dump_reach_excess",
                          "loader_dump_excess", "min_dig_time", "min_dump_time", "poses_at", "swing_time",
                          "turn_drive_turn", "wrap"),
    "earthbench.cut": ("apply_cut", "charge_cut", "cut_along", "cut_level", "footprint", "path_cells", "path_window"),
    "earthbench.rules": ("STEP_FLOOR", "Spec", "arm_shadow", "bodies_touch", "body_reach", "bucket_corners", "cell_heights", "densify",
                         "ground_under", "loader_base_level", "off_map_excess", "overlap_area", "reach_of", "rectangles_touch",
                         "step_excess", "stroke_start", "track_level_and_tilt", "truck_cells", "truck_ground",
                         "undermining_excess", "wheel_step_excess"),
    # the judge, for metrics (a Verdict) and scripts; a planner calls the rules above, never the judge
    "earthbench.referee": ("Execution", "RULES", "RULES_VERSION", "Verdict", "Violation", "judge"),
    # the realistic track
    "earthbench.soil": ("MATERIALS", "Material", "draw", "fill_range", "nominal", "slump"),
    "earthbench.sensing": ("observe",),
    # machine classes (docs/machine-classes.md): a generator or script may fit a scenario to one
    "earthbench.classes": ("MachineClass", "fit", "machine_class", "machine_classes"),
    # metrics: a metric plugin is a callable (scenario, plan, verdict) -> dict; the scoring rule
    "earthbench.results.scoring": ("evaluate", "is_success", "run_order", "target_share", "time_per_target", "time_to_target"),
    # scripts and notebooks: run suites, read results
    "earthbench.results.suite": ("MAX_CELLS", "load_suite"),
    "earthbench.results.store": ("Store", "load_runs"),
    "earthbench.running.harness": ("LocalExecutor", "run_suite"),
    "earthbench.running.harness.dask_executor": ("DaskExecutor",),
}
