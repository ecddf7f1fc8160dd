"""The ``scale`` table and cost-growth figure, drawn for size ladders and only for them."""

from __future__ import annotations

import pandas as pd
import pytest

from earthbench.publishing.board.selection import published_runs
from earthbench.publishing.publish import publish
from earthbench.running.scaling import is_size_ladder, scale_summary
from helpers.leaderboard import EVIL, Behaviour, fill_store, ref, suite_of


@pytest.fixture(scope="module")
def ladder_db(tmp_path_factory):
    behaviours = [Behaviour(ref("greedy", "1.0")), Behaviour(ref(EVIL), keep=0.5, slow=2.0),
                  Behaviour(ref("flaky"), fail="timeout", fail_every=2)]
    return fill_store(tmp_path_factory.mktemp("ladder") / "runs.db", suite_of(2, "ladder", (0.28, 0.56, 1.12)), behaviours)


def test_a_ladder_is_three_targets_each_at_least_double():
    def frame(*t):
        return pd.DataFrame({"target_volume": t})
    assert is_size_ladder(frame(4.0, 16.0, 64.0, 256.0, 4.0))
    assert is_size_ladder(frame(0.28, 0.56, 1.12))
    assert not is_size_ladder(frame(4.0, 16.0))  # two sizes are no growth curve
    assert not is_size_ladder(frame(4.0, 5.0, 6.0, 7.0))  # paper-extensive: close targets
    assert not is_size_ladder(frame(0.56, 0.84, 1.12, 4.0, 8.0))


def test_summary_is_the_median_over_valid_runs(ladder_db):
    runs = published_runs(ladder_db)
    s = scale_summary(runs).set_index(["solver", "target_volume"])
    for (solver, target), g in runs.groupby(["solver", "target_volume"]):
        good = g[(g["reason"] == "ok") & g["valid"].astype(bool) & (g["loaded_volume"] > 0)]
        row = s.loc[(solver, target)]
        assert row["runs"] == len(g) and row["valid"] == len(good)
        if len(good):
            assert row["solve_per_m3_median"] == pytest.approx((good["solve_time_s"] / good["loaded_volume"]).median())
            assert row["time_per_m3_median"] == pytest.approx(good["time_per_m3"].median())
        else:
            assert pd.isna(row["solve_per_m3_median"])
    smallest = s.xs(0.28, level="target_volume")["solve_per_m3_median"]
    growth = s["solve_per_m3_median"] / smallest.reindex(s.index.get_level_values(0)).to_numpy()
    assert s["growth"].to_numpy() == pytest.approx(growth.to_numpy(), nan_ok=True)


def test_leaderboard_of_a_ladder_has_the_scale_table_and_figure(ladder_db, tmp_path):
    board = publish(ladder_db, tmp_path / "board", terrain=False)
    figs = {p.name for p in (board.out / "figures").iterdir()}
    assert sum(f.endswith(("-cost-growth.png", "-cost-growth.svg")) for f in figs) == 2
    md = (board.out / "README.md").read_text()
    assert "scale: cost against target volume" in md
    scale_lines = [line for line in md.splitlines() if line.startswith(("| 0.28 |", "| 0.56 |", "| 1.12 |"))]
    assert len(scale_lines) == 3 * 3  # three targets × three planners
    assert all("<script>" not in line for line in scale_lines)
    page = (board.out / "index.html").read_text()
    assert "scale: cost against target volume" in page and "Cost growth" in page
    assert "<script>alert" not in page


def test_no_scale_table_for_a_suite_of_close_targets(tmp_path):
    db = fill_store(tmp_path / "runs.db", suite_of(1), [Behaviour(ref("greedy", "1.0"))])
    board = publish(db, tmp_path / "board", terrain=False)
    assert "scale: cost" not in (board.out / "README.md").read_text()
    assert not any("cost-growth" in p.name for p in (board.out / "figures").iterdir())
