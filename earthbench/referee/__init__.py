"""The independent referee: replays a plan on a copy of the heightmap and judges it.

The referee, not the planner, decides what happened (docs/DESIGN.md §5). It replays actions in time order, applies
every dig and charge to the grid with the cut model of :mod:`earthbench.cut`, transfers dumped
material to the truck, and records every broken rule as a :class:`Violation` (action index,
rule, magnitude). A plan with any violation is invalid: reported, never ranked.

The contract is public, module by module, so that planners call the rules instead of
re-deriving them:

- :mod:`earthbench.motion` — the motion model between move samples (one arc per pair, which
  every rule samples densely), minimum dig and dump durations, dump reach, the tolerances
  ``ABS_TOL`` and ``RATE_TOL``;
- :mod:`earthbench.cut` — the cut model (``apply_cut``, ``charge_cut``);
- :mod:`earthbench.rules` — the predicates the rules are made of, which planners call too
  (footprints touching, the excavator's stand and undermining line, the loader's step);
- :mod:`earthbench.referee.state` — the replay state (plain data), the verdict and the rules' names;
- :mod:`earthbench.referee.loop` — the one loop that replays the actions in time order, hands
  each to the rules below and alone advances the state;
- :mod:`earthbench.referee.paths` — the rules all machines share along a path: speed, yaw rate,
  heading, keep-out zones and the map's edge along the footprint's swept path;
- :mod:`earthbench.referee.clearance` — clearance between machines along both swept paths at once;
- :mod:`earthbench.referee.backhoe` — digs and dumps of the excavator (reach, depth, drag, dig
  area, floor, undermining, tilt, durations);
- :mod:`earthbench.referee.loader` — the wheel loader's charges, dumps, turning radius and the
  step of its wheels;
- :mod:`earthbench.referee.site` — no machine under a dig's bucket or arm (rules version 2,
  :data:`RULES_VERSION`);
- :mod:`earthbench.referee.truck` — the truck's ground where it drives, and standing still for a dump;
- :mod:`earthbench.referee.ground` — the cut itself (with soil: its truth and slump) and the
  truck's ground left as it was.
"""

from __future__ import annotations

from ..errors import PlanFormatError
from .. import compat
from ..motion import ABS_TOL, RATE_TOL
from ..plan import Action, Plan
from ..world import Scenario
from .state import RULES, RULES_VERSION, DigRecord, Observer, Replay, Verdict, Violation

__all__ = ["ABS_TOL", "RATE_TOL", "RULES", "RULES_VERSION", "DigRecord", "Execution", "Observer", "Verdict", "Violation", "judge"]

#: The cut model was documented here until 0.1.0 (earthbench.compat keeps the old names).
__getattr__ = compat.forward(__name__)


class Execution:
    """A plan judged step by step, as a closed loop executes it (docs/DESIGN.md §6).

    Each :meth:`execute` replays one step's actions after those before, on the same replay
    state, and returns the verdict :func:`judge` gives the plan executed so far — in time
    linear in the step, not in the plan. The steps' actions must start no earlier than the
    plan so far ends (the harness checks that before it executes a step).
    """

    def __init__(self, scenario: Scenario):
        self.replay = Replay(scenario, Plan())

    @property
    def plan(self) -> Plan:
        return self.replay.plan

    def execute(self, actions: tuple[Action, ...]) -> Verdict:
        from . import loop

        return loop.execute(self.replay, actions)


def judge(scenario: Scenario, plan: Plan | dict | str, observe: Observer | None = None) -> Verdict:
    """Replay ``plan`` on ``scenario`` and return the verdict.

    ``plan`` may be a :class:`Plan`, a plan document (dict) or JSON text; a document that
    cannot be read gives an invalid verdict with a ``malformed`` violation, never an exception
    (and ``observe`` is never called). ``observe`` sees the replay's state after every action
    (:data:`Observer`), so the replay viewer's frames come from this one judgement.
    """
    try:
        if isinstance(plan, Plan):  # built in code: check its form the same way as a document's
            plan = Plan.from_dict(plan.to_dict())
        else:
            plan = Plan.from_dict(plan) if isinstance(plan, dict) else Plan.from_json(plan)
    except (PlanFormatError, TypeError, ValueError, AttributeError) as exc:
        v = Violation(None, "malformed", 1.0, str(exc))
        return Verdict((v,), scenario.terrain, 0.0, 0.0, 0.0)
    from . import loop  # the loop and the rules load with the first judgement (a case's start-up, issue 18)

    return loop.run(Replay(scenario, plan), observe)
