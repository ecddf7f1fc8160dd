"""Verifiable submissions: merge re-judges every plan, export bundles, spot re-timing.

Stores are written through the store's own API with real greedy plans judged by the referee
(``helpers.leaderboard``), then tampered with in SQL the way a hand edit would.
"""

from __future__ import annotations

import hashlib
import json
import sqlite3
import zlib
from contextlib import closing
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from earthbench.cli import main
from earthbench.publishing.merge import MergeError, merge
from earthbench.results.store import Store, load_runs
from earthbench.registry import PLANNERS
from earthbench.publishing.verify import Judgement, audit, differences, rejudge, same
from helpers.leaderboard import Behaviour, fill_store, ref, suite_of


@pytest.fixture(scope="module")
def clean(tmp_path_factory) -> Path:
    """greedy (every run a plan) and flaky (a timeout, without a plan, on every second scenario)."""
    return fill_store(
        tmp_path_factory.mktemp("verify") / "clean.db",
        suite_of(2),
        [Behaviour(ref("greedy", PLANNERS.get("greedy").version)), Behaviour(ref("flaky"), keep=0.5, fail="timeout", fail_every=2)],
    )


def _copy(src: Path, dst: Path) -> Path:
    with closing(sqlite3.connect(src)) as a, closing(sqlite3.connect(dst)) as b:
        a.backup(b)
    return dst


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _edit(db: Path, sql: str, *args) -> None:
    """A hand edit, checkpointed into the file so that its bytes are the store's whole content."""
    with closing(sqlite3.connect(db)) as con:
        with con:
            con.execute(sql, args)
        con.execute("PRAGMA wal_checkpoint(TRUNCATE)")


def _greedy_ok(db: Path) -> int:
    with closing(sqlite3.connect(db)) as con:
        return con.execute("SELECT MIN(id) FROM runs WHERE planner='greedy' AND reason='ok'").fetchone()[0]


def test_clean_store_agrees_and_merges(clean, tmp_path, capsys):
    src = _copy(clean, tmp_path / "in.db")
    with Store(src, create=False) as st:
        a = audit(st)
    assert a.problems() == [] and a.agreed == 6 and a.unjudged == {"timeout": 2}
    before = _sha(src)
    assert main(["merge", str(tmp_path / "out.db"), str(src)]) == 0
    out = capsys.readouterr().out
    assert "re-judged 6 plan(s): 6 agree" in out
    assert "2 run(s) without a plan (2 timeout)" in out and "cannot be re-checked" in out
    assert _sha(src) == before
    assert len(load_runs(tmp_path / "out.db")) == 8


def _tamper_metric_column(db):
    _edit(db, "UPDATE runs SET volume_ratio = volume_ratio * 1.5 WHERE id=?", _greedy_ok(db))
    return "column volume_ratio"


def _tamper_metric_json(db):
    rid = _greedy_ok(db)
    with closing(sqlite3.connect(db)) as con:
        m = json.loads(con.execute("SELECT metrics FROM runs WHERE id=?", (rid,)).fetchone()[0])
    m["time_per_m3"] = m["time_per_m3"] * 0.5
    _edit(db, "UPDATE runs SET metrics=? WHERE id=?", json.dumps(m), rid)
    return "metric time_per_m3"


def _tamper_plan(db):
    rid = _greedy_ok(db)
    with closing(sqlite3.connect(db)) as con:
        plan = json.loads(zlib.decompress(con.execute("SELECT plan FROM runs WHERE id=?", (rid,)).fetchone()[0]))
    plan["actions"] = plan["actions"][:-2]  # drop the last dig and dump: it loads less than it claims
    _edit(db, "UPDATE runs SET plan=? WHERE id=?", zlib.compress(json.dumps(plan).encode()), rid)
    return "metric loaded_volume"


def _tamper_scenario(db):
    with closing(sqlite3.connect(db)) as con:
        digest, doc = con.execute("SELECT digest, doc FROM scenarios LIMIT 1").fetchone()
    d = json.loads(zlib.decompress(doc))
    d["task"]["target_volume"] = d["task"]["target_volume"] / 2  # an easier task under the same digest
    _edit(db, "UPDATE scenarios SET doc=? WHERE digest=?", zlib.compress(json.dumps(d).encode()), digest)
    return "does not reproduce the digest"


def _tamper_scenario_digest(db):
    """Label a run with another digest: its scenario is then not stored under it."""
    _edit(db, "UPDATE runs SET scenario_digest=? WHERE id=?", "0" * 64, _greedy_ok(db))
    return "not a member of suite"


def _tamper_suite_digest(db):
    _edit(db, "UPDATE suites SET digest=?", "f" * 64)
    _edit(db, "UPDATE runs SET suite_digest=?", "f" * 64)
    return "is not the one its"


def _tamper_threshold(db):
    _edit(db, "UPDATE runs SET threshold=0.1 WHERE id=?", _greedy_ok(db))
    return "threshold 0.1 is not its suite's"


def _tamper_missing_plan(db):
    _edit(db, "UPDATE runs SET plan=NULL WHERE id=?", _greedy_ok(db))
    return "without a plan: its verdict cannot be verified"


def _tamper_timeout_claims(db):
    _edit(db, "UPDATE runs SET success=1 WHERE reason='timeout'")
    return "without a plan, yet it carries referee figures"


TAMPERS = [_tamper_metric_column, _tamper_metric_json, _tamper_plan, _tamper_scenario, _tamper_scenario_digest,
           _tamper_suite_digest, _tamper_threshold, _tamper_missing_plan, _tamper_timeout_claims]


@pytest.mark.parametrize("tamper", TAMPERS, ids=[t.__name__[len("_tamper_"):] for t in TAMPERS])
def test_tampered_store_is_refused_untouched_and_nothing_written(clean, tmp_path, capsys, tamper):
    src = _copy(clean, tmp_path / "in.db")
    what = tamper(src)
    before = _sha(src)
    out = tmp_path / "out.db"
    assert main(["merge", str(out), str(src)]) == 2
    err = capsys.readouterr().err
    assert "merge refused, nothing was written" in err and what in err, err
    assert "Traceback" not in err
    if tamper not in (_tamper_suite_digest, _tamper_scenario):  # those name the suite or every run of the scenario
        assert f"run {_greedy_ok(src) if tamper is not _tamper_timeout_claims else ''}" in err
    assert not out.exists() and not list(tmp_path.glob(".out.db*"))
    assert _sha(src) == before and not Path(f"{src}-wal").exists() and not Path(f"{src}-shm").exists()
    # into an existing store: refused the same way, the store is unchanged
    existing = _copy(clean, tmp_path / "existing.db")
    _edit(existing, "DELETE FROM runs")
    was = _sha(existing)
    with pytest.raises(MergeError, match="nothing was written"):
        merge(existing, [src])
    assert _sha(existing) == was


@pytest.mark.parametrize("tamper", [_tamper_metric_column, _tamper_metric_json, _tamper_plan])
def test_rescore_replaces_differing_figures_and_counts_them(clean, tmp_path, capsys, tamper):
    src = _copy(clean, tmp_path / "in.db")
    tamper(src)
    out = tmp_path / "out.db"
    assert main(["merge", "--rescore", str(out), str(src)]) == 0
    cap = capsys.readouterr()
    assert "5 agree with the stored figures, 1 re-scored" in cap.out
    assert f"re-scored {src}: run {_greedy_ok(src)} (" in cap.err
    with Store(out, create=False) as st:  # everything in the output is what the referee says
        a = audit(st)
    assert a.problems() == [] and a.agreed == 6


@pytest.mark.parametrize("tamper", [_tamper_missing_plan, _tamper_scenario, _tamper_suite_digest])
def test_rescore_never_lets_unverifiable_runs_in(clean, tmp_path, tamper):
    src = _copy(clean, tmp_path / "in.db")
    what = tamper(src)
    with pytest.raises(MergeError, match=what):
        merge(tmp_path / "out.db", [src], rescore=True)
    assert not (tmp_path / "out.db").exists()


def test_rescore_command_uses_the_same_judgement(clean, tmp_path, capsys):
    db = _copy(clean, tmp_path / "db.db")
    _tamper_metric_column(db)
    assert main(["rescore", "--db", str(db)]) == 0
    with Store(db, create=False) as st:
        assert audit(st).problems() == []


def test_same_allows_round_off_only():
    assert same(1.0, 1.0 + 1e-12) and same(float("nan"), float("nan")) and same(float("inf"), float("inf"))
    assert not same(1.0, 1.0 + 1e-6) and not same(float("inf"), 1e308) and not same(True, False)
    assert same({"a": [1, 2.0]}, {"a": [1.0, 2]}) and not same({"a": 1}, {"a": 1, "b": 2})


def test_rejudge_of_a_malformed_plan_is_invalid_not_a_crash(clean):
    with Store(clean, create=False) as st:
        row = st.query(planner=["greedy"])[0]
        sc = st.scenario(row["scenario_digest"])
    j = rejudge(sc, '{"schema": "earthbench.plan/1", "actions": 42}', 0.9)
    assert j.reason == "invalid" and j.violations[0]["rule"] == "malformed"
    assert any("reason ok (re-judged invalid)" in d for d in differences(row, j))
    assert differences(row, Judgement("error", None, (), "boom"))  # a referee failure never matches a verdict


# -- export --------------------------------------------------------------------------------------


def test_export_bundle_holds_what_verifying_needs_and_merges(tmp_path, capsys):
    suite = suite_of(2)
    db = fill_store(tmp_path / "all.db", suite, [Behaviour(ref("greedy")), Behaviour(ref("half"), keep=0.5)])
    bundle = tmp_path / "greedy.bundle.db"
    assert main(["export", "--db", str(db), "--suite", suite.name, "--planner", "greedy", str(bundle)]) == 0
    assert "exported 4 run(s)" in capsys.readouterr().out
    with Store(bundle, create=False) as b:
        assert {r["planner"] for r in b.query()} == {"greedy"} and len(b.query()) == 4
        for r in b.query():
            assert b.plan_json(r["id"]) and b.scenario(r["scenario_digest"]).digest == r["scenario_digest"]
        assert b.db.execute("SELECT COUNT(*) FROM environments").fetchone()[0] >= 1
        assert b.db.execute("SELECT COUNT(*) FROM planner_configs").fetchone()[0] == 1
        assert audit(b).problems() == []
    # the receiving side: a store with the other planner, then the bundle
    other = fill_store(tmp_path / "other.db", suite, [Behaviour(ref("half"), keep=0.5)])
    merge(tmp_path / "pub.db", [other, bundle])
    assert sorted(load_runs(tmp_path / "pub.db").planner.unique()) == ["greedy", "half"]


def test_export_bad_input(tmp_path, capsys, clean):
    exists = tmp_path / "x.db"
    exists.write_bytes(b"keep me")
    assert main(["export", "--db", str(clean), "--suite", "pubtest", "--planner", "greedy", str(exists)]) == 2
    assert exists.read_bytes() == b"keep me"
    assert main(["export", "--db", str(clean), "--suite", "pubtset", "--planner", "greedy", str(tmp_path / "y.db")]) == 2
    assert "did you mean 'pubtest'" in capsys.readouterr().err
    assert main(["export", "--db", str(clean), "--suite", "pubtest", "--planner", "gredy", str(tmp_path / "y.db")]) == 2
    err = capsys.readouterr().err
    assert "did you mean 'greedy'" in err and "Traceback" not in err
    assert not (tmp_path / "y.db").exists()
    assert main(["export", "--db", str(clean), "--suite", "pubtest", "--planner", "greedy", str(tmp_path / "no" / "y.db")]) == 2
    assert "does not exist; create it first" in capsys.readouterr().err


# -- spot re-timing -------------------------------------------------------------------------------


def test_verify_refuses_a_planner_version_not_installed(clean, tmp_path, capsys):
    old = fill_store(tmp_path / "old.db", suite_of(1, targets=(0.56,)), [Behaviour(ref("greedy", "0.0-old"))])
    before = _sha(old)
    assert main(["verify", str(old), "--sample", "1"]) == 2
    err = capsys.readouterr().err
    assert "is installed, but the runs to re-time are of version 0.0-old" in err and "Traceback" not in err
    assert _sha(old) == before
    db = _copy(clean, tmp_path / "db.db")  # the fixture's greedy (the installed version) has a configuration hash of its own
    assert main(["verify", str(db), "--sample", "2", "--planner", "greedy"]) == 2
    assert "Config changed without a version bump" in capsys.readouterr().err
    assert main(["verify", str(db), "--sample", "2", "--planner", "nobody"]) == 2
    assert "planner 'nobody' has no runs in" in capsys.readouterr().err  # with the planners there
    assert main(["verify", str(db), "--sample", "2", "--planner", "flaky"]) == 2
    assert "unknown planner 'flaky'" in capsys.readouterr().err


def test_verify_reruns_a_sample_here_and_the_leaderboard_shows_it(tmp_path, capsys):
    """A real case under the harness: greedy on one small scenario, rerun by ``verify``."""
    suite_file = tmp_path / "tiny.toml"
    suite_file.write_text('name = "tiny"\ntrack = "backhoe"\n[budget]\nwall_s = 60\ncores = 2\nmemory_mb = 4096\n'
                          '[[family]]\nname = "rbf14"\ngenerator = "rbf"\ntargets = [0.56]\nseeds = "0-1"\n'
                          '[family.params]\nn_bases = 14\n')
    db = tmp_path / "tiny.db"
    assert main(["run", str(suite_file), "--planner", "greedy", "--db", str(db), "--jobs", "1"]) == 0
    capsys.readouterr()
    assert main(["verify", str(db), "--sample", "1", "--seed", "3"]) == 0
    out = capsys.readouterr().out
    assert "greedy" in out and "1/1" in out and "solve ratio median" in out and "CPU ratio median" in out and "load here" in out
    from earthbench.publishing.publish import publish

    page = publish(db, tmp_path / "board", figures=False)
    md = (page.out / "README.md").read_text()
    assert "spot re-timing: greedy" in md and "referee figures agree 1/1" in md
    assert "solve times of greedy" in md


# -- provenance in the leaderboard ------------------------------------------------------------------


def test_leaderboard_names_the_machine_of_each_planners_solve_times(tmp_path):
    from earthbench.publishing.publish import publish

    suite = suite_of(1)
    a = fill_store(tmp_path / "a.db", suite, [Behaviour(ref("greedy"))])
    b = fill_store(tmp_path / "b.db", suite, [Behaviour(ref("half"), keep=0.5, cpu_model="Other CPU 9000")])
    single = publish(a, tmp_path / "one", figures=False)
    md = (single.out / "README.md").read_text()
    assert "provenance: success, volume and time-per-m³ figures are the referee's" in md
    assert "†" not in md and "solve times of greedy 1.0: " in md
    merge(tmp_path / "all.db", [a, b])
    both = publish(tmp_path / "all.db", tmp_path / "two", figures=False)
    md = (both.out / "README.md").read_text()
    assert "| Solve CPU s (median) † |" in md and "| Solve wall s (median) † |" in md and "solve-time columns mix machines" in md
    assert "solve times of half 1.0: " in md and "Other CPU 9000" in md.split("solve times of half 1.0: ")[1].splitlines()[0]
    page = (both.out / "index.html").read_text()
    assert "solve times of greedy 1.0: " in page and "Solve CPU s (median) †" in page
    runs = load_runs(tmp_path / "all.db")  # every run keeps the environment stamp it came with
    assert set(runs.groupby("planner").cpu_model.first()) == {runs[runs.planner == "greedy"].cpu_model.iloc[0], "Other CPU 9000"}


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(column=st.sampled_from(["volume_ratio", "loaded_volume", "makespan_s", "time_per_m3", "time_per_m3_ratio",
                               "mean_bucket_fill", "travel_m"]),
       factor=st.one_of(st.floats(0.0, 0.999999), st.floats(1.000001, 1e6)))
def test_any_edit_beyond_round_off_is_caught(clean, column, factor):
    """Scaling any stored figure by more than one part in a million is a difference, in the column or in the JSON."""
    with Store(clean, read_only=True) as st_:
        row = dict(st_.query(planner=["greedy"])[0])
        sc = st_.scenario(row["scenario_digest"])
        judged = rejudge(sc, st_.plan_json(row["id"]), row["threshold"])
    assert differences(row, judged) == []
    if not row[column]:
        return
    edited = dict(row, **{column: row[column] * factor})
    assert any(d.startswith(f"column {column} ") for d in differences(edited, judged))
    metrics = json.loads(row["metrics"])
    metrics[column] = metrics[column] * factor
    assert any(d.startswith(f"metric {column} ") for d in differences(dict(row, metrics=json.dumps(metrics)), judged))
