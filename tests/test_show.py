"""``earthbench show``: cropped to the map, every layer drawn, violations in red at their action, animations."""

from __future__ import annotations

import dataclasses

import matplotlib.colors as mcolors
import pytest

from earthbench.cli import main
from earthbench.running.figures import terrain_before_after, view_box
from earthbench.plan import Plan
from earthbench.referee import judge
from earthbench_planners.greedy.backhoe import GreedyPlanner
from earthbench_terrains.rbf import rbf


@pytest.fixture(scope="module")
def case():
    sc = rbf(0, 0.56, n_bases=14)
    return sc, GreedyPlanner().plan(sc)


def _red_artists(fig) -> int:
    red = mcolors.to_rgba("#d00000")
    return sum(1 for ax in fig.axes for line in ax.lines if mcolors.to_rgba(line.get_color()) == red
               or mcolors.to_rgba(line.get_markeredgecolor()) == red)


def test_crop_to_the_map_and_the_end_poses(case):
    sc, plan = case
    x0, x1, y0, y1 = view_box(sc, plan)
    ex0, ex1, ey0, ey1 = sc.terrain.extent
    assert x0 <= ex0 and x1 >= ex1 and y0 <= ey0 and y1 >= ey1
    assert y1 < sc.machines.truck_pose.y  # the truck's start (y = 13 on a 6 m map) is an edge marker, not empty space
    fig = terrain_before_after(sc, plan, judge(sc, plan))
    assert fig.axes[0].get_ylim() == pytest.approx((y0, y1))
    labels = fig.axes[0].get_legend_handles_labels()[1]
    assert {"dig area", "excavator", "truck", "reach annulus", "dump"} <= set(labels)
    assert _red_artists(fig) == 0  # a valid plan has no red


def test_violations_are_red_at_their_action(case):
    sc, plan = case
    jumped = Plan(tuple(dataclasses.replace(a, path=tuple((t, x + 3.0, y, w) for t, x, y, w in a.path))
                        if a.kind == "move" else a for a in plan.actions))
    verdict = judge(sc, jumped)
    assert "discontinuous" in {v.rule for v in verdict.violations}
    fig = terrain_before_after(sc, jumped, verdict)
    assert _red_artists(fig) >= 2  # the jump (dashed) and the move it starts, in each panel
    texts = [t.get_text() for ax in fig.axes for t in ax.texts]
    assert any("discontinuous" in t for t in texts)


def test_show_writes_the_figure_and_a_gif(tmp_path, case, capsys):
    sc, plan = case
    s, p = tmp_path / "s.json", tmp_path / "p.json"
    sc.to_json(s)
    plan.to_json(p)
    out, gif = tmp_path / "o.png", tmp_path / "o.gif"
    assert main(["show", "--scenario", str(s), "--plan", str(p), "-o", str(out), "--animate", str(gif), "--frames", "6"]) == 0
    assert out.stat().st_size > 10_000
    from PIL import Image

    with Image.open(gif) as im:
        assert im.n_frames >= 6 + 2  # evenly spaced frames plus one per dig and dump
    assert "frames" in capsys.readouterr().out
    assert main(["show", "--scenario", str(s), "--plan", str(p), "-o", str(out), "--animate", str(tmp_path / "o.avi")]) == 2
    assert ".gif or .mp4" in capsys.readouterr().err
