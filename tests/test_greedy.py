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
from earthbench_planners.greedy.backhoe import GreedyConfig, GreedyPlanner, _Greedy
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
    g = _Greedy(rbf(seed, 1.0, n_bases=30), GreedyConfig())
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
    g = _Greedy(rbf(seed, 1.0, n_bases=30), GreedyConfig())
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
    g = _Greedy(rbf(seed, 1.0, n_bases=30), GreedyConfig())
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
