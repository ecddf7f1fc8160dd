"""No prefix of a plan scores or ranks better than the plan: the scoring rule cannot be gamed by loading less.

The rule (:mod:`earthbench.results.scoring`) is checked three ways: under hypothesis on load curves, on
every prefix of real plans of the built-in planners (each prefix judged by the referee), and on
the hostile wrapper of issue 35 (``tests/plugins/truncating_planners.py``) through the
leaderboard's ranking and ``compare``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from earthbench.results.aggregate import aggregate
from earthbench.cli import main
from earthbench.running.harness.environment import environment
from earthbench.referee import judge
from earthbench.registry import PLANNERS, load_plugin_file
from earthbench.results.scoring import DEFAULT_SUCCESS_THRESHOLD, evaluate, is_success, run_order, time_per_target
from earthbench.results.store import Store, load_runs, suite_members
from earthbench.results.suite import load_suite
from earthbench.publishing.verify import prefix_violations
from earthbench_metrics import lower_bound_time_per_m3
from helpers.leaderboard import suite_of

PLUGIN = Path(__file__).parent / "plugins" / "truncating_planners.py"

# -- under hypothesis --------------------------------------------------------------------------------------

dumps = st.lists(st.tuples(st.floats(0.5, 40.0), st.floats(0.0, 0.3)), min_size=0, max_size=40)


def _curve(ds: list[tuple[float, float]]) -> list[tuple[float, float]]:
    t, total, out = 0.0, 0.0, []
    for dt, v in ds:
        t, total = t + dt, total + v
        out.append((t, total))
    return out


@settings(max_examples=400, deadline=None)
@given(dumps, st.floats(0.05, 6.0), st.floats(0.5, 1.0), st.integers(0, 40), st.floats(0.0, 100.0))
def test_no_prefix_scores_or_ranks_better(ds, target, threshold, cut, solve):
    """Time per target m³, success and the run order of a prefix (the first ``cut`` dumps) never beat the plan's."""
    full, prefix = _curve(ds), _curve(ds)[:cut]
    loaded = full[-1][1] if full else 0.0
    loaded_p = prefix[-1][1] if prefix else 0.0
    t_full, t_prefix = time_per_target(full, target), time_per_target(prefix, target)
    s_full, s_prefix = is_success(True, loaded / target, threshold), is_success(True, loaded_p / target, threshold)
    assert t_prefix >= t_full
    assert s_full or not s_prefix
    assert run_order(s_prefix, t_prefix, loaded_p / target, solve) >= run_order(s_full, t_full, loaded / target, solve)
    if loaded >= target and not (prefix and prefix[-1][1] >= target):
        assert math.isinf(t_prefix)  # a prefix short of the target never scores


def test_the_lower_bound_charge_would_reward_stopping(greedy_plans):
    """Why the missing volume is not charged at the machine's fastest cycle: on a real plan, every
    prefix cut at a dump would then score better than the plan (the dumps it leaves out took longer)."""
    sc, plan = greedy_plans[0]
    v = judge(sc, plan)
    target = v.loaded_volume  # the plan loads exactly its target
    lb = lower_bound_time_per_m3(sc)
    charged = [(t + (target - cum) * lb) / target for t, cum in v.load_curve]
    assert all(c < charged[-1] for c in charged[:-1])
    assert all(math.isinf(time_per_target(v.load_curve[:k], target)) for k in range(len(v.load_curve)))


# -- on real plans --------------------------------------------------------------------------------------------


def _plans(suite: str, planners: list[str], seeds: tuple[int, int] | None = None):
    s = load_suite(suite)
    scs = s.select(seeds) if seeds else s.scenarios
    return [(sc, PLANNERS.get(p)().plan(sc)) for p in planners for sc in scs]


@pytest.fixture(scope="module")
def greedy_plans():
    return _plans("smoke", ["greedy"])


def _check_prefixes(sc, plan) -> int:
    checked, broken = prefix_violations(sc, plan, DEFAULT_SUCCESS_THRESHOLD)
    assert not broken, (sc.id, broken)
    return checked


def test_the_prefix_check_catches_the_old_rule(monkeypatch):
    """The check can fail: under 0.1.0's rule (time to target over the volume loaded, capped at the
    target) some prefix of greedy's plans on `paper-extensive` seeds 0-2 scores better (the
    truncation wrapper's gain), and the check names it."""
    import earthbench.results.scoring as scoring

    def old_rule(scenario, plan, verdict, threshold=DEFAULT_SUCCESS_THRESHOLD):
        m = evaluate(scenario, plan, verdict, threshold)
        loaded = min(verdict.loaded_volume, scenario.task.target_volume)
        m["time_per_target_m3"] = verdict.load_curve[-1][0] / loaded if loaded > 0 else math.inf
        return m

    monkeypatch.setattr(scoring, "evaluate", old_rule)
    plans = _plans("paper-extensive", ["greedy"], (0, 2))
    broken = [line for sc, plan in plans for line in prefix_violations(sc, plan, DEFAULT_SUCCESS_THRESHOLD)[1]]
    assert any("time per target m³" in line for line in broken)


@pytest.mark.parametrize("suite,planners,seeds", [
    ("smoke", ["greedy", "singh-cannon-backhoe"], None),
    ("quick", ["greedy", "singh-cannon-backhoe"], None),
    ("paper-extensive", ["greedy"], (0, 2)),
    ("paper-extensive-realistic", ["greedy"], (0, 0)),
    ("pile", ["greedy-loader", "singh-cannon-loader"], (0, 0)),
])
def test_no_prefix_of_a_built_in_plan_ranks_better(suite, planners, seeds):
    checked = sum(_check_prefixes(sc, plan) for sc, plan in _plans(suite, planners, seeds))
    assert checked > 0


@pytest.mark.slow
@pytest.mark.parametrize("planner", ["separate", "stl-tamp"])
def test_no_prefix_of_the_optimising_planners_ranks_better(planner):
    assert sum(_check_prefixes(sc, plan) for sc, plan in _plans("quick", [planner])) > 0


# -- the hostile wrapper, ranked and compared --------------------------------------------------------------------


@pytest.fixture(scope="module")
def wrapper_store(tmp_path_factory):
    """Greedy and the truncation wrapper on 10 scenarios, scored by the one rule and stored through the store's API."""
    from earthbench.running.harness import Case, CaseResult, PlannerRef
    from earthbench.results.scoring import score

    load_plugin_file(PLUGIN)
    suite = suite_of(5, name="truncation", targets=(2.0, 3.0))
    db = tmp_path_factory.mktemp("trunc") / "t.db"
    env = environment("")
    with Store(db) as store:
        store.register_suite(suite)
        for name in ("greedy", "h-truncated-greedy"):
            planner = PLANNERS.get(name)()
            ref = PlannerRef(name=name, version=planner.version, source=name, config=planner.config_dict,
                             config_hash=planner.config_hash)
            for sc in suite.scenarios:
                plan_json = planner.plan(sc).to_json()
                verdict, metrics = score(sc, plan_json, suite.success_threshold)
                case = Case(suite=suite.name, suite_digest=suite.digest, scenario=sc, planner=ref,
                            threshold=suite.success_threshold)
                store.record(case, CaseResult(key=case.key, scenario_id=sc.id, reason="ok" if verdict.valid else "invalid",
                                              metrics=metrics, plan_json=plan_json, solve_time_s=0.1, solve_cpu_s=0.1,
                                              environment=env))
    return db


def test_the_truncation_wrapper_ranks_below_greedy(wrapper_store):
    runs = load_runs(wrapper_store, suite="truncation")
    table = aggregate(runs, members=suite_members(wrapper_store, ["truncation"])).set_index("planner")
    assert table.loc["greedy", "success_rate"] == table.loc["h-truncated-greedy", "success_rate"] == 1.0
    assert table.loc["greedy", "rank_label"] == "1" and table.loc["h-truncated-greedy", "rank_label"] == "2"
    assert math.isinf(table.loc["h-truncated-greedy", "time_per_target_m3_median"])
    assert table.loc["h-truncated-greedy", "short_of_target"] == 10


def test_compare_finds_the_truncation_wrapper_worse(wrapper_store, tmp_path, capsys):
    out_csv = tmp_path / "c.csv"
    code = main(["compare", str(wrapper_store), "--suite", "truncation", "--a", "greedy", "--b", "h-truncated-greedy",
                 "--csv", str(out_csv), "--fail-on-regression", "time_per_target_m3"])
    assert code == 1  # B is significantly worse on the primary metric
    table = pd.read_csv(out_csv).set_index("metric")
    assert table.loc["time_per_target_m3", "verdict"] == "B worse"
    assert table.loc["time_per_target_m3", "pairs"] == 10
    assert "h-truncated-greedy" in capsys.readouterr().out


def test_lower_bound_is_a_bound_on_real_plans(greedy_plans):
    for sc, plan in greedy_plans:
        m = evaluate(sc, plan, judge(sc, plan))
        assert m["time_per_target_m3_ratio"] >= 1.0 or not np.isfinite(m["time_per_target_m3_ratio"])


def test_a_store_written_under_the_old_rule_reads_under_the_new(wrapper_store, tmp_path):
    """Runs stored with the old finite time for a plan short of the target are read (tables, compare, audit) with ∞."""
    import json
    import shutil
    import sqlite3

    from earthbench.publishing.verify import audit

    old = tmp_path / "old.db"
    shutil.copy(wrapper_store, old)
    with sqlite3.connect(old) as con:
        for rid, text in con.execute("SELECT id, metrics FROM runs WHERE planner='h-truncated-greedy'").fetchall():
            m = json.loads(text)
            m.update(time_per_target_m3=m["makespan_s"] / m["loaded_volume"], time_to_target_s=m["makespan_s"])
            con.execute("UPDATE runs SET metrics=? WHERE id=?", (json.dumps(m), rid))
    runs = load_runs(old)
    assert np.isinf(runs.loc[runs.planner == "h-truncated-greedy", "time_per_target_m3"]).all()
    assert np.isfinite(runs.loc[runs.planner == "greedy", "time_per_target_m3"]).all()
    from earthbench.results.store import Store

    with Store(old, read_only=True) as store:
        assert not audit(store).problems()
