"""Fixtures of the speed benches."""

from __future__ import annotations

import compileall
import importlib

import pytest


@pytest.fixture(scope="session")
def compiled_bytecode() -> None:
    """Byte-compile the core and the built-in plugins before timing a process's start-up.

    An installed wheel has its bytecode (pip compiles it at install); an editable checkout gets
    it at the first import, unless ``PYTHONDONTWRITEBYTECODE`` is set (as on this project's
    machines), in which case every fresh process compiles every module again, ~0.1 s that is
    the interpreter's and not the planner's.
    """
    for name in ("earthbench", "earthbench_planners", "earthbench_terrains", "earthbench_metrics"):
        for folder in importlib.import_module(name).__path__:
            assert compileall.compile_dir(folder, quiet=1), f"{folder} does not compile"
