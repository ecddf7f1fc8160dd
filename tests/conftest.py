"""Shared fixtures; the helpers they use live in ``tests/helpers``."""

from __future__ import annotations

import os
import shutil
import signal
import tempfile
from pathlib import Path

import pytest

from earthbench import Plan, Scenario
from helpers import block_scenario, dig_dump_plan


_NLP_CACHE_ENV = "EARTHBENCH_NLP_CACHE"  # earthbench_planners.stl_tamp.nlp_cache.ENV


#: The test planners' own settings, given to their cases by name (a case gets no other variable
#: of the harness's environment: earthbench.running.harness.sandbox.PASSED_VARS).
_TEST_VARS = ("EARTHBENCH_TEST_PIDDIR,EARTHBENCH_TEST_PIDFILE,EARTHBENCH_TEST_NAP,EARTHBENCH_TEST_RESULT_MB,"
              "EARTHBENCH_TEST_VICTIM")


_PROBES_ENV = "EARTHBENCH_PROBES"  # earthbench.running.harness.probe.ENV


def pytest_configure(config: pytest.Config) -> None:
    """The session's built STL-TAMP NLPs (and those of the cases it runs) and its planner probes'
    answers go to temporary folders, not the user's caches, unless the caller chose them; the test
    planners' settings reach their cases."""
    os.environ.setdefault("EARTHBENCH_CASE_ENV", _TEST_VARS)
    if _NLP_CACHE_ENV not in os.environ:
        config._earthbench_nlp_cache = os.environ[_NLP_CACHE_ENV] = tempfile.mkdtemp(prefix="earthbench-nlp-")
    if _PROBES_ENV not in os.environ:
        config._earthbench_probes = os.environ[_PROBES_ENV] = tempfile.mkdtemp(prefix="earthbench-probes-")


def pytest_unconfigure(config: pytest.Config) -> None:
    for attr, env in (("_earthbench_nlp_cache", _NLP_CACHE_ENV), ("_earthbench_probes", _PROBES_ENV)):
        folder = getattr(config, attr, None)
        if folder:
            shutil.rmtree(folder, ignore_errors=True)
            os.environ.pop(env, None)


@pytest.fixture
def scenario() -> Scenario:
    return block_scenario()


@pytest.fixture
def valid_plan() -> Plan:
    return Plan(tuple(dig_dump_plan()))


@pytest.fixture
def isolation_off(monkeypatch):
    """Cases of this test run with per-process fences only (``EARTHBENCH_ISOLATION=off``)."""
    from earthbench.running.harness import isolation

    monkeypatch.setenv(isolation.SWITCH, "off")
    isolation.support.cache_clear()
    yield
    monkeypatch.delenv(isolation.SWITCH)
    isolation.support.cache_clear()


@pytest.fixture
def prepared_root(tmp_path, monkeypatch):
    """A preparation cache of the test's own, with the planners that prepare
    (``tests/plugins/preparing_planners.py``) registered."""
    from earthbench.registry import load_plugin_file

    root = tmp_path / "prepared"
    monkeypatch.setenv("EARTHBENCH_PREPARED", str(root))
    load_plugin_file(str(Path(__file__).parent / "plugins" / "preparing_planners.py"))
    return root


@pytest.fixture
def forget_test_planners():
    """Planners a test loads must not leak into later tests' default planner lists."""
    from earthbench.registry import PLANNERS

    before = set(PLANNERS.names())
    yield
    for name in set(PLANNERS.names()) - before:
        PLANNERS.unregister(name)


@pytest.fixture
def sigint_delivered():
    """Let Ctrl-C reach Python in this test and the processes it starts.

    A shell's background job (``cmd &``, ``nohup``) starts with SIGINT ignored, an ignored signal
    stays ignored across exec, and Python then never raises KeyboardInterrupt: a Ctrl-C test
    run that way would see a run go on to the end. A handler in this process is reset to the
    default in its children, which then install Python's own.
    """
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)
