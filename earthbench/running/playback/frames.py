"""A plan's effect action by action, as the referee judged it (:func:`changes`, :func:`replay`):
the frames come from the one judgement's observer, never from a second cut model."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...cut import path_window
from ...plan import Plan
from ...referee import Verdict, judge
from ...world import Scenario

from .geometry import bucket_path


@dataclass(frozen=True)
class Step:
    """The state after one action (``action``: its index in the plan), in the referee's order."""

    action: int
    z: np.ndarray  # the heightmap after the action
    loaded: float  # m³ in the truck after the action


@dataclass(frozen=True)
class Change:
    """What one action did, in the referee's order: the m³ in the truck after it and, if it
    changed the ground, the smallest window ``(rows, cols)`` holding every changed cell with
    the heights there after it (``z``)."""

    action: int
    loaded: float
    window: tuple[slice, slice] | None = None
    z: np.ndarray | None = None


def changes(scenario: Scenario, plan: Plan) -> tuple[Verdict, list[Change]]:
    """The referee's verdict and, from the same judgement, what each action changed.

    Only a dig or a charge cuts, and only inside its bucket's path window
    (:func:`earthbench.cut.path_window`), so a step costs that window, not the whole map: a
    plan of thousands of digs on a 96 × 48 m map replays in about one judgement's time and
    keeps only the windows.
    """
    before = np.array(scenario.terrain.z, dtype=np.float64)  # the ground as the last step left it
    out: list[Change] = []

    def observe(n: int, z: np.ndarray, loaded: float) -> None:
        path = bucket_path(scenario, plan.actions[n])
        if path is not None:
            rows, cols = path_window(scenario.terrain, z.shape, *path)
            diff = z[rows, cols] != before[rows, cols]
            if diff.any():
                jj, ii = np.nonzero(diff)
                window = (slice(rows.start + int(jj.min()), rows.start + int(jj.max()) + 1),
                          slice(cols.start + int(ii.min()), cols.start + int(ii.max()) + 1))
                before[window] = z[window]
                out.append(Change(n, loaded, window, before[window].copy()))
                return
        out.append(Change(n, loaded))

    verdict = judge(scenario, plan, observe)
    if len(out) != len(plan.actions):  # a malformed plan: nothing happened
        order = sorted(range(len(plan.actions)), key=lambda n: (plan.actions[n].t_start, n))
        out = [Change(n, 0.0) for n in order]
    return verdict, out


def replay(scenario: Scenario, plan: Plan) -> tuple[Verdict, list[Step]]:
    """The referee's verdict on the whole plan and the state after each action, in time order
    (:func:`changes` made into whole heightmaps; an action that cut nothing shares the one before)."""
    verdict, steps = changes(scenario, plan), []
    z = scenario.terrain.z
    for c in verdict[1]:
        if c.window is not None:
            z = z.copy()
            z[c.window] = c.z
        steps.append(Step(c.action, z, c.loaded))
    return verdict[0], steps
