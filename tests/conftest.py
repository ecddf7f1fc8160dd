"""Shared fixtures; the helpers they use live in ``tests/helpers``."""

from __future__ import annotations

import pytest

from earthbench import Plan, Scenario
from helpers import block_scenario, dig_dump_plan


@pytest.fixture
def scenario() -> Scenario:
    return block_scenario()


@pytest.fixture
def valid_plan() -> Plan:
    return Plan(tuple(dig_dump_plan()))


@pytest.fixture
def forget_test_planners():
    """Planners a test loads must not leak into later tests' default planner lists."""
    from earthbench.registry import PLANNERS

    before = set(PLANNERS.names())
    yield
    for name in set(PLANNERS.names()) - before:
        PLANNERS.unregister(name)
