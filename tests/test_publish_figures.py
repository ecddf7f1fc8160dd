"""The leaderboard's run figures read at a glance: invalid runs on top and large, legends that say what each planner has."""

from __future__ import annotations

import matplotlib.colors as mcolors
import pytest

from earthbench.publishing.board.figures import profiles_figure, volume_time_figure
from earthbench.publishing.board.selection import published_runs
from helpers.leaderboard import Behaviour, fill_store, ref, standard_behaviours, suite_of


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    db = fill_store(tmp_path_factory.mktemp("fig") / "r.db", suite_of(2), standard_behaviours() + [Behaviour(ref("jumpy"), teleport=4.0)])
    return published_runs(db)


def test_invalid_runs_are_large_and_on_top(runs):
    ax = volume_time_figure(runs, "t").axes[0]
    invalid = [c for c in ax.collections if len(c.get_offsets()) and c.get_sizes()[0] >= 60]
    valid = [c for c in ax.collections if len(c.get_offsets()) and c.get_sizes()[0] < 60]
    assert sum(len(c.get_offsets()) for c in invalid) == (runs["reason"] == "invalid").sum() > 0
    assert min(c.get_zorder() for c in invalid) > max(c.get_zorder() for c in valid)


def test_legend_markers_are_honest(runs):
    ax = volume_time_figure(runs, "t").axes[0]
    legend = {t.get_text().split(" (")[0]: h for t, h in zip(ax.get_legend().get_texts(), ax.get_legend().legend_handles)}
    assert legend["jumpy 1.0"].get_marker() == "X"  # every run invalid: no filled dot
    assert legend["half 1.0"].get_marker() == "o" and mcolors.to_rgba(legend["half 1.0"].get_markerfacecolor())[3] == 0
    assert legend["greedy 1.0"].get_marker() == "o" and mcolors.to_rgba(legend["greedy 1.0"].get_markerfacecolor())[3] == 1
    n = int((runs["planner"] == "jumpy").sum())
    assert f"({n} invalid)" in [t.get_text() for t in ax.get_legend().get_texts() if t.get_text().startswith("jumpy")][0]


def test_profile_ticks_are_plain_numbers(runs):
    fig = profiles_figure(runs, "t")
    fig.canvas.draw()
    labels = [t.get_text() for t in fig.axes[0].get_xticklabels() if t.get_text()]
    assert labels and all("^" not in s and "$" not in s for s in labels)
    assert "1" in labels and "2" in labels
