"""The closed loop both backhoe families share (docs/DESIGN.md §6), as
:class:`~earthbench_planners.loader_cycle.CyclePlanner` is the loader families'.

Each step plans from the observation (the terrain as it now is, the machines where they stand,
the clock, the swing's turn and the load the truck reports) up to and including the next dump.
What a planner carries from step to step (greedy: the stations it has visited;
singh-cannon-backhoe: the floor it works to and the stations it has exhausted) is taken from the
first step's session and handed to every later one.
"""

from __future__ import annotations

from abc import abstractmethod
from typing import Generic, Protocol, TypeVar

from earthbench.plan import Plan
from earthbench.planner import Observation, Planner
from earthbench.world import Scenario


class Session(Protocol):
    """A planning session's clock, swing turn and truck load, which a step sets from the observation."""

    t: float
    turn: float
    loaded: float


S = TypeVar("S", bound=Session)
K = TypeVar("K")


class BackhoeLoopPlanner(Planner, Generic[S, K]):
    """A backhoe planner whose closed-loop step is one dump's worth of its open-loop session."""

    tracks = ("backhoe",)
    _carried: K | None = None

    def step(self, observation: Observation) -> Plan | None:
        if observation.truck_full:
            return None
        session = self.session(observation.scenario)
        session.t, session.turn, session.loaded = observation.t, observation.turn, observation.loaded
        if observation.step == 0 or self._carried is None:
            self._carried = self._carry(session)
        plan = self._one_dump(session, self._carried)
        return plan if plan.actions else None

    @abstractmethod
    def session(self, scenario: Scenario) -> S:
        """A planning session at the scenario's initial state."""

    @abstractmethod
    def _carry(self, session: S) -> K:
        """What the planner keeps from its first step's session for the later steps."""

    @abstractmethod
    def _one_dump(self, session: S, carried: K) -> Plan:
        """The session's plan up to and including its next dump, with what was carried."""
