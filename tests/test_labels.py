"""Readable configuration names in `runs`, summaries and `compare`; `run --seeds` counts only what it selected."""

from __future__ import annotations

import pandas as pd
import pytest

from earthbench.cli import main
from earthbench.publishing.compare import CompareError, Selector
from earthbench.results.labels import config_labels, label
from helpers.leaderboard import Behaviour, fill_store, ref, suite_of


def test_labels_name_the_settings_off_their_defaults():
    assert label("greedy", {"min_fill": 0.6, "closed_loop": True}, {"min_fill": 0.6}) == "greedy[closed_loop]"
    assert label("greedy", {"min_fill": 0.5}, {"min_fill": 0.6}) == "greedy[min_fill=0.5]"
    assert label("greedy", {"min_fill": 0.6}, {"min_fill": 0.6}) == "greedy"
    runs = pd.DataFrame({"planner": ["greedy", "greedy", "gone", "gone"], "config_hash": ["a", "b", "c", "d"],
                         "config": ['{"closed_loop": true, "min_fill": 0.6}', '{"min_fill": 0.6}', '{"k": 1, "x": 2}', '{"k": 2, "x": 2}']})
    labels = config_labels(runs)
    assert labels[("greedy", "a")] == "greedy[closed_loop]" and labels[("greedy", "b")] == "greedy"
    assert labels[("gone", "c")] == "gone[k=1]" and labels[("gone", "d")] == "gone[k=2]"  # not installed: what differs


@pytest.fixture(scope="module")
def two_configs(tmp_path_factory):
    greedy_defaults = {"arc_step": 0.35, "max_actions": 2000, "min_fill": 0.6, "radial_step": 0.25, "station_step": 1.0,
                       "travel_penalty": 0.05, "truck_distance": 4.6}
    behaviours = [Behaviour(ref("greedy", "1.1", {**greedy_defaults, "closed_loop": True}), solve_s=0.5),
                  Behaviour(ref("greedy", "1.1", {**greedy_defaults, "min_fill": 0.5}), solve_s=0.5, keep=0.9)]
    return fill_store(tmp_path_factory.mktemp("labels") / "l.db", suite_of(2), behaviours)


def test_an_ambiguous_selector_lists_the_candidates_by_label(two_configs):
    from earthbench.results.store import load_runs

    runs = load_runs(two_configs)
    with pytest.raises(CompareError) as err:
        Selector.parse("greedy").pick(runs, "A")
    assert "greedy[closed_loop]@1.1 (#" in str(err.value) and "greedy[min_fill=0.5]@1.1 (#" in str(err.value)
    picked = Selector.parse("greedy[closed_loop]@1.1").pick(runs, "A")
    assert picked["config"].str.contains('"closed_loop": true').all() and len(picked) == 4


def test_runs_summary_and_compare_show_labels(two_configs, capsys):
    assert main(["runs", "--db", str(two_configs), "--limit", "0"]) == 0
    out = capsys.readouterr().out
    assert "greedy[closed_loop]" in out and "greedy[min_fill=0.5]" in out
    assert main(["compare", str(two_configs), "--a", "greedy[closed_loop]", "--b", "greedy[min_fill=0.5]"]) == 0
    out = capsys.readouterr().out
    assert "A: greedy[closed_loop] 1.1" in out and "B: greedy[min_fill=0.5] 1.1" in out
    assert "with 4 scenario(s) no paired test can tell two planners apart at α = 0.05" in out
    from earthbench.cli.run import print_summary
    from earthbench.results.store import Store

    with Store(two_configs) as store:
        print_summary(store, "pubtest")
    out = capsys.readouterr().out
    assert "greedy[closed_loop] 1.1" in out and "no paired test can tell two planners apart" in out
    assert "exact (Clopper–Pearson)" in out


def test_seeds_summary_counts_only_the_selection_and_an_empty_one_is_an_error(two_configs, capsys):
    from earthbench.cli.run import print_summary
    from earthbench.results.store import Store

    with Store(two_configs) as store:
        print_summary(store, "pubtest", seeds=(0,))
    out = capsys.readouterr().out
    assert "2 scenarios of the selected seeds" in out
    closed = next(line for line in out.splitlines() if "greedy[closed_loop]" in line)
    assert " 2/2 " in closed and "100% [16%–100%]" in closed  # not "2/4", 50 %
    assert main(["run", "smoke", "--seeds", "5-9", "--db", str(two_configs.parent / "x.db")]) == 2
    assert "--seeds 5-9 selects no scenario of suite 'smoke'; its seeds: 0, 1" in capsys.readouterr().err


def test_a_selector_without_a_version_takes_the_latest_one_and_a_version_takes_that_one(tmp_path):
    from earthbench.results.store import load_runs

    defaults = {"arc_step": 0.35, "max_actions": 2000, "min_fill": 0.6, "radial_step": 0.25, "station_step": 1.0,
                "travel_penalty": 0.05, "truck_distance": 4.6}
    behaviours = [Behaviour(ref("greedy", "1.9", defaults), solve_s=0.5), Behaviour(ref("greedy", "1.10", defaults), solve_s=0.5)]
    runs = load_runs(fill_store(tmp_path / "v.db", suite_of(2), behaviours))
    assert set(Selector.parse("greedy").pick(runs, "A")["planner_version"]) == {"1.10"}  # 1.10 is later than 1.9
    assert set(Selector.parse("greedy@1.9").pick(runs, "A")["planner_version"]) == {"1.9"}
