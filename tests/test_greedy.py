"""The greedy baseline: valid plans that meet the target on rbf maps, exact predictions."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from earthbench import judge
from earthbench.cut import apply_cut, path_cells
from earthbench.motion import ABS_TOL
from earthbench.rules import undermining_excess
from earthbench.results.scoring import evaluate
from earthbench_metrics import lower_bound_time_per_m3
from earthbench_planners.greedy.backhoe import GreedyConfig, GreedyPlanner, GreedySession
from earthbench_terrains.rbf import rbf


@pytest.mark.parametrize("seed", range(5))
def test_greedy_plans_are_valid_and_reach_the_target(seed):
    sc = rbf(seed, 4.0, n_bases=30)
    plan = GreedyPlanner().plan(sc)
    v = judge(sc, plan)
    m = evaluate(sc, plan, v)
    assert v.valid, v.violations
    assert m["volume_ratio"] >= 0.9
    assert m["success"]
    # the planner uses the referee's cut model, so its claim is exact
    assert m["volume_prediction_error"] == pytest.approx(0.0, abs=1e-9)
    assert m["makespan_prediction_error"] == pytest.approx(0.0, abs=1e-9)


def test_greedy_respects_the_truck_capacity():
    sc = rbf(1, 6.0, n_bases=30)
    sc = sc.replace(
        machines=sc.machines.__class__(
            truck=sc.machines.truck.__class__(capacity=1.0), truck_pose=sc.machines.truck_pose, excavator_pose=sc.machines.excavator_pose
        )
    )
    v = judge(sc, GreedyPlanner().plan(sc))
    assert v.valid and v.loaded_volume == pytest.approx(1.0)


def test_greedy_config_is_hashed_and_bad_settings_are_named():
    from earthbench import PluginError

    assert GreedyPlanner().config_hash == GreedyPlanner().config_hash
    assert GreedyPlanner(min_fill=0.5).config_hash != GreedyPlanner().config_hash
    with pytest.raises(PluginError, match="min_fill"):
        GreedyPlanner(min_fil=0.5)


@pytest.mark.parametrize("seed", range(3))
def test_time_per_m3_never_beats_the_lower_bound(seed):
    sc = rbf(seed, 2.0, n_bases=14)
    plan = GreedyPlanner().plan(sc)
    m = evaluate(sc, plan, judge(sc, plan))
    assert m["time_per_m3"] >= lower_bound_time_per_m3(sc)
    assert m["time_per_m3_ratio"] >= 1.0


# -- the vectorised scoring is the per-point computation it replaced -------------------------



@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(-2.0, 14.0), st.floats(-2.0, 8.0)), min_size=1, max_size=30))
def test_heights_at_is_height_at_for_every_point(points):
    terrain = rbf(3, 1.0, n_bases=14).terrain
    x, y = np.array(points).T
    assert terrain.heights_at(x, y).tolist() == [terrain.height_at(a, b) for a, b in points]


@settings(max_examples=25, deadline=None)
@given(st.lists(st.tuples(st.floats(-4.0, 16.0), st.floats(-4.0, 10.0)), min_size=1, max_size=8), st.integers(0, 4))
def test_station_volumes_are_the_direct_sum_over_the_annulus(bases, seed):
    g = GreedySession(rbf(seed, 1.0, n_bases=30), GreedyConfig())
    e = g.exc
    excess = np.where(g.in_area, np.clip(g.z - g.floor, 0.0, e.max_cut_depth * 2), 0.0)
    w = np.where(excess > 1e-3, excess, 0.0) * g.terrain.cell_area
    direct = []
    for bx, by in bases:
        d = np.hypot(g.cx - bx, g.cy - by)
        direct.append(w[(d >= e.reach_min + e.max_drag_length) & (d <= e.reach_max)].sum())
    assert g.reachable_volume(np.array(bases)) == pytest.approx(direct, rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("seed", range(3))
def test_trial_cuts_are_the_referees_cut_and_leave_the_grid_as_it_was(seed):
    g = GreedySession(rbf(seed, 1.0, n_bases=30), GreedyConfig())
    g.base = g.base.__class__(6.0, 3.0, 0.0)  # a station in the middle of the map
    p, h, _, level, _ = g.candidates()
    before = g.z.copy()
    for k in range(0, len(p), max(len(p) // 40, 1)):
        contact, e = (float(p[k, 0]), float(p[k, 1])), g.exc
        on_copy = apply_cut(
            g.terrain, before.copy(), contact, float(h[k]), e.bucket_width, e.max_drag_length, float(level[k]), e.bucket_capacity
        )
        cells = path_cells(g.terrain, g.z.shape, contact, float(h[k]), e.bucket_width, e.max_drag_length)
        assert g.trial_cut(contact, float(h[k]), float(level[k]), cells) == on_copy
        assert np.array_equal(g.z, before)


@pytest.mark.parametrize("seed", range(3))
def test_the_undermining_check_agrees_with_the_referees_on_the_cut_map(seed):
    g = GreedySession(rbf(seed, 1.0, n_bases=30), GreedyConfig())
    g.base = g.base.__class__(6.0, 3.0, 0.0)
    p, h, _, level, _ = g.candidates()
    track, e, before = g.station()[0], g.exc, g.z.copy()
    verdicts = []
    for k in range(len(p)):
        contact = (float(p[k, 0]), float(p[k, 1]))
        cells = path_cells(g.terrain, g.z.shape, contact, float(h[k]), e.bucket_width, e.max_drag_length)
        for cut_level in (float(level[k]), track - 0.5, track - 1.0):  # deeper cuts to reach the tracks
            cut = before.copy()
            apply_cut(g.terrain, cut, contact, float(h[k]), e.bucket_width, e.max_drag_length, cut_level, e.bucket_capacity)
            rows, cols = np.nonzero(cut < before)
            referee = cut_level < track and undermining_excess(g.terrain, cut, e, g.base, track, rows, cols) > -ABS_TOL
            assert g.undermines(contact, float(h[k]), cut_level, track, cells) == referee
            assert np.array_equal(g.z, before)
            verdicts.append(referee)
    assert any(verdicts) and not all(verdicts)


@pytest.mark.parametrize("planner", ["greedy", "singh-cannon-backhoe"])
def test_linear_planners_complete_a_large_scale_target(planner):
    from earthbench import PLANNERS

    sc = rbf(0, 64.0, n_bases=480, size=(48.0, 24.0), truck_capacity=80.0)
    plan = PLANNERS.get(planner)().plan(sc)
    v = judge(sc, plan)
    assert v.valid, v.violations[:3]
    assert evaluate(sc, plan, v)["volume_ratio"] >= 0.95


def _swings(sc, plan) -> list[float]:
    """The swing (rad) each dump pays: the angle at the base between the last dig's contact and the truck."""
    from earthbench.plan import Dig, Dump
    from earthbench.referee.state import Replay

    replay = Replay(sc, plan)
    exc, truck = replay.timelines["excavator"], replay.timelines["truck"]
    out, contact = [], None
    for a in sorted(plan.actions, key=lambda a: getattr(a, "t_start", a.path[0][0] if hasattr(a, "path") else 0.0)):
        if isinstance(a, Dig):
            contact = a.contact
        elif isinstance(a, Dump) and contact is not None:
            b, t = exc.pose(a.t_start), truck.pose(a.t_start)
            d = np.arctan2(t.y - b.y, t.x - b.x) - np.arctan2(contact[1] - b.y, contact[0] - b.x)
            out.append(abs((d + np.pi) % (2 * np.pi) - np.pi))
    return out


@pytest.mark.parametrize("seed", range(2))
def test_the_excavator_digs_while_the_truck_drives_to_it(seed):
    """The truck starts out of dump reach: the first bucket is dug during its drive, not after."""
    from earthbench.plan import Dig, Move

    sc = rbf(seed, 1.12, n_bases=30)
    plan = GreedyPlanner().plan(sc)
    verdict = judge(sc, plan)
    assert verdict.valid, verdict.violations[:3]
    first_dig = next(a for a in plan.actions if isinstance(a, Dig))
    approach = next(a for a in plan.actions if isinstance(a, Move) and a.machine == "truck")
    assert first_dig.t_start < approach.path[-1][0] - 3.0


@pytest.mark.parametrize("seed", range(2))
def test_a_large_target_opens_from_a_station_with_the_truck_beyond_the_soil(seed):
    """From the corner of the map the truck, off the dig area, stands far from the soil's
    bearing (greedy 1.3 on the same maps, `standard`'s paper-extensive s0 and s1 at 7 m³: a
    median swing of 25° and 49° a dump, 1.39–1.42 × the target bound); greedy 1.4 first drives
    the excavator onto the map, the truck meanwhile to the edge beyond the soil it digs, and
    swings little after (12° and 18°, 1.18 and 1.20)."""
    from earthbench.plan import Move

    sc = rbf(seed, 7.0, n_bases=30)
    plan = GreedyPlanner().plan(sc)
    verdict = judge(sc, plan)
    assert verdict.valid, verdict.violations[:3]
    m = evaluate(sc, plan, verdict)
    assert m["volume_ratio"] >= 0.99
    assert m["time_per_target_m3_bound_ratio"] <= 1.25
    exc_move = next(a for a in plan.actions if isinstance(a, Move) and a.machine == "excavator")
    truck_move = next(a for a in plan.actions if isinstance(a, Move) and a.machine == "truck")
    assert exc_move.path[0][0] == 0.0 and truck_move.path[0][0] < exc_move.path[-1][0]  # both drive at once
    assert np.median(_swings(sc, plan)) <= np.radians(20.0)


@pytest.mark.parametrize("target", [6.0, 8.0])
def test_a_cab_scan_over_a_bench_edge_never_leads_to_undermining_with_the_20t_class(target):
    """The cab's scan of `standard-20t-realistic`'s bench-sand-cab s1 hides the face below the
    bench edge and fills it from above, so the true face holds less than the scan shows and a
    bucket drags on toward the tracks before it fills: greedy 1.4's plans undermined there (0.24
    and 0.10 m below the line, the referee on the true ground); the whole drag is checked on a scan."""
    from earthbench.results.suite import load_suite
    from earthbench.sensing import observe

    truth = next(sc for sc in load_suite("standard-20t-realistic").scenarios
                 if sc.id == f"standard-20t-realistic/bench-sand-cab/s1/v{target:g}")
    verdict = judge(truth, GreedyPlanner().plan(observe(truth)))
    assert verdict.valid, verdict.violations[:3]
    assert verdict.loaded_volume >= 0.8 * target


def test_the_opening_prices_the_first_swing_from_where_the_excavator_arrives():
    """`standard`'s paper-extensive s6 at 7 m³: greedy 1.4's opening weighed the target's swing
    but not the first cycle's, from where the upper body faces on arrival to the truck's
    bearing, and drove to a station it then swung away from (1.37 × the target bound); 1.5
    prices it (1.15)."""
    sc = rbf(6, 7.0, n_bases=30)
    plan = GreedyPlanner().plan(sc)
    verdict = judge(sc, plan)
    assert verdict.valid, verdict.violations[:3]
    m = evaluate(sc, plan, verdict)
    assert m["volume_ratio"] >= 0.99
    assert m["time_per_target_m3_bound_ratio"] <= 1.20


def _standard(sid: str):
    from earthbench.results.suite import load_suite

    return next(sc for sc in load_suite("standard").scenarios if sc.id == f"standard/{sid}")


@pytest.mark.parametrize(("sid", "most"), [("paper-switch.rbf14-local/s7/v0.56", 1.45), ("paper-switch.rbf14-local/s8/v0.56", 1.80)])
def test_a_small_job_relocates_to_a_near_station_that_holds_it(sid, most):
    """A 2-bucket job whose window lies out of reach: greedy 1.4 drove to the station with the
    most material in reach (less 0.05 m³ a metre), which took a long turn in place (1.81 and
    2.10 × the target bound); 1.5 counts a station's material up to 4 × what is still needed and
    prices the way by the excavator's drive time (1.35 and 1.68)."""
    sc = _standard(sid)
    plan = GreedyPlanner().plan(sc)
    verdict = judge(sc, plan)
    assert verdict.valid, verdict.violations[:3]
    m = evaluate(sc, plan, verdict)
    assert m["volume_ratio"] >= 0.99
    assert m["time_per_target_m3_bound_ratio"] <= most


@pytest.mark.parametrize("seed", [2, 5])
def test_the_opening_parks_the_truck_where_its_line_covers_the_soils_bearings(seed):
    """`standard`'s bench s2 and s5 at 8 m³: greedy 1.4 parked the truck at the stand it reached
    first, at the edge of dump reach, from where it could hardly slide along the face before
    leaving reach, and the dumps swung (1.16 × the target bound); 1.5 weighs each stand's line
    along its heading (the bearings it covers sliding during digs) and parks nearer (1.06),
    though the truck arrives later."""
    sc = _standard(f"bench.bench/s{seed}/v8")
    plan = GreedyPlanner().plan(sc)
    verdict = judge(sc, plan)
    assert verdict.valid, verdict.violations[:3]
    m = evaluate(sc, plan, verdict)
    assert m["volume_ratio"] >= 0.99
    assert m["time_per_target_m3_bound_ratio"] <= 1.10


def test_closed_loop_marks_a_contact_barren_when_the_truck_load_shows_its_dig_came_back_empty():
    from earthbench_planners.greedy.closed_loop import BARREN_SHARE, Carried
    from earthbench.plan import Dig, Plan

    c = Carried()
    c.remember(Plan((Dig("excavator", 0.0, 3.0, (1.0, 2.0), 0.0, 0.3, 1.0),)), cut=0.28, before=1.0)
    c.judge_last(1.0 + BARREN_SHARE * 0.28 + 1e-6)  # loaded about what a quarter bucket holds: not barren
    assert c.barren == [] and c.last is None
    c.remember(Plan((Dig("excavator", 0.0, 3.0, (1.0, 2.0), 0.0, 0.3, 1.0),)), cut=0.28, before=1.0)
    c.judge_last(1.01)
    assert c.barren == [(1.0, 2.0)]


def test_closed_loop_on_a_hard_scan_reaches_the_target_instead_of_digging_the_same_contact():
    """standard-20t-realistic jacksboro-clay-cab s5 at 6 m³: the scan shows soil where the hard layer
    stops the cut; greedy 1.5 dug that contact again at every step until the harness's step cap
    (1,000 steps, 0.92 of the target); 1.5.1 marks it barren after one empty dump."""
    from earthbench.results.suite import load_suite
    from earthbench.running.harness.steps import run_closed_loop

    sc = next(s for s in load_suite("standard-20t-realistic").scenarios if s.id == "standard-20t-realistic/jacksboro-clay-cab/s5/v6")
    plan = run_closed_loop(GreedyPlanner(), sc)
    v = judge(sc, plan)
    m = evaluate(sc, plan, v)
    assert v.valid and m["loaded_volume"] >= sc.task.target_volume
    assert len(plan.info["steps"]) < 60
