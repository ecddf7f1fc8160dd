"""stl-tamp: small real solves on 14-basis maps (the paper's task-switching maps)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from hypothesis import given, settings
from hypothesis import strategies as hst

from earthbench import Move, Plan
from earthbench.motion import arcs
from earthbench.referee import judge
from earthbench.registry import PLANNERS
from earthbench_planners.separate.planner import SeparatePlanner
from earthbench_planners.stl_tamp import Config, StlTampPlanner, StlTampSolveError, TargetTooLargeError
from earthbench_planners.stl_tamp.convert import Converter, SimState, fastest_steps, integrate, min_distance
from earthbench_planners.stl_tamp.guess import build_guess, fill_volumes, settle_contacts
from earthbench_planners.stl_tamp.hierarchy import candidate_areas, local_seeds, site_box, site_layout
from earthbench_planners.stl_tamp.model import tip_position
from earthbench_planners.stl_tamp.problem import inverse_kinematics
from earthbench_terrains.rbf import rbf
from earthbench_planners.stl_tamp.surface import fit_rbf

import casadi as ca

from helpers import block_scenario
from helpers.stl_tamp import richest_local_area


@pytest.fixture(scope="module")
def local_setup():
    """The local NLP (built once, as in a run), the richest area of a 14-basis map, its fit."""
    return richest_local_area()


def _solve(local_setup, target, *, k_active=5, eta0=1.0, fixed=None, max_iter=300):
    sc, pl, nlp, st, area, surf = local_setup
    c = pl.config
    cap = sc.machines.excavator.bucket_capacity
    seeds = local_seeds(area, k_active, c.m_local, 0.7, 1.0, surf, eta0, area.truck)
    p = nlp.pack_p(w=surf.weights.reshape(-1), o=(surf.x0, surf.y0), s0=st.s0, vt=target,
                   alpha=(c.alpha_u, c.alpha_t, c.alpha_v, c.alpha_eta, 0.0), goal=area.base, floor=0.0)
    seeds = settle_contacts(nlp, st.s0, seeds, 0.0, p)
    w0 = fill_volumes(nlp, build_guess(nlp, st.s0, seeds, 0.0), p, [eta0 * cap] * c.m_local)
    cx, cy = area.centre
    box = (cx - 1.45, cx + 1.45, cy - 1.45, cy + 1.45)
    return nlp.solve(p, w0, box, fixed_tasks=fixed, max_iter=max_iter, options=pl._ipopt_options())


def test_registered_as_stl_tamp():
    assert PLANNERS.get("stl-tamp") is StlTampPlanner


def test_inverse_kinematics_reaches_the_point():
    spec = rbf(0, 1.0).machines.excavator
    s = ca.SX.sym("s", 9)
    tip = ca.Function("tip", [s], [ca.vertcat(*tip_position(s, spec))])
    for r, z in ((3.0, -1.0), (5.5, -1.4), (4.0, 1.0)):
        boom, arm = inverse_kinematics(r, z, spec)
        t = np.array(tip([0, 0, 0.3, 0.0, boom, arm, 0, 0, 0])).ravel()
        assert math.hypot(t[0], t[1]) == pytest.approx(r, abs=1e-6)
        assert t[2] - 1.5 == pytest.approx(z, abs=1e-6)


def test_local_solve_meets_the_volume_and_its_specs(local_setup):
    # an area's usual local problem, posed as the planner poses it: its V_max as the target,
    # seeded with as many digs as that takes at the estimated fill, at the planner's η guess
    c = Config()
    k = min(c.m_local, math.ceil(c.area_vmax / (0.28 * c.fill_estimate)))
    sol = _solve(local_setup, c.area_vmax, k_active=k, eta0=c.eta_init)
    assert sol.success, sol.status
    assert float(np.sum(sol.V)) == pytest.approx(c.area_vmax, abs=0.02)
    assert np.all(sol.V <= 0.28 + 1e-6)
    sc, pl, nlp, st, area, surf = local_setup
    ev = nlp.evaluate(sol.info["w"], nlp.pack_p(w=surf.weights.reshape(-1), o=(surf.x0, surf.y0), s0=st.s0, vt=c.area_vmax,
                                                alpha=(0, 0, 0, 0, 0), goal=area.base, floor=0.0))
    # exact (not smoothed) robustness of the safety spec holds on the solution; the task spec
    # is smooth inside its disjunction/finally and may miss the exact value by its log(N)/β bound
    assert ev["rho_safe"] > 0
    assert ev["rho_task"] > -math.log(10) / pl.config.beta
    # the base is still at every work step, and every node pair is a unicycle chord
    dt = np.diff(sol.times)
    for i in range(1, nlp.m1):
        for k in range(nlp.kc[i], nlp.n):
            assert abs(sol.U[i * nlp.n + k, 0]) < 1e-6 and abs(sol.U[i * nlp.n + k, 1]) < 1e-6
    assert np.all(dt > 0)


@pytest.mark.parametrize("buckets", [2, 3, 4])
def test_paper_switch_digs_the_minimum_number_of_buckets(buckets):
    """Fig. 6 on the ``paper-switch`` set-up (one 2.0 m × 1.75 m local area): of the m_l = 4
    phases it may use, the plan digs exactly as many as the target has buckets, and the referee
    measures the target. The switch variables select at least those phases; η acts as a depth
    fraction, so the NLP may spread the volume over one more partial phase, which the conversion
    (full-depth digs until the target is met) leaves out. In the published ``standard`` run
    (0.5.0) 29 of the 30 paper-switch plans dig the minimum, and 26 of 30 local problems select
    exactly that many phases; two seeds here."""
    for seed in (0, 4):
        sc = rbf(seed, buckets * 0.28, n_bases=14, local_area=(2.0, 1.75))
        plan = StlTampPlanner().plan(sc)
        v = judge(sc, plan)
        assert v.valid, v.violations[:3]  # stands too steep for the tilt rule are never used
        assert v.loaded_volume == pytest.approx(buckets * 0.28, abs=0.01)
        assert plan.info["digs"] == buckets
        # 0.6.0: the one area's local problem sometimes stops at the acceptable level short of
        # the target (seeds 0 and 4 at 2 buckets); a second solve on the lowered grid takes the
        # rest, and the phases selected over both are still at least the buckets
        assert buckets <= sum(e >= Config().eta_on for r in plan.info["local"] for e in r["eta"])
        assert plan.info["global"]["used"] is False  # one area: nothing for the global layer to choose


def test_fixed_tasks_reuse_the_same_nlp(local_setup):
    """The ``separate`` baseline: η and contacts fixed through bounds, motions optimised."""
    sc, pl, nlp, st, area, surf = local_setup
    c = pl.config
    # the base stands still after phase 0: a fixed drag heading must lie on the radial line
    seeds = [dataclasses.replace(s, psi=math.atan2(area.base[1] - s.py, area.base[0] - s.px))
             for s in local_seeds(area, 2, 5, 0.7, 1.0, surf, 1.0, area.truck)]
    p = nlp.pack_p(w=surf.weights.reshape(-1), o=(surf.x0, surf.y0), s0=st.s0, vt=0.5,
                   alpha=(c.alpha_u, c.alpha_t, 0.0, 0.0, 0.0), goal=area.base, floor=0.0)
    seeds = settle_contacts(nlp, st.s0, seeds, 0.0, p)
    w0 = fill_volumes(nlp, build_guess(nlp, st.s0, seeds, 0.0), p)  # η with model volume 0.95 V_max
    sl = nlp._slices()
    eta = w0[sl["eta"]][1:]
    fixed = {"eta": eta, "px": [s.px for s in seeds], "py": [s.py for s in seeds], "psi": [s.psi for s in seeds]}
    cx, cy = area.centre
    # separate's trust-region rounds (plain IPOPT strays from the feasible guess into the dead
    # branch of the disjunction, see SeparatePlanner._solve)
    sol, _ = SeparatePlanner()._solve(nlp, p, w0, st.s0, (cx - 1.45, cx + 1.45, cy - 1.45, cy + 1.45),
                                      {k: np.asarray(v, float) for k, v in fixed.items()})
    assert sol.success, sol.status
    assert np.allclose(sol.eta[1:], eta)
    assert np.allclose(sol.px[1:], fixed["px"]) and np.allclose(sol.py[1:], fixed["py"])
    assert int(np.sum(sol.eta[1:] >= 0.25)) == 2


def test_whole_plan_is_valid_and_meets_the_target():
    sc = rbf(1, 1.5, n_bases=14)
    plan = StlTampPlanner(global_layer=False).plan(sc)
    v = judge(sc, plan)
    assert v.valid, v.violations[:3]
    assert v.loaded_volume / 1.5 == pytest.approx(1.0, abs=0.02)
    assert plan.predicted.volume == pytest.approx(v.loaded_volume, abs=1e-9)
    assert plan.predicted.makespan == pytest.approx(v.makespan, abs=1e-9)
    assert plan.info["local"] and all("status" in r for r in plan.info["local"])


def test_failed_solve_is_a_clear_exception():
    sc = rbf(1, 1.0, n_bases=14)
    pl = StlTampPlanner(global_layer=False, max_iter=2, on_failure="raise", accept_feasible=0.0)
    with pytest.raises(StlTampSolveError, match="local solve .* failed: IPOPT"):
        pl.plan(sc)


def test_fallbacks_are_bounded():
    """Past the bound a failed area is left undug: no more guesses are executed, no error."""
    sc = rbf(1, 3.0, n_bases=14)
    plan = StlTampPlanner(global_layer=False, max_iter=2, accept_feasible=0.0, max_fallbacks=1).plan(sc)
    recs = plan.info["local"]
    assert plan.info["fallbacks"] == 1 and plan.info["local_solves"]["fallback"] == 1
    skipped = [r for r in recs if "skipped" in r]
    assert skipped and all(r["loaded"] == 0.0 and "1 of 1" in r["skipped"] for r in skipped)
    assert judge(sc, plan).valid


def test_target_larger_than_the_site_holds():
    from earthbench.world import Task

    sc = rbf(0, 1.0, n_bases=14).replace(task=Task(10_000.0))  # the generator itself refuses such targets
    with pytest.raises(TargetTooLargeError, match="exceeds"):
        StlTampPlanner().plan(sc)


def test_min_distance_is_continuous():
    a = [(0.0, -5.0, 0.0, 0.0), (10.0, 5.0, 0.0, 0.0)]
    from earthbench.world import Pose

    assert min_distance(a, Pose(0.0, 1.0, 0.0)) == pytest.approx(1.0)
    b = [(0.0, 5.0, 0.5, 0.0), (10.0, -5.0, 0.5, 0.0)]
    assert min_distance(a, b) == pytest.approx(0.5)


def test_config_is_a_frozen_dataclass_with_paper_defaults_but_the_documented_horizon():
    """The paper's area (S_l = 5 buckets, V_max = 1 m³); the local horizon is the documented
    departure (m_l = 4, n = 8; planners/stl_tamp/NOTES.md), and ``separate`` keeps the paper's 5 and 10."""
    from earthbench_planners.separate.planner import Config as SeparateConfig

    c = Config()
    assert (c.m_local, c.n_steps, c.contact_step, c.area_vmax, c.area_buckets) == (4, 8, 3, 1.0, 5.0)
    s = SeparateConfig()
    assert (s.m_local, s.n_steps, s.contact_step) == (5, 10, 4)
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.m_local = 3  # type: ignore[misc]


step = hst.tuples(hst.floats(-1.0, 1.0), hst.floats(-1.0, 1.0), hst.floats(0.02, 3.0))


@settings(max_examples=60, deadline=None)
@given(hst.lists(step, min_size=1, max_size=8))
def test_retimed_moves_keep_the_path_within_the_limits(steps):
    """The converter's retiming: the same nodes, never slower than the NLP's pace unless that
    drives the arc (the referee's motion model) over a limit, and the referee finds no move
    rule broken (speed, yaw rate, sideways slip) however the NLP had paced them."""
    sc = block_scenario()
    spec = sc.machines.excavator
    v = np.array([a for a, _, _ in steps]) * spec.travel_speed
    w = np.array([b for _, b, _ in steps]) * spec.yaw_rate
    dts = np.array([d for _, _, d in steps])
    nodes = integrate(sc.machines.excavator_pose, v, w, dts, spec.travel_speed, spec.yaw_rate)
    fast = fastest_steps(nodes, dts, spec.travel_speed, spec.yaw_rate)
    length = arcs(np.column_stack([np.arange(len(nodes), dtype=float), nodes]))["length"]
    limit = np.maximum(length / (spec.travel_speed * 0.999), np.abs(np.diff(nodes[:, 2])) / (spec.yaw_rate * 0.999))
    assert np.all((fast <= dts) | np.isclose(fast, limit)) and np.all(fast > 0)
    times = np.concatenate([[0.0], np.cumsum(fast)])
    move = Move("excavator", tuple((float(t), float(x), float(y), float(yaw)) for t, (x, y, yaw) in zip(times, nodes)))
    broken = {v.rule for v in judge(sc, Plan((move,))).violations}
    assert not broken & {"speed", "yaw_rate", "heading", "discontinuous"}, broken


def test_phase_zero_with_a_still_truck_keeps_the_excavators_path():
    """move_both with a truck that stays: the excavator ends where the NLP's controls take it,
    driven faster, not on a path integrated over the shortened steps."""
    sc = block_scenario()
    st = SimState.start(sc)
    conv = Converter(sc, eta_on=0.25, min_dig_volume=0.02, depth=0.4)
    spec = sc.machines.excavator
    ve, we = np.full(4, 0.3 * spec.travel_speed), np.full(4, 0.2 * spec.yaw_rate)
    dts = np.full(4, 2.0)
    end = integrate(st.exc, ve, we, dts, spec.travel_speed, spec.yaw_rate)[-1]
    assert conv.move_both(st, ve, we, np.zeros(4), np.zeros(4), dts) == "excavator"
    assert (st.exc.x, st.exc.y, st.exc.yaw) == pytest.approx(tuple(end), abs=1e-9)
    assert st.t < dts.sum()  # and faster than the NLP's pace


def test_as_planned_executes_the_nlps_own_digs():
    """as_planned: each dig is at an NLP contact and heading with the full drag and no trimming;
    the plan is judged as it is (here valid), and the local solve counts are reported."""
    from earthbench.plan import Dig

    sc = rbf(1, 1.5, n_bases=14)
    plan = StlTampPlanner(global_layer=False, as_planned=True).plan(sc)
    v = judge(sc, plan)
    assert v.valid, v.violations[:3]
    digs = [a for a in plan.actions if isinstance(a, Dig)]
    assert digs and all(d.drag_length == pytest.approx(sc.machines.excavator.max_drag_length) for d in digs)
    assert not any(k == "contact_repaired" for k in plan.info["skipped"])
    counts = plan.info["local_solves"]
    assert counts["total"] == len(plan.info["local"]) and sum(counts[k] for k in counts if k != "total") == counts["total"]


def test_the_global_layer_splits_a_large_site_into_windows_of_one_shape():
    from earthbench_planners.stl_tamp.hierarchy import global_blocks, global_lattice

    assert global_blocks((0.0, 12.0, 0.0, 6.0), (12.0, 6.0)) == [(0.0, 12.0, 0.0, 6.0)]
    tiles = global_blocks((0.0, 96.0, 0.0, 48.0), (12.0, 6.0))
    assert len(tiles) == 64 and all(b[1] - b[0] <= 12.0 + 1e-9 and b[3] - b[2] <= 6.0 + 1e-9 for b in tiles)
    assert sum((b[1] - b[0]) * (b[3] - b[2]) for b in tiles) == pytest.approx(96.0 * 48.0)
    # the lattice of one window is the one fit_rbf gives the whole paper map (margin 1)
    assert global_lattice((12.0, 6.0), 1.0) == fit_rbf(rbf(0, 1.0).terrain, spacing=1.0, solver="cholesky").shape


def test_solve_counts_are_the_planners_report_and_malformed_counts_add_nothing():
    from earthbench_planners.stl_tamp.hierarchy import solve_counts
    from earthbench_planners.stl_tamp.report import local_solve_counts

    recs = [{"status": "Solve_Succeeded"}, {"status": "Solved_To_Acceptable_Level"},
            {"status": "Maximum_Iterations_Exceeded (feasible iterate accepted)"},
            {"status": "Solve_Succeeded", "fallback": "IK initial guess"}]
    c = solve_counts(recs)
    assert (c["succeeded"], c["acceptable"], c["capped"], c["fallback"], c["total"]) == (1, 1, 1, 1, 4)
    sc = rbf(0, 1.0)
    m = local_solve_counts(sc, Plan(actions=(), info={"local_solves": c}), None)
    assert m["planner_reported_local_succeeded"] == 1 and m["planner_reported_local_succeeded_share"] == 0.25
    for bad in ({}, {"local_solves": "many"}, {"local_solves": dict(c, total=-1)}, {"local_solves": dict(c, capped=1.5)}):
        assert local_solve_counts(sc, Plan(actions=(), info=bad), None) == {}


@settings(max_examples=40, deadline=None)
@given(hst.floats(1.0, 11.0), hst.floats(1.0, 5.0), hst.floats(-math.pi, math.pi), hst.floats(0.01, 0.4),
       hst.floats(0.1, 1.0))
def test_trial_cuts_on_a_window_take_what_the_whole_grid_takes(x, y, heading, depth, drag):
    from earthbench.cut import apply_cut, cut_level

    sc = rbf(3, 1.0, n_bases=30)
    st = SimState.start(sc)
    conv = Converter(sc, eta_on=0.25, min_dig_volume=0.02, depth=0.4)
    es = sc.machines.excavator
    z = st.z.copy()
    whole = apply_cut(sc.terrain, z, (x, y), heading, es.bucket_width, drag, cut_level(sc.terrain, z, (x, y), depth),
                      es.bucket_capacity)
    assert conv.cut_volume(st, (x, y), heading, depth, drag) == pytest.approx(whole, rel=1e-9, abs=1e-12)
    assert np.array_equal(st.z, sc.terrain.z)  # a trial cut leaves the grid as it was


def test_ipopt_runs_on_one_blas_thread(local_setup):
    """The solver's OpenBLAS (the copy CasADi loads) is set to one thread once a solver exists."""
    import ctypes

    _, pl, nlp, *_ = local_setup
    nlp.solver(pl.config.max_iter, pl._ipopt_options())
    with open("/proc/self/maps") as f:
        paths = sorted({ln.split()[-1] for ln in f if "libcasadi-tp-openblas" in ln})
    assert paths and all(ctypes.CDLL(p).openblas_get_num_threads() == 1 for p in paths)


@pytest.mark.parametrize(("turns", "mirror", "shift"), [(0, False, (-40.05, -44.95)), (0, False, (-49.95, 27.3)), (1, True, (37.35, 9.95))])
def test_candidate_areas_do_not_depend_on_where_the_site_lies(turns, mirror, shift):
    """A sealed draw moves the site (earthbench.seal.SiteTransform); the same site far from the
    origin must tile into the same areas. Up to stl-tamp 0.10.0 a 12 m map measured 11.999999999999998 m
    there and lost a row of tiles (17 areas became 12 or 14), and a one-tile dig area lost its tile."""
    from earthbench.seal import SiteTransform
    from earthbench.results.suite import load_suite

    sc = load_suite("smoke").scenarios[0]
    moved = SiteTransform(turns, mirror, shift).apply(sc)
    c, sep = StlTampPlanner().config, SeparatePlanner()

    def estimates(s):  # on separate's 2 m tiles (stl-tamp's own side leaves a margin on this map)
        areas = candidate_areas(s, s.terrain.z, sep.side(s), c.dig_depth, c.area_vmax, c.base_offset, c.truck_offset)
        return sorted(round(a.estimate, 9) for a in areas)

    assert len(estimates(sc)) >= 12
    assert estimates(moved) == estimates(sc)


def test_areas_keep_the_first_layout_wherever_the_machines_stand():
    """Closed loop, the truck and the excavator move between steps; the areas (their drag
    heading, stand and truck stand) face the first step's sides (receding.Horizon.layout), not
    sides read again from where the machines now stand, which turned them around the site."""
    sc = rbf(0, 4.0, n_bases=14)
    pl = StlTampPlanner()
    c = pl.config
    xmin, xmax, ymin, ymax = site_box(sc)
    cx, cy = (xmin + xmax) / 2, (ymin + ymax) / 2
    m = sc.machines
    moved = dataclasses.replace(sc, machines=dataclasses.replace(
        m, truck_pose=dataclasses.replace(m.truck_pose, x=2 * cx - m.truck_pose.x, y=2 * cy - m.truck_pose.y),
        excavator_pose=dataclasses.replace(m.excavator_pose, x=2 * cx - m.excavator_pose.x, y=2 * cy - m.excavator_pose.y)))
    first = site_layout(sc)
    assert site_layout(moved) != first  # read again, the sides turn

    def faces(scenario, layout=None):
        areas = candidate_areas(scenario, sc.terrain.z, pl.area_side(sc), c.dig_depth, c.area_vmax, c.base_offset,
                                c.truck_offset, c.truck_angle, layout)
        return [(a.centre, a.psi, a.base, a.truck) for a in areas]

    assert faces(sc) and faces(moved, first) == faces(sc)
    assert faces(moved) != faces(sc)
