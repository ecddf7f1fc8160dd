"""The replay data: frames the referee computes, packed losslessly (to the quantum), strings that cannot escape."""

from __future__ import annotations

import base64
import json
import re
import zlib

import numpy as np
import pytest

from earthbench.plan import Plan
from earthbench.referee import judge
from earthbench.running.playback import QUANTUM, pick_runs, replay, replay_data, viewer_html
from earthbench.results.store import Store
from helpers.leaderboard import EVIL, Behaviour, fill_store, ref, standard_behaviours, suite_of
from earthbench_planners.greedy.backhoe import GreedyPlanner


@pytest.fixture(scope="module")
def case():
    sc = suite_of(1).scenarios[1]
    return sc, GreedyPlanner().plan(sc)


def _ints(packed: str) -> np.ndarray:
    kind, _, b64 = packed.partition(":")
    assert kind in ("i2", "i4")
    return np.frombuffer(zlib.decompress(base64.b64decode(b64)), dtype="<" + kind).astype(np.int64)


def test_frames_are_the_referees(case):
    sc, plan = case
    verdict, steps = replay(sc, plan)
    assert len(steps) == len(plan.actions)
    np.testing.assert_array_equal(steps[-1].z, verdict.final_terrain.z)
    assert steps[-1].loaded == pytest.approx(verdict.loaded_volume)
    digs = [s for s in steps if plan.actions[s.action].kind == "dig"]
    removed = [float((sc.terrain.z - s.z).sum() * sc.terrain.cell_area) for s in digs]
    assert removed == sorted(removed) and removed[0] > 0  # every dig takes more, never gives back


def test_packed_heights_rebuild_every_frame(case):
    sc, plan = case
    doc = replay_data(sc, plan, "label")
    g = doc["grid"]
    d = _ints(g["rows"]).reshape(g["ny"], g["nx"])
    assert g["rows"].startswith("i2:")  # small differences: 16 bits
    d[:, 0] = g["base"] + np.cumsum(d[:, 0])
    z = np.cumsum(d, axis=1)
    np.testing.assert_allclose(g["lo"] + z * g["q"], sc.terrain.z, atol=g["q"] / 2 + 1e-12)
    _, steps = replay(sc, plan)
    for ev, s in zip(doc["events"], steps):
        if "delta" in ev:
            d = ev["delta"]
            z[d["j"]:d["j"] + d["h"], d["i"]:d["i"] + d["w"]] += _ints(d["d"]).reshape(d["h"], d["w"])
        np.testing.assert_allclose(g["lo"] + z * g["q"], s.z, atol=g["q"] / 2 + 1e-12)
    assert g["q"] == QUANTUM
    assert sum("delta" in ev for ev in doc["events"]) == sum(a.kind == "dig" for a in plan.actions)


def test_violations_sit_at_their_action(case):
    sc, plan = case
    moved = Plan(tuple(a if a.kind != "move" else type(a)(a.machine, tuple((t, x + 3, y, w) for t, x, y, w in a.path))
                       for a in plan.actions))
    verdict = judge(sc, moved)
    assert not verdict.valid
    doc = replay_data(sc, moved, "teleport")
    marked = {(ev["a"], v["rule"]) for ev in doc["events"] for v in ev.get("violations", [])}
    assert marked == {(v.action, v.rule) for v in verdict.violations if v.action is not None}
    assert doc["verdict"] == verdict.summary()


def test_no_string_escapes_the_data_block(case):
    sc, plan = case
    html = viewer_html([replay_data(sc, plan, EVIL + "</script><b>&amp;")])
    block = re.search(r'<script type="application/json" id="rp-data">(.*?)</script>', html, re.S).group(1)
    assert "<" not in block and ">" not in block and "&" not in block
    assert json.loads(block)[0]["label"] == EVIL + "</script><b>&amp;"
    assert viewer_html([]) == ""


def test_pick_runs_takes_a_success_and_an_invalid_run_per_planner(tmp_path):
    behaviours = standard_behaviours() + [Behaviour(ref("jumpy"), teleport=4.0)]
    db = fill_store(tmp_path / "r.db", suite_of(2), behaviours)
    from earthbench.publishing.board.selection import published_runs

    with Store(db, create=False) as store:
        runs = published_runs(store)
    picked = pick_runs(runs, 6)
    assert len(picked) == 6 and picked["id"].is_unique
    assert set(picked["reason"]) <= {"ok", "invalid"}
    jumpy = picked[picked["planner"] == "jumpy"]
    assert "invalid" in set(jumpy["reason"])
    assert len(pick_runs(runs, 0)) == 0


def _prefix_frames(sc, plan):
    """The definition the viewer's frames must meet: the referee's judgement of the digs,
    charges and dumps up to each action (moves cut nothing), one judgement per action."""
    order = sorted(range(len(plan.actions)), key=lambda n: (plan.actions[n].t_start, n))
    work, frames = [], []
    z, loaded = sc.terrain.z, 0.0
    for n in order:
        if plan.actions[n].kind in ("dig", "charge", "dump"):
            work.append(plan.actions[n])
            v = judge(sc, Plan(tuple(work)))
            z, loaded = v.final_terrain.z, v.loaded_volume
        frames.append((n, z, loaded))
    return frames


def _loader_case():
    from earthbench.results.suite import load_suite
    from earthbench_planners.singh_cannon.loader import SinghCannonLoader

    sc = load_suite("pile").scenarios[0]
    return sc, SinghCannonLoader().plan(sc)


@pytest.mark.parametrize("which", ["greedy", "teleporting", "loader"])
def test_one_judgement_gives_the_frames_of_judging_every_prefix(case, which):
    if which == "loader":
        sc, plan = _loader_case()
    else:
        sc, plan = case
        if which == "teleporting":  # invalid: the frames still show what the referee cut
            plan = Plan(tuple(a if a.kind != "move" else type(a)(a.machine, tuple((t, x + 3, y, w) for t, x, y, w in a.path))
                              for a in plan.actions))
    verdict, steps = replay(sc, plan)
    assert verdict == judge(sc, plan)
    expected = _prefix_frames(sc, plan)
    assert [s.action for s in steps] == [n for n, _, _ in expected]
    for s, (_, z, loaded) in zip(steps, expected):
        np.testing.assert_array_equal(s.z, z)
        assert s.loaded == loaded


def test_a_plan_that_changes_no_cell_still_replays(case):
    sc, plan = case
    moves_only = Plan(tuple(a for a in plan.actions if a.kind == "move"))
    doc = replay_data(sc, moves_only, "moves only")
    assert json.loads(json.dumps(doc))["label"] == "moves only"
