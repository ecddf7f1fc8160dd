"""Built-in planner plugins, installed as ``earthbench_planners``, one sub-package per family
(docs/DESIGN.md §1). Each planner registers through the ``earthbench.planners`` entry points,
exactly as a third-party package's would."""
