"""The harness package's shape: no import circle with the store or the progress line, no private names across modules."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).parents[1] / "earthbench"


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
    for path in [*sorted((ROOT / "harness").glob("*.py")), ROOT / "store.py", ROOT / "progress.py"]:
        for module, name, _ in _imports(path):
            if module.startswith(".") or module.startswith("earthbench"):
                assert not name.startswith("_"), f"{path.name} imports the private {module}.{name}"


def test_the_store_and_progress_line_read_only_the_case_types_and_the_harness_never_imports_them():
    for path in (ROOT / "store.py", ROOT / "progress.py"):
        harness = {m for m, _, _ in _imports(path) if "harness" in m}
        assert harness <= {".harness.cases"}, f"{path.name} imports {harness}"
    for path in sorted((ROOT / "harness").glob("*.py")):
        for module, name, guarded in _imports(path):
            if module.lstrip(".") in ("store", "progress", "suite"):
                assert guarded, f"harness/{path.name} imports {module}.{name} at run time"
