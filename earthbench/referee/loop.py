"""The one loop that replays a plan (docs/DESIGN.md §5): it takes the actions in time order,
hands each to the rules of its kind and its machine, and alone advances the state
(:class:`~earthbench.referee.state.Replay`): machines move, cuts are made, buckets fill and
empty. The rule modules read the state and append what they find; none calls another back.

For each action, in this order: the machine exists and is free (here); a move's shared rules
(:mod:`~earthbench.referee.paths`), then its machine's (:mod:`~earthbench.referee.loader`,
:mod:`~earthbench.referee.truck`); a dump's truck standing still, then the dumping machine's
rules; a dig's or charge's rules before the cut (:mod:`~earthbench.referee.backhoe`,
:mod:`~earthbench.referee.loader`, which ask :mod:`~earthbench.referee.site` about the machines
near it), the cut (:mod:`~earthbench.referee.ground`), the track's rules on the fresh cut, the
slump and the truck's ground. After the last action, clearance between the machines along both
paths (:mod:`~earthbench.referee.clearance`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable

import numpy as np

from ..motion import ABS_TOL
from ..plan import Action, Charge, Dig, Dump, Move, Plan
from ..world import LoaderSpec, Pose, TruckSpec
from . import backhoe, clearance, ground, loader, paths, truck
from .state import DigRecord, Observer, Replay, Stroke, Verdict, Violation, timelines


def run(r: Replay, observe: Observer | None = None) -> Verdict:
    """Replay the whole plan of ``r`` and return the verdict."""
    replay(r, range(len(r.plan.actions)), observe)
    clearance.collisions(r)
    return verdict(r)


def replay(r: Replay, indices: Iterable[int], observe: Observer | None = None) -> None:
    """Replay the plan's actions ``indices`` in time order, telling ``observe`` after each."""
    plan = r.plan
    z = r.z.view()  # the cuts change r.z in place, so this view stays current
    z.flags.writeable = False
    for n in sorted(indices, key=lambda n: (plan.actions[n].t_start, n)):
        a = plan.actions[n]
        if a.machine not in r.pose:
            r.violations.append(Violation(n, "unknown_machine", 1.0, f"no machine {a.machine!r}; on site: {', '.join(r.pose)}"))
        else:
            _step(r, n, a)
        if observe is not None:
            observe(n, z, r.loaded)


def _step(r: Replay, n: int, a: Action) -> None:
    """One action: the rules of its kind and machine, and what it does to the state."""
    if a.t_start < r.busy_until[a.machine] - ABS_TOL:
        gap = r.busy_until[a.machine] - a.t_start
        r.violations.append(Violation(n, "overlap", float(gap), f"{a.machine} is busy until t={r.busy_until[a.machine]:.3f} s"))
    spec = r.specs.get(a.machine)
    if isinstance(a, Move):
        arc = paths.move(r, n, a)
        p = a.path[-1]
        r.travel[a.machine] += float(arc["length"].sum())
        r.pose[a.machine] = Pose(float(p[1]), float(p[2]), float(p[3]))
        if isinstance(spec, LoaderSpec):
            loader.act(r, n, a, arc)
        elif isinstance(spec, TruckSpec):
            truck.path(r, n, np.array(a.path, dtype=float), arc)
    elif isinstance(a, Dump):
        if isinstance(spec, LoaderSpec) or (a.machine == "excavator" and spec is not None):
            truck.still(r, n, a)
            if isinstance(spec, LoaderSpec):
                loader.act(r, n, a, None)
            else:
                backhoe.act(r, n, a)
            _empty_bucket(r, a)
        else:
            r.violations.append(Violation(n, "wrong_machine", 1.0, f"{a.machine} cannot dump into the truck"))
    elif isinstance(a, Dig):
        if (stroke := backhoe.act(r, n, a)) is not None:
            _cut(r, n, a, stroke, backhoe.after_cut)
    elif isinstance(a, Charge):
        if (stroke := loader.act(r, n, a, None)) is not None:
            _cut(r, n, a, stroke, loader.after_cut)
    r.busy_until[a.machine] = max(r.busy_until[a.machine], a.t_end)


def _cut(r: Replay, n: int, a: Dig | Charge, stroke: Stroke, after_cut: Callable[..., None]) -> None:
    """Make a dig's or charge's cut, check what it left, and fill the bucket."""
    got, nominal = ground.cut(r, stroke)
    after_cut(r, n, a, stroke, got, nominal)
    ground.settle(r, n, stroke.stands)
    r.bucket += got.volume
    r.removed += got.volume
    r.digs.append(DigRecord(n, got.volume, got.volume / stroke.capacity, None if nominal is None else nominal.volume))
    if stroke.base is not None:  # the excavator's upper body turns to the dig
        base = stroke.base
        r.turn = math.atan2(stroke.contact[1] - base.y, stroke.contact[0] - base.x) - base.yaw
    if isinstance(a, Charge):  # the loader drives through the charge
        r.travel[a.machine] += a.penetration
        r.pose[a.machine] = Pose(a.end[0], a.end[1], a.entry[2])  # a charge holds its heading


def _empty_bucket(r: Replay, a: Dump) -> None:
    """A dump moves the bucket's load into the truck, up to its capacity; the excavator's upper body turns to the truck."""
    take = min(r.bucket, max(r.truck_capacity - r.loaded, 0.0))
    r.loaded += take
    r.bucket -= take
    r.dumps += 1
    r.load_curve.append((a.t_end, r.loaded))
    if a.machine == "excavator":
        base, tpos = r.timelines[a.machine].pose(a.t_start), r.timelines["truck"].pose(a.t_start)
        r.turn = math.atan2(tpos.y - base.y, tpos.x - base.x) - base.yaw


def execute(r: Replay, actions: tuple[Action, ...]) -> Verdict:
    """Append a closed-loop step's actions to the plan being replayed (docs/DESIGN.md §6),
    replay them, and return the verdict on the plan so far. They start no earlier than the plan
    so far ends, so replaying them next gives the state a replay of the whole plan would;
    clearance is checked along the whole of both paths so far and again after the next step."""
    n0 = len(r.plan.actions)
    r.plan = Plan(r.plan.actions + tuple(actions))
    r.timelines = timelines(r.sc, r.plan)
    replay(r, range(n0, len(r.plan.actions)))
    kept = len(r.violations)
    clearance.collisions(r)
    found = verdict(r)
    del r.violations[kept:]
    return found


def verdict(r: Replay) -> Verdict:
    """What the replay measured so far."""
    return Verdict(
        violations=tuple(r.violations),
        final_terrain=r.terrain.with_z(r.z),
        loaded_volume=r.loaded,
        removed_volume=r.removed,
        makespan=r.plan.makespan,
        digs=tuple(r.digs),
        dumps=r.dumps,
        travel=r.travel,
        load_curve=tuple(r.load_curve),
        final_poses={mid: tl.pose(r.plan.makespan) for mid, tl in r.timelines.items()},
        final_turn=r.turn,
        final_bucket=r.bucket,
    )
