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
- :mod:`earthbench.referee.state` — the replay state and the rules all machines share: speed, yaw rate, heading,
  keep-out zones and the map's edge along the footprint's swept path, and clearance between
  machines checked along both swept paths at once;
- :mod:`earthbench.referee.backhoe` — digs and dumps of the excavator (reach, depth, drag, dig
  area, floor, undermining, tilt, durations);
- :mod:`earthbench.referee.loader` — the wheel loader's charges, dumps, turning radius and the
  step of its wheels;
- :mod:`earthbench.referee.site` — no machine under a dig's bucket or arm, and the truck's
  ground (rules version 2, :data:`RULES_VERSION`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np

from ..errors import PlanFormatError
from ..lazy import moved_getattr
from ..motion import ABS_TOL, RATE_TOL
from ..plan import Action, Charge, Dig, Dump, Move, Plan
from ..world import LoaderSpec, Scenario, TruckSpec
from .state import RULES, RULES_VERSION, DigRecord, Replay, Verdict, Violation

__all__ = ["ABS_TOL", "RATE_TOL", "RULES", "RULES_VERSION", "DigRecord", "Execution", "Observer", "Verdict", "Violation", "judge"]

#: The cut model was documented here until 0.1.0 and moved to :mod:`earthbench.cut` (0.2.0);
#: a plugin that imports it from here still runs, with a DeprecationWarning.
__getattr__ = moved_getattr(__name__, dict.fromkeys(("apply_cut", "charge_cut", "cut_level", "footprint"), "earthbench.cut")
                            | {"LOADER_DUMP_HALF_ANGLE": "earthbench.motion"})


#: Called after each action, in the referee's time order, with the action's index, the heightmap
#: as it then stands (read-only, current only during the call) and the m³ in the truck.
Observer = Callable[[int, np.ndarray, float], None]


def _act(r: Replay, indices: Iterable[int], observe: Observer | None = None) -> None:
    """Replay the plan's actions ``indices`` in time order, telling ``observe`` after each."""
    plan = r.plan
    z = r.z.view()  # the rules cut r.z in place, so this view stays current
    z.flags.writeable = False
    for n in sorted(indices, key=lambda n: (plan.actions[n].t_start, n)):
        a = plan.actions[n]
        if a.machine not in r.pose:
            r.flag(n, "unknown_machine", 1.0, f"no machine {a.machine!r}; on site: {', '.join(r.pose)}")
        else:
            _apply(r, n, a)
        if observe is not None:
            observe(n, z, r.loaded)


def _apply(r: Replay, n: int, a: Action) -> None:
    # each track's rules load with the first judgement, not with every planner that calls one
    # of them (a case's start-up, issue 18)
    from . import backhoe, loader, site

    if a.t_start < r.busy_until[a.machine] - ABS_TOL:
        gap = r.busy_until[a.machine] - a.t_start
        r.flag(n, "overlap", gap, f"{a.machine} is busy until t={r.busy_until[a.machine]:.3f} s")
    spec = r.specs.get(a.machine)
    if isinstance(a, Move):
        arc = r.move(n, a)
        if isinstance(spec, LoaderSpec):
            loader.move(r, n, a, spec, arc)
        elif isinstance(spec, TruckSpec):
            site.truck_path(r, n, np.array(a.path, dtype=float), arc)
    elif isinstance(a, Dig):
        backhoe.dig(r, n, a)
    elif isinstance(a, Dump):
        if isinstance(spec, LoaderSpec):
            loader.dump(r, n, a, spec)
        elif a.machine == "excavator" and spec is not None:
            backhoe.dump(r, n, a, spec)  # type: ignore[arg-type]
        else:
            r.flag(n, "wrong_machine", 1.0, f"{a.machine} cannot dump into the truck")
    elif isinstance(a, Charge):
        loader.charge(r, n, a)
    r.busy_until[a.machine] = max(r.busy_until[a.machine], a.t_end)


def _run(r: Replay, observe: Observer | None = None) -> Verdict:
    _act(r, range(len(r.plan.actions)), observe)
    r.collisions()
    return r.verdict()


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
        r = self.replay
        _act(r, r.extend(actions))
        kept = len(r.violations)
        r.collisions()  # along the whole of both paths so far; checked again after the next step
        verdict = r.verdict()
        del r.violations[kept:]
        return verdict


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
    return _run(Replay(scenario, plan), observe)
