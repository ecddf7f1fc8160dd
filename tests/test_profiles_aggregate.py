"""Performance-profile math and per-planner aggregates on hand-computed cases."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from earthbench.results.aggregate import aggregate
from earthbench.profiles import cost_matrix, performance_ratios, profile

INF = math.inf


def test_ratios_and_profile_by_hand():
    # three problems, two solvers; B fails on p3, nobody... A is best on p1, B on p2
    costs = pd.DataFrame({"A": [2.0, 6.0, 5.0], "B": [4.0, 3.0, INF]}, index=["p1", "p2", "p3"])
    r = performance_ratios(costs)
    assert r.loc["p1"].tolist() == [1.0, 2.0]
    assert r.loc["p2"].tolist() == [2.0, 1.0]
    assert r.loc["p3", "A"] == 1.0 and math.isinf(r.loc["p3", "B"])
    rho = profile(costs, taus=[1.0, 1.5, 2.0, 10.0])
    # A: ratios 1, 2, 1 -> at τ=1: 2/3, τ=1.5: 2/3, τ=2: 1
    assert rho["A"].tolist() == pytest.approx([2 / 3, 2 / 3, 1.0, 1.0])
    # B: ratios 2, 1, inf -> 1/3, 1/3, 2/3, 2/3 (the failure is never solved)
    assert rho["B"].tolist() == pytest.approx([1 / 3, 1 / 3, 2 / 3, 2 / 3])


def test_problem_nobody_solves_counts_for_no_one():
    costs = pd.DataFrame({"A": [1.0, INF], "B": [3.0, INF]}, index=["p1", "p2"])
    rho = profile(costs, taus=[1.0, 3.0, 1e9])
    assert rho["A"].tolist() == pytest.approx([0.5, 0.5, 0.5])
    assert rho["B"].tolist() == pytest.approx([0.0, 0.5, 0.5])


def test_default_taus_are_the_breakpoints():
    costs = pd.DataFrame({"A": [1.0, 4.0], "B": [2.0, 1.0]}, index=["p1", "p2"])
    rho = profile(costs)
    assert rho.index.tolist() == [1.0, 2.0, 4.0]
    assert rho["A"].tolist() == pytest.approx([0.5, 0.5, 1.0])
    assert rho["B"].tolist() == pytest.approx([0.5, 1.0, 1.0])


def test_cost_matrix_failures_and_missing_runs_are_inf():
    runs = pd.DataFrame({
        "scenario_digest": ["s1", "s1", "s2", "s2", "s3"],
        "solver": ["A", "B", "A", "B", "A"],
        "t": [10.0, 20.0, 5.0, 0.0, INF],
        "success": [True, True, False, True, True],
    })
    c = cost_matrix(runs, "t")
    assert c.loc["s1"].tolist() == [10.0, 20.0]
    assert math.isinf(c.loc["s2", "A"])  # not a success
    assert 0 < c.loc["s2", "B"] <= 1e-9  # zero raised to MIN_COST
    assert math.isinf(c.loc["s3", "A"])  # infinite cost = failure
    assert math.isinf(c.loc["s3", "B"])  # no run = failure
    rho = profile(c, taus=[1.0, 2.0])
    assert rho["A"].tolist() == pytest.approx([1 / 3, 1 / 3])
    assert rho["B"].tolist() == pytest.approx([1 / 3, 2 / 3])


def _run(planner, scenario, reason, success, vr, tpm, st, version="1", cpu="cpu-a"):
    return {"suite": "s", "track": "backhoe", "planner": planner, "planner_version": version, "config_hash": "h",
            "scenario_digest": scenario, "reason": reason, "success": success, "volume_ratio": vr, "time_per_m3": tpm,
            "time_per_target_m3": tpm, "time_per_target_m3_ratio": None if tpm is None else tpm / 10.0,
            "time_per_m3_ratio": None if tpm is None else tpm / 10.0, "solve_time_s": st, "solve_cpu_s": st,
            "cpu_model": cpu}


def test_aggregate_by_hand_and_ranking():
    runs = pd.DataFrame([
        _run("fast", "a", "ok", True, 1.0, 20.0, 1.0),
        _run("fast", "b", "ok", True, 0.9, 40.0, 2.0),
        _run("fast", "c", "ok", False, 0.5, 30.0, 3.0),
        _run("fast", "d", "timeout", False, None, None, 60.0),
        _run("good", "a", "ok", True, 1.0, 50.0, 10.0),
        _run("good", "b", "ok", True, 1.0, 60.0, 10.0),
        _run("good", "c", "invalid", False, 1.0, 10.0, 10.0),
        _run("good", "d", "ok", True, 1.0, INF, 10.0, cpu="cpu-b"),
    ])
    s = aggregate(runs)
    assert s["planner"].tolist() == ["good", "fast"]  # 3/4 success beats 2/4
    assert s["rank_label"].tolist() == ["1=", "1="]  # four pairs can separate nothing: a shared rank
    f = s.set_index("planner").loc["fast"]
    assert f["runs"] == 4 and f["successes"] == 2 and f["success_rate"] == 0.5
    assert f["volume_ratio_mean"] == pytest.approx(0.8)
    assert f["volume_ratio_sd"] == pytest.approx(np.std([1.0, 0.9, 0.5], ddof=1))
    assert f["time_per_m3_median"] == 30.0
    assert f["time_per_m3_q1"] == 25.0 and f["time_per_m3_q3"] == 35.0 and f["time_per_m3_iqr"] == 10.0
    assert f["time_per_m3_ratio_median"] == pytest.approx(3.0)
    assert f["solve_time_median"] == 2.5
    assert f["solve_time_p90"] == pytest.approx(np.percentile([1, 2, 3, 60], 90))
    assert (f["n_ok"], f["n_timeout"], f["n_invalid"]) == (3, 1, 0)
    g = s.set_index("planner").loc["good"]
    assert g["time_per_m3_median"] == 55.0  # the invalid run is not ranked, the inf one loaded nothing
    assert g["loaded_nothing"] == 1 and g["n_invalid"] == 1 and g["cpu_models"] == 2


def test_ties_on_success_are_broken_by_time_per_target_m3():
    runs = pd.DataFrame([
        _run("slow", "a", "ok", True, 1.0, 90.0, 1.0),
        _run("quick", "a", "ok", True, 1.0, 30.0, 5.0),
        _run("none", "a", "error", False, None, None, 0.1),
    ])
    s = aggregate(runs)
    assert s["planner"].tolist() == ["quick", "slow", "none"]


def test_scenarios_without_a_run_count_as_failures():
    runs = pd.DataFrame([
        _run("partial", "a", "ok", True, 1.0, 20.0, 1.0),
        _run("full", "a", "ok", True, 1.0, 30.0, 1.0),
        _run("full", "b", "ok", True, 1.0, 30.0, 1.0),
        _run("full", "c", "ok", False, 0.5, 30.0, 1.0),
        _run("full", "d", "ok", True, 1.0, 30.0, 1.0),
    ])
    s = aggregate(runs, {"s": 4}).set_index("planner")
    assert s.loc["partial", "success_rate"] == 0.25 and s.loc["partial", "of"] == 4
    assert s.loc["full", "success_rate"] == 0.75
    assert aggregate(runs)["planner"].tolist() == ["partial", "full"]  # without sizes: over its own scenarios
    assert aggregate(runs, {"s": 4})["planner"].tolist() == ["full", "partial"]
