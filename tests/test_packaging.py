"""The wheel installs ``earthbench`` and the plugin packages under their own names — never a
generic top-level ``planners``, ``terrains`` or ``metrics`` — with every sub-package, the
suite files, the page's assets and the ``py.typed`` marker (docs/DESIGN.md §1)."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
INSTALLED_AS = {"earthbench": "earthbench", "planners": "earthbench_planners", "terrains": "earthbench_terrains",
                "metrics": "earthbench_metrics"}


@pytest.fixture(scope="module")
def wheel_names(tmp_path_factory) -> set[str]:
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--wheel-dir", str(out), str(ROOT)],
                   check=True, capture_output=True)
    (wheel,) = out.glob("earthbench-*.whl")
    with zipfile.ZipFile(wheel) as z:
        return set(z.namelist())


@pytest.mark.slow
def test_the_wheel_installs_no_generic_top_level_name(wheel_names):
    tops = {n.split("/")[0] for n in wheel_names if not n.split("/")[0].endswith(".dist-info")}
    assert tops == set(INSTALLED_AS.values())


@pytest.mark.slow
def test_the_wheel_holds_every_package_suite_file_and_the_typed_marker(wheel_names):
    for folder, name in INSTALLED_AS.items():
        for init in (ROOT / folder).rglob("__init__.py"):
            assert f"{name}/{init.relative_to(ROOT / folder).as_posix()}" in wheel_names, init
    suites = {p.name for p in (ROOT / "terrains" / "suites").glob("*.toml")}
    assert suites and {f"earthbench_terrains/suites/{s}" for s in suites} <= wheel_names
    assert "earthbench/py.typed" in wheel_names
    assets = {p.name for p in (ROOT / "earthbench" / "assets").iterdir() if p.suffix in (".css", ".js")}
    assert assets and {f"earthbench/assets/{a}" for a in assets} <= wheel_names  # the page's style sheets and scripts
