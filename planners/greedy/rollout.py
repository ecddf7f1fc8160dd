"""Greedy with its opening and relocations chosen by rollouts: a witness for best known plans (issue 49).

At each of the decisions that shape a greedy plan most — where the excavator and the truck go
first, and each relocation — every candidate (greedy's own choice, staying put, the opening's
best-estimated stations with their best truck stands, the next stations a relocation would try)
is played out to the end by greedy itself, and the one that reaches the target soonest by the
session's own model is taken (Bertsekas' rollout algorithm with greedy as the base policy).
Greedy's own choice is always a candidate and a session is deterministic, so the plan is never
later to the target than greedy's: :func:`rollout_plan` checks it.

Not a registered planner: it costs tens of greedy plans per plan. ``scripts/best_witness.py``
offers its plans as candidates to ``earthbench best update``, which judges them again.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable

from earthbench.plan import Plan
from earthbench.world import Pose, Scenario

from .backhoe import GreedyConfig, GreedySession

#: The opening's stations (best estimate first) and truck stands at each that are played out,
#: and the stations a relocation plays out.
OPENING_STATIONS, OPENING_STANDS, RELOCATIONS = 8, 4, 4

Visited = set[tuple[float, float]]
Act = Callable[["RolloutSession", Visited], bool]
Tried = tuple[Act, "RolloutSession", Visited]  # a candidate, a copy with it done, the copy's visited set


class RolloutSession(GreedySession):
    """Greedy's session whose opening and relocations are chosen by playing each candidate out."""

    def __init__(self, sc: Scenario, cfg: GreedyConfig):
        super().__init__(sc, cfg)
        self.inner = False  # a copy being played out decides as greedy does
        self.curve: list[tuple[float, float]] = []  # (end of each dump, the load after it)
        self.rollouts = 0

    def dump(self) -> None:
        super().dump()
        self.curve.append((self.t, self.loaded))

    def outcome(self) -> tuple[float, float]:
        """Time to the target by the session's own model (inf when short of it), then the shortfall."""
        goal = min(self.sc.task.target_volume, self.truck_spec.capacity)
        return next((t for t, load in self.curve if load >= goal - 1e-9), math.inf), -self.loaded

    def opening(self, visited: Visited) -> bool:
        if self.inner:
            return super().opening(visited)
        need = min(self.sc.task.target_volume, self.truck_spec.capacity) - self.loaded
        n = math.ceil(need / self.exc.bucket_capacity - 1e-9)
        acts: list[Act] = [lambda s, v: GreedySession.opening(s, v) or True, lambda s, v: True]  # greedy's own; staying
        bases = self._opening_stations(need)
        ranked = []
        for k in range(1, len(bases)):
            est = self._opening_estimate(Pose(float(bases[k, 0]), float(bases[k, 1]), self.base.yaw), need, n, moved=True)
            if est is not None:
                ranked.append((est[0], k, est[1]))
        for _, k, spots in sorted(ranked, key=lambda r: r[0])[:OPENING_STATIONS]:
            key = (round(float(bases[k, 0]), 3), round(float(bases[k, 1]), 3))
            for _, _, spot, _ in self._sliding_order(Pose(*key, self.base.yaw), spots, need, n)[1][:OPENING_STANDS]:
                acts.append(lambda s, v, key=key, spot=spot: _open_at(s, v, key, spot))
        tried = [(act, *got) for act in acts if (got := self._tried(act, visited)) is not None]
        return self._take(visited, tried)

    def relocate(self, visited: Visited, stay: bool = False, toward: tuple[float, float] | None = None) -> bool:
        if self.inner or stay:
            return super().relocate(visited, stay, toward)
        tried: list[Tried] = []
        passed: frozenset[tuple[float, float]] = frozenset()  # the stations of the candidates before
        for _ in range(RELOCATIONS):
            act: Act = lambda s, v, skip=passed: _relocate_past(s, v, skip)  # noqa: E731
            got = self._tried(act, visited)
            if got is None:
                break
            tried.append((act, *got))
            passed |= {(round(got[0].base.x, 3), round(got[0].base.y, 3))}
        return self._take(visited, tried) if tried else False

    def _tried(self, act: Act, visited: Visited) -> tuple[RolloutSession, Visited] | None:
        """A copy with ``act`` done and its visited set, for greedy to play out (None: ``act`` finds no move)."""
        s = copy.deepcopy(self, {id(self.sc): self.sc})  # the scenario is never changed: shared
        s.inner, v = True, set(visited)
        return (s, v) if act(s, v) else None

    def _take(self, visited: Visited, tried: list[Tried]) -> bool:
        """Play every tried candidate out; do the one that reaches the target soonest (the first on ties)."""
        if not tried:
            return False
        outcomes = []
        for _, s, v in tried:
            s.run(v)
            self.rollouts += 1
            outcomes.append(s.outcome())
        v = set(visited)
        moved = tried[outcomes.index(min(outcomes))][0](self, v)
        visited |= v
        return moved


def _open_at(s: RolloutSession, v: Visited, key: tuple[float, float], spot: Pose) -> bool:
    """The opening forced: the excavator to ``key``, the truck to ``spot``."""
    move = s._truck_move(Pose(*key, s.base.yaw), spots=[spot])
    if move is None:
        return False
    v.add(key)
    s._drive_in_turn(key, *move)
    return True


def _relocate_past(s: RolloutSession, v: Visited, skip: frozenset[tuple[float, float]]) -> bool:
    """Greedy's relocation with the earlier candidates' stations passed over (they stay visited,
    so the plan played out and the plan made agree)."""
    v |= skip
    return GreedySession.relocate(s, v)


def rollout_plan(sc: Scenario, cfg: GreedyConfig | None = None) -> tuple[Plan, int]:
    """The rollout's plan for ``sc`` (planned from ``sc`` as given) and how many rollouts it played;
    raises if greedy's own plan reaches the target sooner (the cost improvement above)."""
    cfg = cfg or GreedyConfig()
    s = RolloutSession(sc, cfg)
    plan = s.run()
    plain = RolloutSession(sc, cfg)
    plain.inner = True  # greedy itself, its dumps recorded
    plain.run()
    if s.outcome() > plain.outcome():
        raise AssertionError(f"the rollout's {s.outcome()} is behind greedy's {plain.outcome()}")
    return plan, s.rollouts
