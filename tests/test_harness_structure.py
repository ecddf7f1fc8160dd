"""The import graph: the run's records below the store and the harness, the store and the progress line
apart from the harness, no cycle in the core, no import from the core into the plugin packages, no
private name across modules, no SQL outside the store (docs/DESIGN.md §2)."""

from __future__ import annotations

import ast
import graphlib
import re
from pathlib import Path


ROOT = Path(__file__).parents[1] / "earthbench"
#: The harness's modules (the running layer's folder).
HARNESS = ROOT / "running" / "harness"
#: The store's modules: every SQL statement of earthbench is in them.
STORE = sorted((ROOT / "results" / "store").glob("*.py"))
#: Import name of each plugin package → its folder in the repository (pyproject's package-dir).
PLUGIN_PACKAGES = {"earthbench_planners": "planners", "earthbench_terrains": "terrains", "earthbench_metrics": "metrics"}
FOLDER_PACKAGES = {folder: name for name, folder in PLUGIN_PACKAGES.items()}


def _imports(path: Path) -> list[tuple[str, str, bool]]:
    """(module imported from, name, inside ``if TYPE_CHECKING``) for every ``from … import`` of a file."""
    tree = ast.parse(path.read_text())
    guarded = {id(n) for node in ast.walk(tree) if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)
               for n in ast.walk(node)}
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            base = "." * node.level + (node.module or "")
            out += [(base, alias.name, id(node) in guarded) for alias in node.names]
    return out


def test_no_private_name_crosses_a_harness_module():
    for path in [*sorted(HARNESS.glob("*.py")), ROOT / "results" / "records.py", *STORE, ROOT / "results" / "progress.py"]:
        for module, name, _ in _imports(path):
            if module.startswith(".") or module.startswith("earthbench"):
                assert not name.startswith("_"), f"{path.name} imports the private {module}.{name}"


def test_the_store_and_progress_line_never_import_the_harness_and_the_harness_imports_them_only_for_types():
    """The store keeps the run's records (:mod:`earthbench.results.records`) and knows nothing of how cases
    run; the records sit below both, so neither a store nor a record reaches up into the harness,
    not even for type checking."""
    for path in (*STORE, ROOT / "results" / "progress.py", ROOT / "results" / "records.py"):
        found = {m for m, _ in _all_imports(path, in_functions=True, type_checking=True) if m.startswith("earthbench.running.harness")}
        assert found == set(), f"{path.name} imports {found}"
    up = {"earthbench.results.store", "earthbench.results.progress", "earthbench.publishing", "earthbench.cli"}
    found = {m for m, _ in _all_imports(ROOT / "results" / "records.py", in_functions=True, type_checking=True) if m.startswith(tuple(up))}
    assert found == set()
    for path in sorted(HARNESS.glob("*.py")):
        for module, name, guarded in _imports(path):
            if module.lstrip(".") in ("store", "progress", "suite"):
                assert guarded, f"harness/{path.name} imports {module}.{name} at run time"


def _reached(graph: dict[str, set[str]], start: str) -> set[str]:
    seen, todo = set(), [start]
    while todo:
        for dep in graph.get(todo.pop(), ()):
            if dep not in seen:
                seen.add(dep)
                todo.append(dep)
    return seen


def test_the_sandbox_runs_and_measures_and_judges_nothing():
    """The harness's seams (docs/DESIGN.md §6): the sandbox (and its supervisor and fences) reaches
    neither the referee nor the scoring rule, not even through another module or on first use;
    the judge is a step of its own, and the closed loop's step is the step loop's."""
    graph = _core_graph(in_functions=True)
    for module in ("earthbench.running.harness.sandbox", "earthbench.running.harness.supervisor", "earthbench.running.harness.isolation"):
        reached = _reached(graph, module)
        judging = ("earthbench.referee", "earthbench.results.scoring", "earthbench.running.harness.steps",
                   "earthbench.running.harness.judge")
        assert not {m for m in reached if m.startswith(judging)}, module
    assert "earthbench.results.scoring" in graph["earthbench.running.harness.judge"]
    assert "earthbench.referee" in _reached(graph, "earthbench.running.harness.steps")


def test_the_harness_names_no_planner():
    """A planner declares what its cases read (``Planner.reads``) as it declares its preparation:
    the harness knows no planner by name."""
    found = [(p.name, n) for p in sorted(HARNESS.glob("*.py"))
             for n, line in enumerate(p.read_text().splitlines(), 1) if re.search(r"stl|nlp", line, re.I)]
    assert found == []


def test_run_case_imported_from_its_old_place_still_works_with_a_warning():
    import warnings

    import earthbench.running.harness
    from earthbench.running.harness import sandbox

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert sandbox.run_case is earthbench.running.harness.run_case
    assert [w.category for w in caught] == [DeprecationWarning] and "earthbench.running.harness.run" in str(caught[0].message)


#: The longest a module of the harness may be (lines).
HARNESS_MODULE_LINES = 600


def test_no_harness_module_runs_over_600_lines():
    long = {p.name: n for p in sorted(HARNESS.glob("*.py")) if (n := len(p.read_text().splitlines())) > HARNESS_MODULE_LINES}
    assert long == {}


# -- the whole core ------------------------------------------------------------------------------


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
    parts[0] = FOLDER_PACKAGES.get(parts[0], parts[0])
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _all_imports(path: Path, *, in_functions: bool, type_checking: bool = False) -> list[tuple[str, str | None]]:
    """(absolute module, name or None) for every import of a file outside ``if TYPE_CHECKING`` (inside
    it too with ``type_checking``); imports inside function bodies (made on first use) only when ``in_functions``."""
    tree = ast.parse(path.read_text())
    skipped: set[int] = set()
    for node in ast.walk(tree):
        if not type_checking and isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skipped |= {id(n) for n in ast.walk(node)}
        elif not in_functions and isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            skipped |= {id(n) for n in ast.walk(node)}
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out: list[tuple[str, str | None]] = []
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        if isinstance(node, ast.Import):
            out += [(alias.name, None) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                module = ".".join(base + ([module] if module else []))
            out += [(module, alias.name) for alias in node.names]
    return out


CORE = {_module_name(p): p for p in sorted(ROOT.rglob("*.py"))}


def _core_graph(*, in_functions: bool) -> dict[str, set[str]]:
    graph = {}
    for name, path in CORE.items():
        deps = set()
        for module, imported in _all_imports(path, in_functions=in_functions):
            if imported and f"{module}.{imported}" in CORE:
                deps.add(f"{module}.{imported}")  # ``from package import submodule``
            elif module in CORE:
                deps.add(module)
        graph[name] = deps - {name}
    return graph


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    try:
        tuple(graphlib.TopologicalSorter(graph).static_order())
    except graphlib.CycleError as e:
        return e.args[1]
    return None


def test_the_graph_sees_every_kind_of_import():
    database = ROOT / "results" / "store" / "database.py"
    assert ("earthbench.results.records", "Case") in _all_imports(database, in_functions=False, type_checking=True)
    assert ("earthbench.results.records", "Case") not in _all_imports(database, in_functions=True)
    graph = _core_graph(in_functions=True)
    judge = graph["earthbench.running.harness.judge"]
    assert {"earthbench.running.harness.environment", "earthbench.results.scoring"} <= judge  # from .x, from ...x
    assert "earthbench.results.scoring" not in _core_graph(in_functions=False)["earthbench.publishing.verify"]  # imported on first use
    assert {"earthbench.results.scoring", "earthbench.running.harness.environment"} <= graph["earthbench.publishing.verify"]
    assert _cycle({"a": {"b"}, "b": {"a"}}) is not None and _cycle({"a": {"b"}, "b": set()}) is None


def test_publishing_reads_labels_not_verify():
    """What publishing and ``verify`` both show (machine labels, the latest spot checks) lives in
    :mod:`earthbench.results.labels`; publishing never imports ``verify`` (issue 52)."""
    graph = _core_graph(in_functions=True)
    publishing = [m for m in graph if m == "earthbench.publishing.publish" or m.startswith("earthbench.publishing.board")]
    assert len(publishing) > 3 and not {m for m in publishing if "earthbench.publishing.verify" in graph[m]}


def test_no_import_cycle_among_the_core_modules_at_import_time():
    assert _cycle(_core_graph(in_functions=False)) is None


def test_no_import_cycle_among_the_core_modules_counting_imports_made_on_first_use():
    assert _cycle(_core_graph(in_functions=True)) is None


#: The core's layers, bottom first (docs/DESIGN.md §2): each layer's folder under ``earthbench/``
#: ("" for the package's face, the top) and the modules and packages in it. A module imports from
#: its own layer or the ones below, never from above (not even for type checking, nor in a function
#: body); within a layer, no cycle. The folders are the map: a module's folder is its layer.
LAYERS: dict[str, tuple[str, tuple[str, ...]]] = {
    "base": ("", ("errors", "lazy", "compat", "stats", "plotting", "profiles", "assets", "api")),
    "world": ("", ("world", "machines", "classes", "plan")),
    "contract": ("", ("cut", "motion", "soil", "sensing", "rules", "planner", "registry", "seal")),
    "judge": ("referee", ("state", "loop", "paths", "clearance", "backhoe", "loader", "truck", "site", "ground")),
    "results": ("results", ("scoring", "records", "progress", "labels", "aggregate", "generalisation", "store", "suite",
                            "suite_checks", "identity", "calibration", "provenance")),
    "running": ("running", ("harness", "playback", "figures", "scaling")),
    "publishing": ("publishing", ("verify", "merge", "best", "board", "publish", "compare")),
    "commands": ("cli", ("run", "runs", "plan", "show", "leaderboard", "compare", "merge", "verify", "best", "export",
                         "rescore", "prepare", "preparing", "seal", "suites", "list_", "validate", "calibration",
                         "new_planner", "_common")),
}
#: ``python -m earthbench`` runs ``earthbench/__main__.py``: the one module that sits outside its
#: layer's folder, where Python looks for it.
MAIN = ("__main__", "commands")
#: The layers a plugin may import at run time: a planner or a terrain builds on the contract
#: (never the judge, the harness or the store); a metric reads the judge's verdict and the scoring.
PLUGIN_LAYERS = {"planners": "contract", "terrains": "contract", "metrics": "results"}
#: The top layer of the package's face: what every planner and terrain imports by its short path.
FACE = list(LAYERS).index(PLUGIN_LAYERS["planners"])
#: A name directly under ``earthbench/`` (a face module, a layer's folder, ``__main__``) → its layer's rank.
_RANK = {name: n for n, (folder, modules) in enumerate(LAYERS.values()) for name in (modules if not folder else (folder,))} \
    | {MAIN[0]: list(LAYERS).index(MAIN[1])}


def _layer(module: str) -> int | None:
    """The rank of a core module's layer; None for the package's face (``earthbench``), whose
    imports are for type checkers only."""
    parts = module.split(".")
    return None if len(parts) == 1 else _RANK[parts[1]]


def _runs_up(rank: int, module: str, imported: str | None) -> str | None:
    """The core module that ``from module import imported`` reaches, if it lies above layer
    ``rank``; the face counts as above every layer (it re-exports the judge) but for ``__version__``
    and ``build_info`` (the module a build writes beside it, :mod:`earthbench.results.provenance`)."""
    target = f"{module}.{imported}" if imported and f"{module}.{imported}" in CORE else module
    if target not in CORE:
        return None
    layer = _layer(target)
    if layer is None:
        return None if imported in ("__version__", "build_info") else f"{module}.{imported}"
    return target if layer > rank else None


def test_every_core_module_has_one_layer():
    assert {m.split(".")[1] for m in CORE if "." in m} == set(_RANK)
    names = [name for folder, modules in LAYERS.values() for name in (modules if not folder else (folder,))]
    assert len(names) == len(set(names)) == len(_RANK) - 1


def test_the_folders_show_the_layers():
    """The rule that decides which layers are folders: the layers a planner or terrain imports
    (base, world, contract) are the package's face, flat under ``earthbench/`` (the documented
    plugin API keeps its short paths, ``earthbench.plan``, ``earthbench.cut``, …); each layer above
    is one folder of its own, named for the layer, but for the judge's ``referee/`` (``earthbench.judge``
    is the face's function) and the commands' ``cli/`` (the console script's module)."""
    assert [n for n, (folder, _) in enumerate(LAYERS.values()) if not folder] == list(range(FACE + 1))
    assert {layer: folder for layer, (folder, _) in LAYERS.items() if folder and folder != layer} == {"judge": "referee",
                                                                                                    "commands": "cli"}


def test_the_layer_rule_refuses_an_import_that_runs_back_up():
    store, planners = _RANK["results"], FACE
    assert _runs_up(store, "earthbench.running.harness", "Case") == "earthbench.running.harness"
    assert _runs_up(store, "earthbench.running.harness.cases", "Case") == "earthbench.running.harness.cases"
    assert _runs_up(planners, "earthbench.referee", "judge") == "earthbench.referee"
    assert _runs_up(planners, "earthbench.referee", "state") == "earthbench.referee.state"
    assert _runs_up(planners, "earthbench", "judge") == "earthbench.judge"
    assert _runs_up(planners, "earthbench.rules", "bodies_touch") is None
    assert _runs_up(store, "earthbench", "__version__") is None and _runs_up(store, "numpy", None) is None
    # a module put in the results' folder is a results module: it may not import publishing
    assert _runs_up(_layer("earthbench.results.merge"), "earthbench.publishing.verify", "audit") == "earthbench.publishing.verify"


def test_no_import_runs_back_up_the_layers():
    up = {(name, hit) for name, path in CORE.items() if "." in name
          for module, imported in _all_imports(path, in_functions=True, type_checking=True)
          if (hit := _runs_up(_layer(name), module, imported)) and hit != name}  # type: ignore[arg-type]
    assert up == set(), "imports that run back up the layers (docs/DESIGN.md §2)"


def test_the_plugins_import_no_layer_above_theirs():
    """At run time, that is: a metric plugin may name the judge's ``Verdict`` for type checking."""
    up = {(str(path.relative_to(ROOT.parent)), hit) for folder, highest in PLUGIN_LAYERS.items()
          for path in sorted((ROOT.parent / folder).rglob("*.py"))
          for module, imported in _all_imports(path, in_functions=True)
          if (hit := _runs_up(list(LAYERS).index(highest), module, imported))}
    assert up == set()


def test_the_core_never_imports_a_plugin_package():
    found = {(name, module) for name, path in CORE.items() for module, _ in _all_imports(path, in_functions=True)
             if module.split(".")[0] in PLUGIN_PACKAGES}
    assert found == set()


def _private_imports() -> set[tuple[str, str]]:
    """(importing module, module.name) for each private name imported from another module of the
    project, or a private module imported from outside its own package."""
    files = [p for top in ("earthbench", *FOLDER_PACKAGES, "scripts") for p in sorted((ROOT.parent / top).rglob("*.py"))]
    out = set()
    for path in files:
        here = path.stem if path.parent.name == "scripts" else _module_name(path)
        package = here if path.name == "__init__.py" else here.rpartition(".")[0]
        for module, imported in _all_imports(path, in_functions=True):
            if module.split(".")[0] not in ("earthbench", *PLUGIN_PACKAGES):
                continue
            private_name = imported is not None and imported.startswith("_") and not imported.startswith("__")
            owner, _, leaf = module.rpartition(".")
            private_module = leaf.startswith("_") and not leaf.startswith("__") and owner != package
            if private_name or private_module:
                out.add((here, f"{module}.{imported}"))
    return out


def test_no_private_name_crosses_a_module():
    assert _private_imports() == set()


def test_no_file_imports_a_plugin_folder_by_its_generic_name():
    """``planners``, ``terrains`` and ``metrics`` are folders, not import names: the wheel installs
    them as ``earthbench_planners``, … (a module reached both ways would be loaded twice)."""
    files = [p for top in ("earthbench", *FOLDER_PACKAGES, "scripts", "tests") for p in sorted((ROOT.parent / top).rglob("*.py"))]
    assert len(files) > 100
    found = {(str(path.relative_to(ROOT.parent)), module) for path in files
             for module, _ in _all_imports(path, in_functions=True) if module.split(".")[0] in FOLDER_PACKAGES}
    assert found == set()


def test_planners_call_the_public_rules_and_only_the_referee_calls_the_judge():
    """A planner plans within the rules with :mod:`earthbench.rules` (as with ``cut`` and
    ``motion``); the judge (:mod:`earthbench.referee`) is for the harness and the tools, and the
    rules never reach back up into it (docs/DESIGN.md §2)."""
    planners = sorted((ROOT.parent / "planners").rglob("*.py"))
    assert len(planners) > 10
    found = {(str(path.relative_to(ROOT.parent)), module) for path in planners
             for module, _ in _all_imports(path, in_functions=True) if module.startswith("earthbench.referee")}
    assert found == set()
    graph = _core_graph(in_functions=True)
    assert not {m for m in graph["earthbench.rules"] if m.startswith("earthbench.referee")}
    assert "earthbench.rules" in graph["earthbench.referee.backhoe"] and "earthbench.rules" in graph["earthbench.referee.loader"]


def test_a_rule_imported_from_its_old_place_in_the_referee_still_works_with_a_warning():
    import warnings

    import earthbench.rules
    from earthbench.referee import backhoe, loader

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the module's own move (tests/test_api.py)
        from earthbench.referee import replay
    for module, name in ((backhoe, "track_level_and_tilt"), (loader, "wheel_step_excess"), (replay, "bodies_touch")):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            assert getattr(module, name) is getattr(earthbench.rules, name)
        assert [w.category for w in caught] == [DeprecationWarning]
        assert "earthbench.rules" in str(caught[0].message)
    try:
        backhoe.no_such_rule  # noqa: B018
    except AttributeError as e:
        assert "no_such_rule" in str(e)
    else:
        raise AssertionError("an unknown name must raise AttributeError")


# -- the store owns its SQL ------------------------------------------------------------------------

_SQL = re.compile(r"^\s*(SELECT|INSERT|UPDATE|DELETE|REPLACE|CREATE|ALTER|DROP|PRAGMA|BEGIN|COMMIT|ROLLBACK|WITH)\b")
_CURSOR_CALLS = {"execute", "executemany", "executescript"}


def _sql_in(source: str) -> set[tuple[int, str]]:
    """(line, what) for each SQL statement (an f-string's too), ``sqlite3`` import or cursor call on a string literal in ``source``."""
    out = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and _SQL.match(node.value):
            out.add((node.lineno, node.value.split()[0]))
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names = [node.module or ""] if isinstance(node, ast.ImportFrom) else [a.name for a in node.names]
            if "sqlite3" in names:
                out.add((node.lineno, "import sqlite3"))
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in _CURSOR_CALLS \
                and node.args and isinstance(node.args[0], (ast.Constant, ast.JoinedStr, ast.BinOp)):
            out.add((node.lineno, f".{node.func.attr}()"))
    return out


def test_the_sql_finder_sees_every_shape_of_statement():
    source = ('import sqlite3\nQ = """\n  SELECT 1"""\ndb.execute(f"UPDATE runs SET x={x}")\n'
              'db.executemany("INS" + "ERT INTO t VALUES (?)", [])\nengine.execute(fig)\nprint("Selected runs; DROP it")\n')
    assert _sql_in(source) == {(1, "import sqlite3"), (2, "SELECT"), (4, "UPDATE"), (4, ".execute()"), (5, ".executemany()")}


def test_no_sql_outside_the_store():
    """Every SQL statement lives in the :mod:`earthbench.results.store` package, behind a named method or
    reader (docs/DESIGN.md §2): the rest of the core, the plugins and the scripts read and write a
    store only through it."""
    files = [p for top in ("earthbench", *FOLDER_PACKAGES, "scripts") for p in sorted((ROOT.parent / top).rglob("*.py"))]
    found = {(str(p.relative_to(ROOT.parent)), *hit) for p in files if p not in STORE for hit in _sql_in(p.read_text())}
    assert found == set()
    assert _sql_in((ROOT / "results" / "store" / "database.py").read_text())  # the finder reads the store's own statements


def test_the_records_keep_their_old_import_paths():
    import earthbench.running.harness
    import earthbench.results.records
    from earthbench.running.harness import cases

    for name in ("REASONS", "Case", "CaseResult", "PlannerRef"):
        assert getattr(cases, name) is getattr(earthbench.results.records, name) is getattr(earthbench.running.harness, name)


# -- functions a reader can hold in mind -----------------------------------------------------------

#: No function of the core or the plugins runs over this many lines (issue 52: without exceptions).
LONG = 80


def test_no_function_runs_over_80_lines():
    files = [p for top in ("earthbench", *FOLDER_PACKAGES) for p in sorted((ROOT.parent / top).rglob("*.py"))]
    found = {(str(p.relative_to(ROOT.parent)), n.name) for p in files for n in ast.walk(ast.parse(p.read_text()))
             if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.end_lineno - n.lineno + 1 > LONG}
    assert found == set(), f"split these: {sorted(found)}"


# -- modules a reader can hold in mind -------------------------------------------------------------

#: No module of the core or the plugins runs over this many lines (issue 52): one with a package's
#: worth inside is cut into one.
LONG_MODULE = 600


def test_no_module_runs_over_600_lines():
    files = [p for top in ("earthbench", *FOLDER_PACKAGES) for p in sorted((ROOT.parent / top).rglob("*.py"))]
    found = {str(p.relative_to(ROOT.parent)) for p in files if len(p.read_text().splitlines()) > LONG_MODULE}
    assert found == set(), f"split these: {sorted(found)}"


def _design_layers() -> dict[str, tuple[str, tuple[str, ...]]]:
    """docs/DESIGN.md §2's table of layers: each layer's folder ("" for ``earthbench/`` itself) and modules."""
    text = (ROOT.parent / "docs" / "DESIGN.md").read_text().split("## 2. Data flow and layers", 1)[1].split("\n## ", 1)[0]
    layers: dict[str, tuple[str, tuple[str, ...]]] = {}
    for row in text.splitlines():
        cells = [c.strip() for c in row.strip().strip("|").split("|")]
        if len(cells) < 3 or cells[0] in ("layer", "") or set(cells[0]) <= {"-"}:
            continue
        folder = re.match(r"`earthbench/(\w*)/?`", cells[1])
        assert folder, f"DESIGN §2, layer {cells[0]}: its folder, `earthbench/…/`, first in the second column"
        layers[cells[0]] = (folder.group(1), tuple(re.findall(r"`([\w.]+)`", cells[2])))
    return layers


def _entries(folder: Path) -> set[str]:
    """The modules and packages in ``folder``, by name (a package's ``__init__`` is the package)."""
    return {p.stem if p.is_file() else p.name for p in folder.iterdir()
            if (p.suffix == ".py" and p.name != "__init__.py") or (p / "__init__.py").exists()}


def _on_disk() -> dict[str, set[str]]:
    """``earthbench/`` ("") and each layer's folder → the modules and packages in it."""
    return {"": _entries(ROOT)} | {folder: _entries(ROOT / folder) for folder, _ in LAYERS.values() if folder}


def _misplaced(disk: dict[str, set[str]]) -> set[tuple[str, str]]:
    """(folder, name) for each module or package in a folder that ``LAYERS`` does not put there,
    and each that ``LAYERS`` puts in a folder where it is not."""
    expected = {"": set(_RANK)} | {folder: set(modules) for folder, modules in LAYERS.values() if folder}
    return {(folder, name) for folder in expected.keys() | disk.keys() for name in expected.get(folder, set()) ^ disk.get(folder, set())}


def test_a_module_in_the_wrong_layers_folder_is_found():
    disk = _on_disk()
    disk["results"] = disk["results"] | {"verify"}
    disk["publishing"] = disk["publishing"] - {"verify"}
    assert _misplaced(disk) == {("results", "verify"), ("publishing", "verify")}
    assert _misplaced(_on_disk() | {"": _entries(ROOT) | {"scoring"}}) == {("", "scoring")}


def test_design_the_layers_table_and_the_folders_are_one_map():
    """DESIGN §2's table is ``LAYERS``, layer by layer in order: each layer's folder and its modules;
    and the folders hold exactly those modules, each in its layer's folder (the face's at the top)."""
    assert _design_layers() == LAYERS
    assert _misplaced(_on_disk()) == set()
