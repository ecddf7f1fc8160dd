"""The closed-loop base of the loader planners (:class:`CyclePlanner`, docs/DESIGN.md §6): one cycle
per step from the observation, remembering the first ground and what the charges delivered."""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass

import numpy as np

from earthbench.plan import Plan
from earthbench.planner import Observation, Planner
from earthbench.world import Scenario

from .cycle import CycleBuilder


@dataclass
class LoopMemory:
    """What a closed-loop loader planner keeps between its steps: the first ground it saw (the
    harder layer lies under it), and each step's expected and delivered volume, whose ratio
    (:attr:`yield_factor`) sizes the next charges when they come back short."""

    z0: np.ndarray
    loaded: float
    expected: float = 0.0
    delivered: float = 0.0

    @property
    def yield_factor(self) -> float:
        if self.expected < 0.05:
            return 1.0
        return min(max(self.delivered / self.expected, 0.3), 1.2)


class CyclePlanner(Planner):
    """A wheel-loader planner on :class:`CycleBuilder`, which differs from the others only in
    how :meth:`_run` chooses each dig: open loop runs cycles until the target is loaded, a
    closed-loop step one cycle from the observation."""

    tracks = ("wheel_loader",)

    def plan(self, scenario: Scenario) -> Plan:
        return self._run(CycleBuilder(scenario, self.config))

    def step(self, observation: Observation) -> Plan | None:
        """One cycle from the observation. The planner remembers its first ground and what its
        charges delivered (:class:`LoopMemory`): a charge that came back short is followed by
        another, sized with the yield seen so far, until the truck reports the target."""
        if observation.truck_full:
            return None
        memory: LoopMemory | None = getattr(self, "_memory", None)
        if memory is None or observation.step == 0:
            b = CycleBuilder.observed(observation, self.config)
            memory = self._memory = LoopMemory(b.z, observation.loaded)
        else:
            memory.delivered += observation.loaded - memory.loaded
            memory.loaded = observation.loaded
            b = CycleBuilder.observed(observation, self.config, z0=memory.z0, yield_factor=memory.yield_factor)
        plan = self._run(b, max_dumps=1)
        if not plan.actions:
            return None
        memory.expected += sum(c.charge_result.delivered for c in b.cycles)
        return plan

    @abstractmethod
    def _run(self, b: CycleBuilder, max_dumps: int | None = None) -> Plan:
        """Cycles on ``b`` until the target is loaded (or ``max_dumps`` cycles: one step)."""
