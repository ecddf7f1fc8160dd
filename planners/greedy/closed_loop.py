"""What greedy keeps from step to step in closed loop (docs/DESIGN.md §6)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from earthbench.plan import Dig, Plan

#: A dig whose dump raised the truck's reported load by less than this share of what the
#: planner's model cut marks its contact barren.
BARREN_SHARE = 0.25


@dataclass
class Carried:
    """The stations visited, and the contacts whose dig came back (nearly) empty by the truck's
    load: ground harder than the scan shows, which the next scan shows unchanged, so greedy would
    dig there again (1.5 did, until the harness's step cap, on two 20t scans). ``last``: the last
    dig's contact, the volume the model cut and the load before it, judged at the next step."""

    visited: set[tuple[float, float]] = field(default_factory=set)
    barren: list[tuple[float, float]] = field(default_factory=list)
    last: tuple[tuple[float, float], float, float] | None = None

    def judge_last(self, loaded: float) -> None:
        """Mark the last dig's contact barren when ``loaded``, the load now reported, shows it came back empty."""
        if self.last is not None:
            contact, cut, before = self.last
            if loaded - before < BARREN_SHARE * cut:
                self.barren.append(contact)
            self.last = None

    def remember(self, plan: Plan, cut: float, before: float) -> None:
        """Keep the step's last dig (``cut``: the volume the model cut; ``before``: the load at the step's start)."""
        digs = [a for a in plan.actions if isinstance(a, Dig)]
        self.last = (digs[-1].contact, cut, before) if digs else None


def away_from(points: np.ndarray, barren: list[tuple[float, float]], distance: float) -> np.ndarray:
    """Which of ``points[k, 2]`` lie at least ``distance`` from every barren contact."""
    if not barren:
        return np.ones(len(points), bool)
    b = np.asarray(barren)
    return np.hypot(points[:, 0, None] - b[:, 0], points[:, 1, None] - b[:, 1]).min(axis=1) >= distance
