"""Property tests of the referee: conservation, the floor, capacity, and no broken limit passes."""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from earthbench import Dig, Dump, Move, Plan, judge
from earthbench_planners.greedy.backhoe import GreedyPlanner
from earthbench_terrains.rbf import rbf

SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@functools.cache
def site(floor: float):
    sc = rbf(7, 2.0, n_bases=14)
    return sc.replace(site=dataclasses.replace(sc.site, floor=floor))


digs = st.lists(
    st.tuples(
        st.floats(0.0, 12.0), st.floats(0.0, 6.0),  # contact
        st.floats(-math.pi, math.pi),  # heading
        st.floats(0.01, 1.5),  # depth, beyond the limit too
        st.floats(0.05, 1.5),  # drag length, beyond the limit too
        st.booleans(),  # dump after it
    ),
    min_size=1,
    max_size=12,
)


def random_plan(items) -> Plan:
    acts, t = [], 0.0
    for x, y, h, depth, drag, dump in items:
        acts.append(Dig("excavator", t, t + 1.0, (x, y), h, depth, drag))
        t += 1.0
        if dump:
            acts.append(Dump("excavator", t, t + 1.0))
            t += 1.0
    return Plan(tuple(acts))


@SETTINGS
@given(digs, st.sampled_from([0.0, 0.3, 0.6]))
def test_volume_is_conserved_and_nothing_goes_below_the_floor(items, floor):
    sc = site(floor)
    v = judge(sc, random_plan(items))
    lost = float((sc.terrain.z - v.final_terrain.z).sum() * sc.terrain.cell_area)
    assert math.isclose(lost, v.removed_volume, rel_tol=1e-9, abs_tol=1e-9)
    # no cell is raised, and no cell that started above the floor ends below it
    assert np.all(v.final_terrain.z <= sc.terrain.z + 1e-12)
    assert np.all(v.final_terrain.z >= np.minimum(sc.terrain.z, floor) - 1e-9)


@SETTINGS
@given(digs)
def test_loaded_volume_never_exceeds_digs_times_capacity(items):
    sc = site(0.0)
    v = judge(sc, random_plan(items))
    cap = sc.machines.excavator.bucket_capacity
    assert v.loaded_volume <= len(v.digs) * cap + 1e-9
    assert v.loaded_volume <= v.removed_volume + 1e-9
    assert all(d.volume <= cap + 1e-12 for d in v.digs)


@functools.cache
def greedy_case():
    sc = rbf(0, 1.4, n_bases=14)
    plan = GreedyPlanner().plan(sc)
    assert judge(sc, plan).valid
    return sc, plan


def break_limit(plan: Plan, pick: int, kind: str, amount: float) -> Plan | None:
    acts = list(plan.actions)
    a = acts[pick % len(acts)]
    k = acts.index(a)
    if kind == "faster" and isinstance(a, Move):
        t0 = a.path[0][0]
        acts[k] = Move(a.machine, tuple((t0 + (t - t0) / (1.01 + amount), x, y, w) for t, x, y, w in a.path))
    elif kind == "shorter" and not isinstance(a, Move):
        acts[k] = dataclasses.replace(a, t_end=a.t_end - 0.001 - amount)
    elif kind == "deeper" and isinstance(a, Dig):
        acts[k] = dataclasses.replace(a, depth=0.4 + 0.005 + amount)
    elif kind == "further" and isinstance(a, Dig):
        base = next(m for m in reversed(acts[:k]) if isinstance(m, Move) and m.machine == "excavator").path[-1] if any(
            isinstance(m, Move) and m.machine == "excavator" for m in acts[:k]) else (0, 13.0, 7.2, math.pi)
        dx, dy = a.contact[0] - base[1], a.contact[1] - base[2]
        r = math.hypot(dx, dy)
        s = (6.1 + 0.01 + amount) / r
        acts[k] = dataclasses.replace(a, contact=(base[1] + dx * s, base[2] + dy * s))
    elif kind == "sideways" and isinstance(a, Move):
        t, x, y, w = a.path[-1]
        d = 0.06 + amount
        acts[k] = Move(a.machine, a.path[:-1] + ((t, x - d * math.sin(w), y + d * math.cos(w), w),))
    else:
        return None
    return Plan(tuple(acts))


@SETTINGS
@given(st.integers(0, 10_000), st.sampled_from(["faster", "shorter", "deeper", "further", "sideways"]), st.floats(0.0, 0.5))
def test_a_plan_with_a_broken_limit_is_never_valid(pick, kind, amount):
    sc, plan = greedy_case()
    broken = break_limit(plan, pick, kind, amount)
    if broken is None:
        return
    assert not judge(sc, broken).valid


@SETTINGS
@given(contact=st.tuples(st.floats(0.0, 12.0), st.floats(0.0, 6.0)), heading=st.floats(-math.pi, math.pi),
       length=st.floats(0.05, 1.5), depth=st.floats(-0.2, 1.0), capacity=st.floats(0.0, 0.6), per_cell=st.booleans())
def test_a_dry_run_of_the_cut_says_exactly_what_the_cut_does_and_cuts_nothing(contact, heading, length, depth, capacity, per_cell):
    """``cut_along(apply=False)``, the referee's prediction of a nominal volume with soil, gives
    the very ``Cut`` of the real one (bit for bit) and leaves the grid as it was."""
    from earthbench.cut import cut_along, cut_level, path_cells

    sc = site(-10.0)
    t = sc.terrain
    z = np.array(t.z)
    level = cut_level(t, z, contact, depth)
    cells = path_cells(t, z.shape, contact, heading, 0.7, length)
    if per_cell:  # one level per path cell, as the harder layer gives
        level = level + np.linspace(0.0, 0.1, cells[0].size)
    dry = cut_along(t, z, contact, heading, 0.7, length, level, capacity, cells, apply=False)
    assert np.array_equal(z, t.z)
    wet = cut_along(t, z, contact, heading, 0.7, length, level, capacity, cells)
    assert dry == wet
