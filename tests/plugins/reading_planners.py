"""Planners that declare the folders their cases read (``Planner.reads``), for tests/test_planner_reads.py."""

from __future__ import annotations

import os

from earthbench.plan import Plan, Prediction
from earthbench.planner import Planner, SharedFolder


def _listing(path: str | None) -> list[str] | str:
    try:
        return sorted(os.listdir(path)) if path else "unset"
    except OSError as exc:
        return type(exc).__name__


class ReadsShared(Planner):
    """Reports what its declared folder holds, and what it sees of an undeclared one beside it."""

    name = "t-reads-shared"
    reads = (SharedFolder("EARTHBENCH_TEST_SHARED", "earthbench/test-shared"),)

    def plan(self, scenario):
        shared = os.environ.get("EARTHBENCH_TEST_SHARED")
        other = os.path.join(os.path.dirname(shared), "other") if shared and shared != "off" else None
        return Plan(predicted=Prediction(volume=0.0, makespan=0.0),
                    info={"env": shared, "shared": _listing(shared), "other": _listing(other)})


class DeclaresNothing(ReadsShared):
    """The same planner without the declaration: its cases get neither the variable nor the folder."""

    name = "t-reads-nothing"
    reads = ()
