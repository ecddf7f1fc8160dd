"""Fixtures of the speed benches."""

from __future__ import annotations

import compileall
from collections.abc import Iterator
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


@pytest.fixture(params=["on", "off"])
def isolation(request, monkeypatch) -> Iterator[str]:
    """Each bench twice in one run, side by side: cases in their namespaces and cgroup ("on",
    skipped where the kernel does not allow it) and with per-process fences only ("off")."""
    from earthbench.running.harness import isolation as iso

    if request.param == "off":
        monkeypatch.setenv(iso.SWITCH, "off")
    iso.support.cache_clear()
    if request.param == "on" and not iso.support().full:
        pytest.skip(iso.describe())
    yield iso.support().label
    monkeypatch.undo()
    iso.support.cache_clear()
