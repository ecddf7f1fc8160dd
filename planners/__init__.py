"""Built-in planner plugins. Each registers through the ``earthbench.planners`` entry points."""
