"""STL-TAMP in receding horizon: the closed-loop mode of ``stl-tamp`` (docs/DESIGN.md §6).

The paper plans the whole task up front (Algorithm 1: a global problem over local areas, then
a local problem per area) and executes it open loop. Closed loop, each step is one pass of
Algorithm 1 on what is now observed: the candidate areas are tiled on the observed terrain,
the global problem over them is solved again for the volume still missing (the truck's
reported load, not the model's), the first area it chooses gets its local problem (the next
one, up to :data:`TRIES`, when it yields nothing), and that area's actions are the step. The
next step re-solves the remaining areas on the terrain the referee left, warm-started from the
previous solution: the areas it chose and did not dig yet lead the new tour, in its order, so
the global problem's initial guess is the previous plan's tail. Areas that yielded nothing are not chosen again;
when every area a solution chose yielded nothing, the step goes on over the other tiles without
the global problem (0.12.3, :func:`step`).
The areas face the sides of the first step (:class:`~.hierarchy.Layout`) in every step, as the
open-loop plan's face the scenario's: read again from where the truck stands after each area,
they turned to another side of the site and sent the excavator around it (0.10.2).

The volume model is corrected by what the truck reports: each step asks its local problem for
the missing volume divided by the ratio loaded so far ÷ the model's volume of the steps so far
(:meth:`Horizon.ask`), so a soil that fills the bucket less than the model expects is met by
larger digs in the area at hand, not by a tail of short steps. The run ends when the truck holds
the target, not within the open loop's ``volume_tol`` of it: short of the target by any amount,
a run has no time to it (docs/metrics.md). A step never asks for more than the truck surely
still takes (:func:`room`): a step digs up to four buckets, and a bucket dug after the truck is
full starts the next dig with material in it.

Only the planner's own functions are called (:meth:`StlTampPlanner._global`,
:meth:`StlTampPlanner._local` and :mod:`.hierarchy`); nothing of the open-loop path changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from earthbench.plan import Plan, Prediction
from earthbench.planner import Observation
from earthbench.soil import MATERIALS
from .surface import fit_rbf

from .convert import Converter, SimState
from .stand import stand_judge
from .stand import tour as seed_tour
from .hierarchy import (
    Area,
    Layout,
    Trace,
    global_blocks,
    global_lattice,
    in_box,
    nearest_block,
    site_box,
    site_layout,
)


#: Areas of one solution tried in a step before it gives up (each costs a local solve).
TRIES = 3
#: The observed yield ratio is trusted within these bounds (a first area's ratio can be noise).
YIELD_BOUNDS = (0.5, 1.5)
#: What a step asks for beyond the corrected missing volume: a share of it, and at least this
#: many m³, so that the scan's noise does not leave the truck a sliver short.
ASK_MARGIN, ASK_MIN = 0.05, 0.05
#: Earlier scans a stand's tilt is also judged on (:class:`.judge.StandJudge`), the latest so many.
SCANS_KEPT = 8


@dataclass
class Horizon:
    """What one closed-loop run of ``stl-tamp`` carries from step to step."""

    ahead: list[Area] = field(default_factory=list)  # the previous solution's chosen areas not yet dug
    done: list[tuple[float, float, float]] = field(default_factory=list)  # areas that yielded nothing: centre, drag heading
    joints: tuple[float, float] = (0.3, -1.5)
    trace: Trace = field(default_factory=Trace)
    layout: Layout | None = None  # the first step's sides, kept for the run
    modelled: float = 0.0  # the model's volume of the steps executed so far (m³)
    scans: list[np.ndarray] = field(default_factory=list)  # the earlier steps' scans, last SCANS_KEPT (0.13.0)

    def ask(self, observation: Observation) -> float:
        """The model volume a step plans for: the missing volume over the yield observed so far
        (truck-reported ÷ modelled), with :data:`ASK_MARGIN` and :data:`ASK_MIN`, and never more
        than :func:`room` at that yield."""
        ratio = observation.loaded / self.modelled if self.modelled > 0 and observation.loaded > 0 else 1.0
        ratio = min(max(ratio, YIELD_BOUNDS[0]), YIELD_BOUNDS[1])
        want = max(observation.remaining / ratio * (1 + ASK_MARGIN), observation.remaining + ASK_MIN)
        return min(want, room(observation) / ratio)


def room(observation: Observation) -> float:
    """Bank m³ the truck surely still takes: its capacity counts loose m³, so it is divided by the
    largest swell of the soil's class (the planner knows the class, not the site's value; a class
    it does not know: the swell it is told)."""
    sc = observation.scenario
    known = MATERIALS.get(sc.soil.material) if sc.soil is not None else None
    swell = known.swell[1] if known is not None else (sc.soil.swell if sc.soil is not None else 1.0)
    return sc.machines.truck.capacity / swell - observation.loaded


def step(planner, observation: Observation, h: Horizon) -> Plan | None:
    """One receding-horizon step of ``planner`` (a :class:`~.planner.StlTampPlanner`); None when
    done: the truck holds the target or is full, or every tile left has yielded nothing. When the
    global problem's pass gives nothing (its areas yield nothing and are marked, ``Horizon.done``,
    or it chooses none), the step goes on over the other tiles in the greedy tour's order, up to
    :data:`TRIES` local solves a pass, without the global problem, whose continuous areas can
    settle back on the fruitless ground (0.12.3: 0.12.2 ended the run there, at 0.40 of the
    target on one ``standard-realistic`` scan and with nothing loaded on four 20t ones)."""
    if observation.remaining <= 0.0 or observation.truck_full or room(observation) < ASK_MIN:
        return None
    first = True
    while True:
        tried = len(h.done)
        plan = _pass(planner, observation, h, first)
        if plan is not None or (not first and len(h.done) == tried):
            h.scans = [*h.scans, np.array(observation.scenario.terrain.z)][-SCANS_KEPT:]
            return plan
        first = False


def _pass(planner, observation: Observation, h: Horizon, use_global: bool) -> Plan | None:
    """One pass of Algorithm 1 over the tiles not yet found fruitless (``use_global``: with the
    global problem): the step's actions, or None."""
    c, sc = planner.config, observation.scenario
    exc = sc.machines.excavator
    remaining = h.ask(observation)
    st = SimState.start(sc)
    st.t, st.turn, st.loaded = observation.t, observation.turn, observation.loaded
    side = planner.area_side(sc)
    box = site_box(sc)
    conv = Converter(sc, eta_on=c.eta_on, min_dig_volume=c.min_dig_volume, depth=c.dig_depth, repair=c.repair,
                     retime=c.retime_moves, follow_face=c.follow_face, keep_soil=True)
    st.judge = stand_judge(c, sc, tuple(h.scans) if sc.soil is not None else ())
    if h.layout is None:
        h.layout = site_layout(sc)
    areas = [t for t in (_untried(a, h.done, side, c.swing_first) for a in planner.areas(sc, st.z, side, h.layout, st.judge))
             if t is not None]
    if not areas:
        return None
    vmax = c.area_vmax if len(areas) > 1 else max(c.area_vmax, c.m_local * exc.bucket_capacity)
    blocks = global_blocks(box, c.global_window)
    block = nearest_block(blocks, areas, (st.exc.x, st.exc.y))
    in_block = [a for a in areas if in_box(a.centre, block)]
    v_block = remaining if len(blocks) == 1 else min(remaining, c.block_fill * sum(a.estimate for a in in_block),
                                                     (c.block_phases - 1) * c.area_vmax)
    tour = _warm(seed_tour(c, in_block, (st.exc.x, st.exc.y), v_block, exc), h.ahead, side)
    if c.global_layer and use_global and len(tour) > 1:
        if len(blocks) == 1:
            surf = fit_rbf(sc.terrain.with_z(st.z), spacing=c.global_fit_spacing, solver="cholesky")
        else:
            surf = fit_rbf(sc.terrain.with_z(st.z), spacing=c.global_fit_spacing, window=block,
                           shape=global_lattice(c.global_window, c.global_fit_spacing), solver="cholesky")
        chosen, _ = planner._global(sc, st, surf, tour, v_block, side, box, block, len(blocks) > 1, h.trace)
    else:
        chosen = tour
    got, h.ahead, solved = 0.0, [], 0
    for k, area in enumerate(chosen):  # an area that yields nothing: on to the next the solution chose
        if solved == TRIES:  # an area passed over for want of a truck stand (0.12.1) is not a try
            break
        nxt = chosen[k + 1].base if k + 1 < len(chosen) else area.base
        passed = h.trace.standless.passed
        got, _, h.joints = planner._local(sc, st, conv, area, nxt, remaining, vmax, h.joints, box, h.trace)
        solved += h.trace.standless.passed == passed
        if got > c.volume_tol:
            h.ahead = chosen[k + 1:]
            break
        h.done.append((area.centre[0], area.centre[1], area.psi))
    if not st.actions:
        return None
    h.modelled += got
    return Plan(tuple(st.actions), Prediction(volume=got), {"planner": planner.name, "area": list(area.centre)})


def _untried(area: Area | None, done: list[tuple[float, float, float]], side: float, by_face: bool) -> Area | None:
    """``area``, or with ``by_face`` (0.13.0) the first of its fallbacks (``Area.toward``), not yet
    found fruitless: a tile facing away from the truck can yield nothing where the same tile
    facing it still yields (the base elsewhere, another stand); without, no face of the tile."""
    while area is not None:
        fruitless = [d for d in done if math.dist(area.centre, d[:2]) <= side / 2]
        if not fruitless or (by_face and all(abs(math.remainder(area.psi - d[2], 2 * math.pi)) >= math.pi / 2 for d in fruitless)):
            return area
        area = area.toward if by_face else None
    return None


def _warm(tour: list[Area], ahead: list[Area], side: float) -> list[Area]:
    """``tour`` with the areas near the previous solution's remaining choices first, in its order."""
    first: list[Area] = []
    for prev in ahead:
        near = [a for a in tour if a not in first and math.dist(a.centre, prev.centre) <= side / 2]
        if near:
            first.append(min(near, key=lambda a: math.dist(a.centre, prev.centre)))
    return first + [a for a in tour if a not in first]
