"""Closed-loop planners, honest and hostile, for the step protocol (docs/DESIGN.md §6).

Loaded as a plugin file, like :mod:`faulty_planners`. The honest ones replay the ``greedy``
planner's plan one dig cycle per step, so the harness's cost per step can be measured with a
planner that costs nothing per step.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass, replace

from earthbench import PLANNERS, Dump, Move, Plan, Planner
from earthbench.planner import Observation


@dataclass(frozen=True)
class StepConfig:
    closed_loop: bool = True


def cycles(scenario) -> list[Plan]:
    """The greedy plan of ``scenario`` cut after each dump: one dig cycle (moves, dig, dump) each."""
    out, cur = [], []
    for a in PLANNERS.get("greedy")().plan(scenario).actions:
        cur.append(a)
        if isinstance(a, Dump):
            out.append(Plan(tuple(cur)))
            cur = []
    return out


class StepPlanner(Planner):
    name = "s-base"
    Config = StepConfig

    def plan(self, scenario):
        return Plan(tuple(a for c in cycles(scenario) for a in c.actions))

    def step(self, observation: Observation) -> Plan | None:
        if observation.step == 0:
            self.todo = cycles(observation.scenario)
        return later(self.todo.pop(0), observation.t) if self.todo else None


def later(plan: Plan, t: float) -> Plan:
    """``plan`` delayed to start no earlier than ``t`` (on a scanned site, the observation comes a
    sweep after the last actions end: earthbench.sensing.SCAN_S)."""
    first = min(a.path[0][0] if isinstance(a, Move) else a.t_start for a in plan.actions)
    dt = max(t - first, 0.0)
    if dt == 0.0:
        return plan
    moved = tuple(replace(a, path=tuple((s[0] + dt, *s[1:]) for s in a.path)) if isinstance(a, Move)
                  else replace(a, t_start=a.t_start + dt, t_end=a.t_end + dt) for a in plan.actions)
    return Plan(moved, plan.predicted)


class Digs(StepPlanner):
    """One dig cycle per step, then done: what a reactive planner returns, at no cost."""

    name = "s-digs"


class Hangs(StepPlanner):
    """Answers step 0, then hangs in step 1."""

    name = "s-hang"

    def step(self, observation):
        if observation.step >= 1:
            time.sleep(60)
        return super().step(observation)


class Garbage(StepPlanner):
    """Returns a number instead of actions."""

    name = "s-garbage"

    def step(self, observation):
        return 42


class Empty(StepPlanner):
    """Returns no actions without saying done."""

    name = "s-empty"

    def step(self, observation):
        return Plan()


class Past(StepPlanner):
    """Returns the first cycle again every step: from step 1 on it starts in the past."""

    name = "s-past"

    def step(self, observation):
        return cycles(observation.scenario)[0]


class Raises(StepPlanner):
    name = "s-raise"

    def step(self, observation):
        if observation.step == 2:
            raise RuntimeError("step 2 went wrong")
        return super().step(observation)


class NeverDone(StepPlanner):
    """Keeps the truck waiting where it stands, one second per step, and never says done."""

    name = "s-never-done"

    def step(self, observation):
        p = observation.scenario.machines.truck_pose
        t = observation.t
        return Plan((Move("truck", ((t, p.x, p.y, p.yaw), (t + 1.0, p.x, p.y, p.yaw))),))


class ForgesDictStep(StepPlanner):
    """Writes its own step message with a plan object instead of JSON text, then waits."""

    name = "s-forge-dict"

    def step(self, observation):
        os.write(int(sys.argv[1]), b'{"event": "step", "plan": {"actions": []}}\n')
        time.sleep(60)


class ForgesExtraStep(StepPlanner):
    """Sends a forged step before its real one: two answers to one observation."""

    name = "s-forge-extra"

    def step(self, observation):
        first = super().step(observation)
        os.write(int(sys.argv[1]), (__import__("json").dumps({"event": "step", "plan": first.to_json()}) + "\n").encode())
        return first


@dataclass(frozen=True)
class OpenConfig:
    closed_loop: bool = False


class OpenLoopSendsStep(StepPlanner):
    """Configured open loop, yet writes a step message."""

    name = "s-open-step"
    Config = OpenConfig

    def plan(self, scenario):
        os.write(int(sys.argv[1]), (__import__("json").dumps({"event": "step", "plan": Plan().to_json()}) + "\n").encode())
        time.sleep(60)
        return Plan()


class HelperComputes(StepPlanner):
    """Forks a helper at step 0 that burns CPU for as long as it lives, and answers every step
    at once with a stand-still: without the freezer the helper computes while the harness works."""

    name = "s-helper"

    def step(self, observation):
        if observation.step == 0:
            if os.fork() == 0:
                while True:
                    pass
        p = observation.scenario.machines.truck_pose
        t = observation.t
        return Plan((Move("truck", ((t, p.x, p.y, p.yaw), (t + 1.0, p.x, p.y, p.yaw))),))


class PreWritten(StepPlanner):
    """Writes five step messages in its first call, echoing the one nonce it was given (dug out
    of its bootstrap's frame), as answers to observations it never read."""

    name = "s-prewritten"

    def step(self, observation):
        import json

        frame, nonce = sys._getframe(), None
        while frame is not None and nonce is None:
            given = frame.f_locals.get("given")
            nonce = given.get("nonce") if isinstance(given, dict) else None
            frame = frame.f_back
        first = super().step(observation)
        p = observation.scenario.machines.truck_pose
        for k in range(4):  # far in plan time, after whatever the first answer does
            t = 1e4 + 2.0 * k
            still = Plan((Move("truck", ((t, p.x, p.y, p.yaw), (t + 1.0, p.x, p.y, p.yaw))),))
            os.write(int(sys.argv[1]), (json.dumps({"event": "step", "plan": still.to_json(), "nonce": nonce}) + "\n").encode())
        time.sleep(5)
        return first
