"""Every name that moved, in one table: the old import paths that still work, each with a
:class:`DeprecationWarning` that names its new place and the release that removes it.

Users' code keeps working for at least one release after a documented name moves (docs/plugins.md,
"The public API"); the history lives here and in CHANGELOG.md ("Removal schedule"), not in the
modules the names left. A module that lost names keeps one line, ``__getattr__ =
compat.forward(__name__)``; a module or package that moved whole leaves no file behind: its old
path is an alias of the new module (:func:`install`, called by the package's face), so the folders
show only where the code is (docs/DESIGN.md §2).
"""

from __future__ import annotations

import importlib
import sys
import warnings
from collections.abc import Callable, Sequence
from importlib.machinery import ModuleSpec
from types import ModuleType
from typing import TYPE_CHECKING, Any, cast

if TYPE_CHECKING:  # pragma: no cover
    from importlib.abc import Loader  # not at run time: it imports importlib.resources


def _into(layer: str, modules: str, removed_in: str) -> dict[str, tuple[str, str]]:
    """``earthbench.<module>`` → ``earthbench.<layer>.<module>``: modules moved into their layer's folder."""
    return {f"earthbench.{name}": (f"earthbench.{layer}.{name}", removed_in) for name in modules.split()}


#: Old module → (new module, the release that removes the old one) for modules that moved whole;
#: a package's old path carries its submodules with it (``earthbench.board.tables`` and so on).
MOVED_MODULES: dict[str, tuple[str, str]] = {
    "earthbench.replay": ("earthbench.running.playback", "0.6.0"),  # moved after 0.2.0
    "earthbench.runner": ("earthbench.running.harness", "0.6.0"),  # moved in 0.2.0
    "earthbench.dask_executor": ("earthbench.running.harness.dask_executor", "0.6.0"),  # moved in 0.2.0
    "earthbench.referee.replay": ("earthbench.referee.state", "0.6.0"),  # moved after 0.2.0
    # the folders show the layers (issue 52, docs/DESIGN.md §2)
    **_into("results", "scoring records progress labels aggregate generalisation store suite suite_checks identity calibration "
                       "provenance", "0.6.0"),
    **_into("running", "harness playback figures scaling", "0.6.0"),
    **_into("publishing", "verify merge best board publish compare", "0.6.0"),
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
    "earthbench.seal": _names("new_key open_sealed", "earthbench.results.suite", "0.6.0"),
    # publishing was split by job into earthbench.board in 0.3.0
    "earthbench.publish": _names(_BOARD_TABLES, "earthbench.publishing.board.tables", "0.6.0")
    | _names(_BOARD_PAGE, "earthbench.publishing.board.page", "0.6.0")
    | _names(_BOARD_FIGURES, "earthbench.publishing.board.figures", "0.6.0")
    | _names(_BOARD_SELECTION, "earthbench.publishing.board.selection", "0.6.0")
    | _names("REASONS", "earthbench.results.aggregate", "0.6.0"),
    # what publishing and verify share moved beside the other labels (issue 52)
    "earthbench.verify": _names("latest_spot_checks machine_label", "earthbench.results.labels", "0.6.0"),
    # running a case (measure, then judge) left the sandbox, which only measures (issue 52)
    "earthbench.harness.sandbox": _names("run_case", "earthbench.running.harness.run", "0.6.0"),
}


def new_path(old: str) -> tuple[str, str] | None:
    """(new module, the release that removes the old path) for an old module path, a submodule of a
    moved package included; None for a path that did not move."""
    for moved, (new, removed_in) in MOVED_MODULES.items():
        if old == moved or old.startswith(moved + "."):
            return new + old[len(moved):], removed_in
    return None


def _old_names(module: str) -> dict[str, tuple[str, str, str]]:
    """name → (the old module it was documented in, its new module, the release that removes it) for
    the names that moved out of ``module`` or out of an old path that is now ``module``."""
    out: dict[str, tuple[str, str, str]] = {}
    for old, names in MOVED_NAMES.items():
        if old == module or (new_path(old) or ("",))[0] == module:
            out |= {name: (old, target, removed_in) for name, (target, removed_in) in names.items()}
    return out


def forward(module: str) -> Callable[[str], Any]:
    """The module ``__getattr__`` of ``module``: a name that moved out of it, or out of an old path of
    it (:data:`MOVED_NAMES`), warns and comes from its new place; anything else raises ``AttributeError``."""
    names = _old_names(module)

    def __getattr__(name: str) -> Any:
        if name in names:
            old, target, removed_in = names[name]
            warnings.warn(f"{old}.{name} moved to {target}.{name}; import it from there (the old name goes in {removed_in})",
                          DeprecationWarning, stacklevel=2)
            return getattr(importlib.import_module(target), name)
        raise AttributeError(f"module {module!r} has no attribute {name!r}")

    return __getattr__


class _MovedModules:
    """The import-system finder and loader of the old paths (:data:`MOVED_MODULES`): importing one
    warns once and binds the old path to the new module itself, so both names are one object (one
    module state, never a copy loaded twice)."""

    def find_spec(self, fullname: str, path: Sequence[str] | None = None, target: ModuleType | None = None) -> ModuleSpec | None:
        if not fullname.startswith("earthbench."):  # every import of the process asks: answer the others at once
            return None
        return ModuleSpec(fullname, cast("Loader", self)) if new_path(fullname) is not None else None

    def create_module(self, spec: ModuleSpec) -> None:
        return None  # a placeholder module; exec_module puts the real one in its place

    def exec_module(self, module: ModuleType) -> None:
        old = module.__name__
        new, removed_in = new_path(old)  # type: ignore[misc]  # find_spec took only moved paths
        if old in MOVED_MODULES:  # once, for the path the user named (not for each submodule under it)
            warnings.warn(f"the module {old} moved to {new}; import from there (the old name goes in {removed_in})",
                          DeprecationWarning, stacklevel=2)
        sys.modules[old] = importlib.import_module(new)  # the import system returns what sys.modules holds


def install() -> None:
    """Make the old paths importable (once per process), ahead of the file finders so that an old
    package's submodule is never found, and loaded a second time, under its old name."""
    if not any(isinstance(finder, _MovedModules) for finder in sys.meta_path):
        sys.meta_path.insert(0, _MovedModules())
