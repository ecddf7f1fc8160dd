"""Best known plans (earthbench.publishing.best, ``earthbench best``): only a re-judged, strictly faster valid plan under
today's rules is kept; the committed set holds; the boards show each planner's ratio to it."""

from __future__ import annotations

import dataclasses
import gzip
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from earthbench.publishing.best import check, file_candidates, judged_figures, kept, update, with_best_known
from earthbench.cli import main
from earthbench.plan import Move, Plan
from earthbench.publishing.publish import publish
from earthbench.referee import RULES_VERSION
from earthbench.results.suite import load_suite
from earthbench_planners.greedy.backhoe import GreedyPlanner
from helpers.leaderboard import Behaviour, fill_store, ref

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def smoke():
    return load_suite("smoke")


@pytest.fixture(scope="module")
def plans(smoke):
    """Greedy's plan of the first two scenarios, and the same plan started 20 s later (valid, slower)."""
    out = {}
    for sc in smoke.scenarios[:2]:
        plan = GreedyPlanner().plan(sc)
        out[sc.digest] = (plan, _delayed(plan, 20.0))
    return out


def _delayed(plan: Plan, dt: float) -> Plan:
    def later(a):
        if isinstance(a, Move):
            return dataclasses.replace(a, path=tuple((t + dt, x, y, yaw) for t, x, y, yaw in a.path))  # it waits where it is
        return dataclasses.replace(a, t_start=a.t_start + dt, t_end=a.t_end + dt)
    return Plan(tuple(later(a) for a in plan.actions))


def _teleported(plan: Plan) -> Plan:
    """The truck jumps 5 m east off its start: an invalid plan."""
    return Plan(tuple(dataclasses.replace(a, path=tuple((t, x + 5.0, y, yaw) for t, x, y, yaw in a.path))
                      if isinstance(a, Move) and a.machine == "truck" else a for a in plan.actions))


def _file(path: Path, digest: str, plan: Plan, **extra) -> Path:
    path.write_text(json.dumps({"scenario_digest": digest, "plan": json.loads(plan.to_json()),
                                "producer": {"kind": "witness", "name": path.stem}, **extra}))
    return path


def test_update_keeps_only_a_strictly_faster_valid_plan(smoke, plans, tmp_path):
    root = tmp_path / "best"
    digest = smoke.scenarios[0].digest
    fast, slow = plans[digest]
    sc = smoke.scenarios[0]
    figs_fast, _ = judged_figures(sc, fast.to_json(), smoke.success_threshold)
    figs_slow, why = judged_figures(sc, slow.to_json(), smoke.success_threshold)
    assert figs_slow is not None, why
    assert figs_fast is not None and figs_fast["time_to_target_s"] < figs_slow["time_to_target_s"]

    out = update(root, smoke, file_candidates([_file(tmp_path / "slow.json", digest, slow)]))
    assert len(out.accepted) == 1 and not out.refused
    assert kept(root, "smoke")[digest]["time_to_target_s"] == pytest.approx(figs_slow["time_to_target_s"])

    out = update(root, smoke, file_candidates([_file(tmp_path / "fast.json", digest, fast)]))
    assert len(out.accepted) == 1
    entry = kept(root, "smoke")[digest]
    assert entry["time_to_target_s"] == pytest.approx(figs_fast["time_to_target_s"])
    assert entry["rules"] == RULES_VERSION and entry["producer"]["name"] == "fast" and entry["scenario_id"] == sc.id

    # the same plan again, and the slower one: not strictly better, nothing changes
    out = update(root, smoke, file_candidates([tmp_path / "slow.json", tmp_path / "fast.json"]))
    assert out.not_better == 2 and not out.accepted and not out.refused
    assert check(root, smoke) == (1, [])


def test_update_refuses_invalid_tampered_foreign_and_stale_candidates(smoke, plans, tmp_path):
    root = tmp_path / "best"
    digest = smoke.scenarios[0].digest
    fast, slow = plans[digest]
    figs, _ = judged_figures(smoke.scenarios[0], slow.to_json(), smoke.success_threshold)
    assert figs is not None
    bad = [
        _file(tmp_path / "invalid.json", digest, _teleported(fast)),
        _file(tmp_path / "tampered.json", digest, slow, time_per_target_m3=figs["time_per_target_m3"] * 0.5),
        _file(tmp_path / "foreign.json", "0" * 64, fast),
        _file(tmp_path / "older.json", digest, fast, rules=RULES_VERSION - 1),
    ]
    out = update(root, smoke, file_candidates(bad))
    why = {Path(c.source).stem: w for c, w in out.refused}
    assert not out.accepted and sorted(why) == ["foreign", "invalid", "older", "tampered"]
    assert why["invalid"].startswith("invalid")
    assert "figures that re-judging does not give" in why["tampered"]
    assert "not one of the suite's" in why["foreign"]
    assert f"judged under rules {RULES_VERSION - 1}" in why["older"]
    assert kept(root, "smoke") == {}
    # the command says so and exits 1 when a plan file is refused
    assert main(["best", "update", "--plans", str(bad[0]), "--suite", "smoke", "--dir", str(root)]) == 1


def test_check_finds_a_tampered_or_stale_kept_entry_and_update_settles_them(smoke, plans, tmp_path):
    root = tmp_path / "best"
    digest = smoke.scenarios[0].digest
    update(root, smoke, file_candidates([_file(tmp_path / "fast.json", digest, plans[digest][0])]))
    assert main(["best", "check", "--dir", str(root)]) == 0
    path = next((root / "smoke").glob("*.json.gz"))
    doc = json.loads(gzip.decompress(path.read_bytes()))

    def kept_as(**changes):
        path.write_bytes(gzip.compress(json.dumps({**doc, **changes}).encode()))

    kept_as(time_per_target_m3_lower_bound=1.0)  # a bound that moved (a metric's change): re-recorded, the plan stays
    assert "target bound" in check(root, smoke)[1][0]
    out = update(root, smoke, [])
    assert len(out.refreshed) == 1 and not out.dropped and check(root, smoke) == (1, [])
    kept_as(time_to_target_s=doc["time_to_target_s"] - 1)
    n, problems = check(root, smoke)
    assert n == 1 and len(problems) == 1 and "time_to_target_s" in problems[0]
    kept_as(rules=RULES_VERSION - 1)
    assert main(["best", "check", "--dir", str(root), "--suite", "smoke"]) == 1
    out = update(root, smoke, [])
    assert len(out.dropped) == 1 and kept(root, "smoke") == {}


def test_the_committed_best_known_plans_hold():
    """Every kept plan of leaderboard/best re-judges valid under today's rules, with the figures it records."""
    root = ROOT / "leaderboard" / "best"
    suites = sorted(p.name for p in root.iterdir() if p.is_dir())
    assert suites, "no committed best known plans"
    for name in suites:
        suite = load_suite(name)
        n, problems = check(root, suite)
        assert problems == [] and n == len(list((root / name).glob("*.json.gz"))) > 0
        assert set(kept(root, name)) <= {sc.digest for sc in suite.scenarios}


def test_update_from_a_store_and_the_board_column(smoke, plans, tmp_path):
    """Runs of a store are re-judged as candidates; the board shows each planner's median ratio to the best known."""
    db = fill_store(tmp_path / "runs.db", smoke, [Behaviour(ref("greedy", "1.0")), Behaviour(ref("half"), keep=0.5)])
    root = tmp_path / "best"
    assert main(["best", "update", "--db", str(db), "--dir", str(root)]) == 0
    entries = kept(root, "smoke")
    assert len(entries) == len(smoke.scenarios)
    assert {e["producer"]["planner"] for e in entries.values()} == {"greedy"}  # half loads less: short or slower
    # a witness slower than greedy on two scenarios would not replace it; make those the kept ones by hand-free means:
    slow_root = tmp_path / "slow"
    update(slow_root, smoke, file_candidates([_file(tmp_path / f"s{n}.json", d, p[1]) for n, (d, p) in enumerate(plans.items())]))
    slow = {d: e["time_per_target_m3"] for d, e in kept(slow_root, "smoke").items()}
    # a scenario is one problem by its digest: plans kept under another suite's folder (standard ⊃ bench) count
    (slow_root / "smoke").rename(slow_root / "superset")
    board = publish(db, tmp_path / "board", figures=False, best=slow_root)
    runs = board.runs
    assert runs is not None and board.summary is not None
    greedy = runs[runs["planner"] == "greedy"]
    want = [t / slow[d] for d, t in zip(greedy["scenario_digest"], greedy["time_per_target_m3"]) if d in slow]
    assert len(want) == 2 and all(w < 1 for w in want)
    row = board.summary.query("scope == 'suite' and planner == 'greedy'").iloc[0]
    assert row["time_per_target_m3_best_ratio_median"] == pytest.approx(float(np.median(want)))
    assert greedy["time_per_target_m3_best_ratio"].isna().sum() == len(smoke.scenarios) - 2
    readme = (tmp_path / "board" / "README.md").read_text()
    assert "× best known" in readme and "## Best known plans" in readme and "2 of 4 scenarios" in readme
    page = (tmp_path / "board" / "index.html").read_text()
    assert "× best known" in page and 'href="best.csv"' in page and "2 of 4 scenarios" in page
    brackets = pd.read_csv(tmp_path / "board" / "best.csv")
    assert len(brackets) == 2 and (brackets["best_over_bound"] > 1).all() and set(brackets["suite"]) == {"smoke"}
    assert np.allclose(brackets["best_known_s_per_m3"] / brackets["bound_s_per_m3"], brackets["best_over_bound"])
    assert "time_per_target_m3_best_ratio" in pd.read_csv(tmp_path / "board" / "runs.csv").columns
    # without a best-known folder the board is as before: no column, no best.csv
    plain = publish(db, tmp_path / "plain", figures=False)
    assert "× best known" not in (tmp_path / "plain" / "README.md").read_text()
    assert not (tmp_path / "plain" / "best.csv").exists() and plain.summary is not None
    assert plain.summary["time_per_target_m3_best_ratio_median"].isna().all()


def test_best_ratio_of_runs_without_a_kept_plan_is_nan(tmp_path):
    runs = pd.DataFrame({"scenario_digest": ["a", "b"], "time_per_target_m3": [10.0, math.inf]})
    out = with_best_known(runs, tmp_path)
    assert out["time_per_target_m3_best_ratio"].isna().all()
