"""Every name that moved, in one table: the old import paths that still work, each with a
:class:`DeprecationWarning` that names its new place and the release that removes it.

Users' code keeps working for at least one release after a documented name moves (docs/plugins.md,
"The public API"); the history lives here and in CHANGELOG.md ("Removal schedule"), not in the
modules the names left. A module that lost names keeps one line, ``__getattr__ =
compat.forward(__name__)``; a module that moved whole is that line and its docstring.
"""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable
from typing import Any

#: Old module → (new module, the release that removes the old one) for modules that moved whole.
MOVED_MODULES: dict[str, tuple[str, str]] = {
    "earthbench.replay": ("earthbench.playback", "0.6.0"),  # moved after 0.2.0
    "earthbench.runner": ("earthbench.harness", "0.6.0"),  # moved in 0.2.0
    "earthbench.dask_executor": ("earthbench.harness.dask_executor", "0.6.0"),  # moved in 0.2.0
    "earthbench.referee.replay": ("earthbench.referee.state", "0.6.0"),  # moved after 0.2.0
}


def _names(names: str, to: str, removed_in: str) -> dict[str, tuple[str, str]]:
    return dict.fromkeys(names.split(), (to, removed_in))


_RULES_FROM_REPLAY = _names("bodies_touch off_map_excess reach_of rectangles_touch", "earthbench.rules", "0.6.0")
_BOARD_TABLES = ("FAILURE_COLUMNS FORMULA_STARTS PROVENANCE UNSEPARABLE Stamp builds_of load_text mark_mixed_solve_columns "
                 "mark_unseparable markdown_more_tables markdown_page markdown_table md_escape section_tables slug "
                 "spreadsheet_safe stamp table_rows table_sections write_csv")
_BOARD_PAGE = "FILTERS RUN_COLUMNS filter_bar fold_zero_failures html_more_tables html_page html_table replay_links replay_runs run_rows"
_BOARD_FIGURES = ("FIGURE_COLUMNS RUN_FIGURES Renderer families_figure figure_jobs history_figure profiles_figure terrain_figure "
                  "volume_time_figure")
_BOARD_SELECTION = ("closed_configs histories limit_to_seeds load_runs_empty published_runs sample_runs seed_list shown_runs "
                    "solver_labels")

#: Old module → {name: (new module, the release that removes the old name)}.
MOVED_NAMES: dict[str, dict[str, tuple[str, str]]] = {
    # the cut model and the motion constants were documented in the referee until 0.1.0 (moved in 0.2.0)
    "earthbench.referee": _names("apply_cut charge_cut cut_level footprint", "earthbench.cut", "0.6.0")
    | _names("LOADER_DUMP_HALF_ANGLE", "earthbench.motion", "0.6.0"),
    # the rules' predicates, public in earthbench.rules since 0.2.0
    "earthbench.referee.backhoe": _names("ground_under track_level_and_tilt undermining_excess", "earthbench.rules", "0.6.0"),
    "earthbench.referee.loader": _names("STEP_FLOOR cell_heights densify loader_base_level step_excess wheel_step_excess",
                                        "earthbench.rules", "0.6.0"),
    "earthbench.referee.replay": _RULES_FROM_REPLAY,
    # a machine's samples over time belong to the motion model (issue 52)
    "earthbench.referee.state": _names("Timeline", "earthbench.motion", "0.6.0"),
    # the seal no longer imports the suite: drawing a sealed suite moved there after 0.2.0
    "earthbench.seal": _names("new_key open_sealed", "earthbench.suite", "0.6.0"),
    # publishing was split by job into earthbench.board in 0.3.0
    "earthbench.publish": _names(_BOARD_TABLES, "earthbench.board.tables", "0.6.0")
    | _names(_BOARD_PAGE, "earthbench.board.page", "0.6.0") | _names(_BOARD_FIGURES, "earthbench.board.figures", "0.6.0")
    | _names(_BOARD_SELECTION, "earthbench.board.selection", "0.6.0") | _names("REASONS", "earthbench.aggregate", "0.6.0"),
    # what publishing and verify share moved beside the other labels (issue 52)
    "earthbench.verify": _names("latest_spot_checks machine_label", "earthbench.labels", "0.6.0"),
    # running a case (measure, then judge) left the sandbox, which only measures (issue 52)
    "earthbench.harness.sandbox": _names("run_case", "earthbench.harness.run", "0.6.0"),
}


def forward(module: str) -> Callable[[str], Any]:
    """The module ``__getattr__`` of ``module``: a moved name (:data:`MOVED_NAMES`) warns and comes
    from its new place; in a module that moved whole (:data:`MOVED_MODULES`), which warns once on
    import, every other name comes from its new module; anything else raises ``AttributeError``."""
    names = MOVED_NAMES.get(module, {})
    whole = MOVED_MODULES.get(module)
    if whole is not None:
        warnings.warn(f"the module {module} moved to {whole[0]}; import from there (the old name goes in {whole[1]})",
                      DeprecationWarning, stacklevel=3)

    def __getattr__(name: str) -> Any:
        if name in names:
            target, removed_in = names[name]
            warnings.warn(f"{module}.{name} moved to {target}.{name}; import it from there (the old name goes in {removed_in})",
                          DeprecationWarning, stacklevel=2)
            return getattr(importlib.import_module(target), name)
        if whole is not None:
            try:
                return getattr(importlib.import_module(whole[0]), name)
            except AttributeError:
                raise AttributeError(f"module {module!r} (now {whole[0]!r}) has no attribute {name!r}") from None
        raise AttributeError(f"module {module!r} has no attribute {name!r}")

    return __getattr__
