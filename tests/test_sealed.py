"""Sealed evaluation (issue 34, docs/sealed-evaluation.md): what a case can know, what a sealed
draw hides, what a revealed key proves, and that a known suite name means one world.

The hostile planners of ``tests/plugins/sealing_planners.py`` document the trust model: each
trick works on the public suite and gains nothing on a sealed draw.
"""

from __future__ import annotations

import json
import math
import sqlite3
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from helpers.leaderboard import Behaviour, fill_store, ref, suite_of

from earthbench.cli import main
from earthbench.errors import EarthbenchError
from earthbench.results.generalisation import gap_table
from earthbench.running.harness import build_cases, run_case
from earthbench.results.identity import variant_name
from earthbench.publishing.merge import MergeError, merge
from earthbench.registry import PLANNERS, load_plugin_file
from earthbench.results.scoring import score
from earthbench.seal import SealError, SealKey, SiteTransform, public_name
from earthbench.sensing import ANONYMOUS_ID, observe
from earthbench.results.store import SCHEMA_VERSION, Store, load_runs
from earthbench.results.suite import load_suite, new_key, open_sealed
from earthbench_planners.greedy.backhoe import GreedyPlanner

PLUGIN = str(Path(__file__).parent / "plugins" / "sealing_planners.py")

REALISTIC = """name = "tiny-realistic"
track = "backhoe"
success_threshold = 0.9
[budget]
wall_s = 60
cores = 2
memory_mb = 4096
[[family]]
name = "rbf14-sand"
generator = "rbf"
targets = [0.56]
seeds = [0, 1]
[family.params]
n_bases = 14
[family.soil]
material = "sand"
[family.sensing]
noise = 0.01
occlusion = false
"""


@pytest.fixture(scope="module")
def realistic(tmp_path_factory):
    """A two-scenario realistic suite file, its sealed key, and the hostile planners' configuration.

    The hostile planners are registered for this module only (they must not join later tests'
    default planner lists)."""
    before = set(PLANNERS.names())
    load_plugin_file(PLUGIN)
    d = tmp_path_factory.mktemp("sealed")
    suite_file = d / "tiny-realistic.toml"
    suite_file.write_text(REALISTIC)
    suite = load_suite(suite_file)
    table = {observe(sc).digest: GreedyPlanner().plan(sc).to_json() for sc in suite.scenarios}  # computed "offline"
    (d / "table.json").write_text(json.dumps(table))
    suite_file.write_text(REALISTIC + f'[config.t-oracle]\nsuites = ["{suite_file}"]\n[config.t-lookup]\ntable = "{d / "table.json"}"\n')
    key, _ = new_key(load_suite(suite_file))
    key.write(d / "tiny.key")
    yield d, suite_file, d / "tiny.key"
    for name in set(PLANNERS.names()) - before:
        PLANNERS.unregister(name)


def _tricks(db: Path, suite: str) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    with Store(db, read_only=True) as st:
        for r in st.query(suite=suite):
            if r["planner"].startswith("t-"):
                out.setdefault(r["planner"], []).append(json.loads(st.plan_json(r["id"]))["info"]["trick"])
    return out


# -- what a case receives ----------------------------------------------------------------------


def test_every_observation_is_anonymous_on_both_tracks():
    for sc in (load_suite("smoke").scenarios[0], load_suite("bench-realistic").scenarios[0]):
        view = observe(sc)
        assert (view.id, view.meta) == (ANONYMOUS_ID, {}) and sc.id != ANONYMOUS_ID and sc.meta


def test_a_case_process_reads_no_name_of_its_scenario(realistic, tmp_path, monkeypatch):
    d, suite_file, key_file = realistic
    monkeypatch.setenv("EARTHBENCH_DB", str(tmp_path / "the-store.db"))  # the harness is told where its store is; a case is not
    sealed = open_sealed(load_suite(suite_file), SealKey.read(key_file))
    (case,), _ = build_cases(sealed, ["t-witness"], plugins=[PLUGIN], seeds=[1])
    seen = json.dumps(json.loads(run_case(case).plan_json)["info"])
    assert "the-store.db" not in seen
    sc = case.scenario
    for secret in (sc.id, sc.digest, sealed.name, "tiny-realistic/rbf14-sand/s1", SealKey.read(key_file).commitment[:12],
                   str(key_file), suite_file.name, "~sealed-", "rbf14-sand"):
        assert secret not in seen, secret


# -- sealed draws --------------------------------------------------------------------------------


def test_a_sealed_draw_is_reproducible_from_its_key_and_nothing_else(realistic):
    _, suite_file, key_file = realistic
    public, key = load_suite(suite_file), SealKey.read(key_file)
    a, b = open_sealed(public, key), open_sealed(public, key)
    assert [s.digest for s in a.scenarios] == [s.digest for s in b.scenarios]
    assert public_name(a.name) == "tiny-realistic" and a.digest != public.digest
    assert not {s.digest for s in a.scenarios} & {s.digest for s in public.scenarios}
    for pub, sea in zip(public.scenarios, a.scenarios):
        assert sea.meta["seed"] == pub.meta["seed"] and sea.meta["sealed"] is True  # --seeds selects the same draws
        assert sea.soil != pub.soil and sea.soil.material == pub.soil.material  # redrawn, same class
        assert sea.sensing.seed != pub.sensing.seed and sea.sensing.noise == pub.sensing.noise
    other, _ = new_key(public)
    assert other.commitment != key.commitment


def test_a_key_that_does_not_match_is_refused_with_one_line(realistic, tmp_path, capsys):
    _, suite_file, key_file = realistic
    doc = json.loads(key_file.read_text())
    edited = tmp_path / "edited.key"
    edited.write_text(json.dumps({**doc, "key": "00" * 32}))
    with pytest.raises(SealError, match="commitment"):
        open_sealed(load_suite(suite_file), SealKey.read(edited))
    with pytest.raises(SealError, match="made for suite"):
        open_sealed(load_suite("smoke"), SealKey.read(key_file))
    (tmp_path / "junk.key").write_text("{}")
    assert main(["run", str(suite_file), "--sealed", str(tmp_path / "junk.key"), "--db", str(tmp_path / "x.db")]) == 2
    assert "not an earthbench key file" in capsys.readouterr().err
    assert main(["seal", str(suite_file), "--key", str(key_file)]) == 2  # never overwrites a key
    assert "never overwritten" in capsys.readouterr().err


@pytest.mark.parametrize("turns,mirror", [(t, m) for t in range(4) for m in (False, True)])
def test_the_site_transform_is_a_rigid_motion_of_the_whole_site(turns, mirror):
    sc = load_suite("smoke").scenarios[1]
    moved = SiteTransform(turns, mirror, (3.5, -12.25)).apply(sc)
    xs, ys = np.random.default_rng(1).uniform(0.3, 5.7, (2, 40))
    xs = xs * 2  # inside the 12 m × 6 m map
    px, py = xs - 6.0, ys - 3.0
    if mirror:
        px = -px
    for _ in range(turns):
        px, py = -py, px
    assert np.allclose(moved.terrain.heights_at(px + 6.0 + 3.5, py + 3.0 - 12.25), sc.terrain.heights_at(xs, ys), atol=1e-12)
    assert moved.terrain.volume_above(0.0) == pytest.approx(sc.terrain.volume_above(0.0))
    e0, e1 = sc.machines.excavator_pose, moved.machines.excavator_pose
    t0, t1 = sc.machines.truck_pose, moved.machines.truck_pose
    assert math.dist((e0.x, e0.y), (t0.x, t0.y)) == pytest.approx(math.dist((e1.x, e1.y), (t1.x, t1.y)))
    plan = GreedyPlanner().plan(observe(moved))  # an honest planner plans the moved site as it would the original
    assert score(moved, plan.to_json(), 0.9)[1]["success"]


# -- hostile planners: each trick works in public and gains nothing sealed -------------------------


@pytest.mark.usefixtures("isolation_off")
def test_regenerating_or_looking_up_the_world_gains_nothing_on_a_sealed_draw(realistic, tmp_path):
    """Run without isolation: a sandboxed case could not read the suite file or the table at all
    (docs/isolation.md), and the seal must hold where isolation is not available."""
    _, suite_file, key_file = realistic
    db = tmp_path / "hostile.db"
    common = ["--plugin", PLUGIN, "--db", str(db), "--quiet", "--jobs", "1"]
    hostile = ["--planner", "t-oracle", "--planner", "t-lookup"]
    assert main(["run", str(suite_file), *hostile, *common]) == 0
    assert main(["run", str(suite_file), "--sealed", str(key_file), *hostile, "--planner", "greedy", *common]) == 0
    sealed = SealKey.read(key_file).name
    assert _tricks(db, "tiny-realistic") == {"t-oracle": ["hit", "hit"], "t-lookup": ["hit", "hit"]}  # public: recognised
    assert _tricks(db, sealed) == {"t-oracle": ["miss", "miss"], "t-lookup": ["miss", "miss"]}  # sealed: 0 hits
    runs = load_runs(db, suite=sealed)
    success = runs.groupby("planner")["success"].sum()
    assert success["t-oracle"] == success["t-lookup"] == success["greedy"]  # the honest planner's figures, no more
    assert main(["verify", str(db), "--key", str(key_file)]) == 0


# -- verify with a revealed key -------------------------------------------------------------------


def test_verify_regenerates_the_draw_and_catches_an_edited_sealed_scenario(realistic, tmp_path, capsys):
    _, suite_file, key_file = realistic
    sealed = open_sealed(load_suite(suite_file), SealKey.read(key_file))
    db = fill_store(tmp_path / "sealed.db", sealed, [Behaviour(ref("greedy"))])
    assert main(["verify", str(db), "--key", str(key_file)]) == 0
    out = capsys.readouterr().out
    assert f"sealed draw {sealed.name}: holds" in out and "2 scenario(s) regenerated and matched" in out
    assert "re-judged 2 plan(s): 2 agree" in out
    other = tmp_path / "other.key"
    key2, _ = new_key(load_suite(suite_file))
    key2.write(other)
    assert main(["verify", str(db), "--key", str(other)]) == 1
    assert "holds no suite" in capsys.readouterr().out
    with sqlite3.connect(db) as con:  # swap a sealed scenario's member digest for the public one: an easier world
        public = load_suite(suite_file).scenarios[0].digest
        con.execute("UPDATE suite_scenarios SET scenario_digest=? WHERE scenario_id LIKE '%/s0/%'", (public,))
    assert main(["verify", str(db), "--key", str(key_file)]) == 1
    assert "the key regenerates" in capsys.readouterr().out


# -- pinned suite identity ----------------------------------------------------------------------


def test_a_known_name_with_the_registered_world_merges(tmp_path):
    db = fill_store(tmp_path / "smoke.db", load_suite("smoke"), [Behaviour(ref("greedy"))])
    assert merge(tmp_path / "out.db", [db]).runs == 4
    assert main(["verify", str(tmp_path / "out.db")]) == 0


def test_a_different_world_under_a_known_name_is_refused_with_both_digests(tmp_path, capsys):
    fake = suite_of(1, name="smoke", targets=(0.56,))  # an easier world called smoke
    db = fill_store(tmp_path / "renamed.db", fake, [Behaviour(ref("greedy"))])
    with pytest.raises(MergeError, match="different world under a known name") as exc:
        merge(tmp_path / "out.db", [db])
    assert fake.digest[:12] in str(exc.value) and load_suite("smoke").digest[:12] in str(exc.value)
    assert not (tmp_path / "out.db").exists()
    assert main(["verify", str(db)]) == 1
    assert "different world under a known name" in capsys.readouterr().out


def test_as_variant_stores_the_other_world_under_a_name_that_says_so(tmp_path):
    fake = suite_of(1, name="smoke", targets=(0.56,))
    db = fill_store(tmp_path / "renamed.db", fake, [Behaviour(ref("greedy"))])
    assert main(["merge", str(tmp_path / "out.db"), str(db), "--as-variant"]) == 0
    with Store(tmp_path / "out.db", read_only=True) as st:
        names = [r[0] for r in st.db.execute("SELECT name FROM suites")]
        labels = {r[0] for r in st.db.execute("SELECT suite FROM runs")}
    assert names == [variant_name("smoke", fake.digest)] and labels == set(names)
    assert main(["verify", str(tmp_path / "out.db")]) == 0


def test_a_sealed_looking_name_without_a_seal_is_refused(tmp_path):
    fake = suite_of(1, name="smoke~sealed-0123456789ab", targets=(0.56,))
    db = fill_store(tmp_path / "fake-seal.db", fake, [Behaviour(ref("greedy"))])
    with pytest.raises(MergeError, match="carries no seal"):
        merge(tmp_path / "out.db", [db])


def test_a_sealed_draw_of_another_world_is_refused(realistic, tmp_path):
    key, sealed = new_key(suite_of(1, name="smoke", targets=(0.56,)))  # drawn from a fake smoke
    db = fill_store(tmp_path / "fake-draw.db", sealed, [Behaviour(ref("greedy"))])
    with pytest.raises(MergeError, match="a sealed draw of another world"):
        merge(tmp_path / "out.db", [db])


# -- the store's schema ---------------------------------------------------------------------------


def test_a_version_2_store_gains_the_seal_columns_in_its_own_step(tmp_path):
    db = fill_store(tmp_path / "old.db", suite_of(1, targets=(0.56,)), [Behaviour(ref("greedy"))])
    with sqlite3.connect(db) as con:
        for table, cols in (("suites", ("sealed_from", "public_digest", "commitment")), ("scenarios", ("sealed",)), ("runs", ("sealed",))):
            for c in cols:
                con.execute(f"ALTER TABLE {table} DROP COLUMN {c}")
        con.execute("PRAGMA user_version = 2")
    assert not load_runs(Store(db, read_only=True))["sealed"].any()  # read-only: read as it is
    with Store(db) as st:
        assert st.db.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION  # 3 and every later step
        assert "sealed" in {r[1] for r in st.db.execute("PRAGMA table_info(runs)")}
    assert list(load_runs(db)["sealed"]) == [False]


def test_sealed_runs_are_marked_in_the_store(realistic, tmp_path):
    _, suite_file, key_file = realistic
    sealed = open_sealed(load_suite(suite_file), SealKey.read(key_file))
    db = fill_store(tmp_path / "s.db", sealed, [Behaviour(ref("greedy"))])
    with Store(db, read_only=True) as st:
        row = st.db.execute("SELECT sealed_from, public_digest, commitment FROM suites").fetchone()
        assert tuple(row) == ("tiny-realistic", load_suite(suite_file).digest, SealKey.read(key_file).commitment)
        assert {r[0] for r in st.db.execute("SELECT sealed FROM scenarios")} == {1}
    assert load_runs(db)["sealed"].all()


# -- the generalisation gap ------------------------------------------------------------------------


def _runs(planner: str, suite: str, successes: list[bool], times: list[float]) -> pd.DataFrame:
    return pd.DataFrame({"suite": suite, "planner": planner, "planner_version": "1", "config_hash": "c",
                         "scenario_digest": [f"{suite}-{i}" for i in range(len(successes))], "success": successes,
                         "reason": "ok", "time_per_target_m3": times, "volume_ratio": 1.0})


def test_the_gap_is_sealed_minus_public_and_a_planner_outside_the_public_interval_is_flagged():
    rng = np.random.default_rng(0)
    t = list(rng.normal(40, 2, 30))
    runs = pd.concat([
        _runs("honest", "s", [True] * 30, t), _runs("honest", "s~sealed-aaaaaaaaaaaa", [True] * 30, list(rng.normal(40, 2, 30))),
        _runs("memoriser", "s", [True] * 30, t), _runs("memoriser", "s~sealed-aaaaaaaaaaaa", [True] * 10 + [False] * 20, t),
    ], ignore_index=True)
    members = pd.DataFrame({"suite": ["s"] * 30 + ["s~sealed-aaaaaaaaaaaa"] * 30,
                            "scenario_digest": [f"s-{i}" for i in range(30)] + [f"s~sealed-aaaaaaaaaaaa-{i}" for i in range(30)]})
    g = gap_table(runs, members).set_index(["planner", "metric"])
    assert not g.loc[("honest", "success_rate"), "flagged"] and not g.loc[("honest", "time_per_target_m3"), "flagged"]
    m = g.loc[("memoriser", "success_rate")]
    assert m["flagged"] and m["gap"] == pytest.approx(-2 / 3) and m["gap_lo"] <= m["gap"] <= m["gap_hi"] < 0
    assert (g["draws"] == 1).all()


def test_a_public_sample_without_spread_flags_no_chance_failure_but_a_real_drop_is_flagged():
    """Public volume ratios all 1 have a bootstrap interval of no width; four sealed failures in
    220 (the 0.2.0 board's stl-tamp) are not evidence of a gap (Fisher p = 0.31), forty are."""
    def runs(name: str, sealed_failures: int) -> pd.DataFrame:
        pub = _runs(name, "s", [True] * 110, [30.0] * 110)
        sea = _runs(name, "s~sealed-aaaaaaaaaaaa", [True] * (220 - sealed_failures) + [False] * sealed_failures, [30.0] * 220)
        sea["volume_ratio"] = [1.0] * (220 - sealed_failures) + [0.55] * sealed_failures
        return pd.concat([pub, sea], ignore_index=True)

    members = pd.DataFrame({"suite": ["s"] * 110 + ["s~sealed-aaaaaaaaaaaa"] * 220,
                            "scenario_digest": [f"s-{i}" for i in range(110)] + [f"s~sealed-aaaaaaaaaaaa-{i}" for i in range(220)]})
    g = gap_table(pd.concat([runs("chance", 4), runs("drop", 40)], ignore_index=True), members).set_index(["planner", "metric"])
    chance, drop = g.loc[("chance", "volume_ratio")], g.loc[("drop", "volume_ratio")]
    assert chance["public_lo"] == chance["public_hi"] == 1.0 and chance["sealed_hi"] < chance["public_lo"]  # the intervals are disjoint
    assert not chance["flagged"] and not g.loc[("chance", "success_rate"), "flagged"]
    assert g.loc[("chance", "success_rate"), "p_value"] == pytest.approx(0.31, abs=0.01)
    assert drop["flagged"] and g.loc[("drop", "success_rate"), "flagged"] and drop["p_value"] < 0.01


def test_bad_key_files_are_one_line_errors(tmp_path):
    for text in ("not json", json.dumps({"schema": "earthbench.seal/1", "suite": "x"}), json.dumps([1])):
        p = tmp_path / "k"
        p.write_text(text)
        with pytest.raises(EarthbenchError):
            SealKey.read(p)
    with pytest.raises(EarthbenchError, match="not found|cannot read|no such"):
        SealKey.read(tmp_path / "missing.key")


def test_the_gap_table_uses_the_boards_intervals_and_counts_a_run_short_of_the_target_as_infinite():
    """Runs that stop short of the target (∞ time to it) make the sealed median worse, never
    better; the success rate gets its exact interval (30/30 is not [100 %–100 %])."""
    rng = np.random.default_rng(1)
    public = list(rng.normal(40, 2, 30))
    sealed = list(rng.normal(35, 2, 6)) + [math.inf] * 24  # faster where it loads the target, short elsewhere
    runs = pd.concat([_runs("stopper", "s", [True] * 30, public),
                      _runs("stopper", "s~sealed-aaaaaaaaaaaa", [True] * 6 + [False] * 24, sealed)], ignore_index=True)
    members = pd.DataFrame({"suite": ["s"] * 30 + ["s~sealed-aaaaaaaaaaaa"] * 30,
                            "scenario_digest": [f"s-{i}" for i in range(30)] + [f"s~sealed-aaaaaaaaaaaa-{i}" for i in range(30)]})
    g = gap_table(runs, members).set_index(["planner", "metric"])
    t = g.loc[("stopper", "time_per_target_m3")]
    assert t["sealed"] == math.inf and t["sealed_n"] == 30 and t["gap"] == math.inf
    assert t["flagged"] and t["gap_lo"] > 0  # worse beyond doubt: stopping short never looks faster
    r = g.loc[("stopper", "success_rate")]
    assert r["public"] == 1.0 and 0.88 < r["public_lo"] < 0.89 and r["public_hi"] == 1.0


def test_new_key_and_open_sealed_still_import_from_the_seal_with_a_warning():
    """They moved to earthbench.results.suite (they draw a suite; the seal no longer imports it)."""
    import earthbench.seal
    import earthbench.results.suite

    for name in ("new_key", "open_sealed"):
        with pytest.warns(DeprecationWarning, match=rf"earthbench\.seal\.{name} moved to earthbench\.results\.suite\.{name}"):
            assert getattr(earthbench.seal, name) is getattr(earthbench.results.suite, name)
