"""earthbench leaderboard / compare / merge on stores written through the real store API."""

from __future__ import annotations

import html
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import earthbench

from earthbench.cli import main
from earthbench.publishing.compare import Selector, compare
from earthbench.publishing.merge import MergeError, merge
from earthbench.publishing.board.selection import seed_list
from earthbench.publishing.board.tables import md_escape
from earthbench.publishing.publish import publish
from earthbench.results.store import load_runs
from helpers.leaderboard import EVIL, Behaviour, fill_store, ref, standard_behaviours, suite_of


@pytest.fixture(scope="module")
def db(tmp_path_factory) -> Path:
    return fill_store(tmp_path_factory.mktemp("pub") / "runs.db", suite_of(3), standard_behaviours())


@pytest.fixture(scope="module")
def board(db, tmp_path_factory):
    out = tmp_path_factory.mktemp("board")
    return publish(db, out)


def test_files_written(board):
    out = board.out
    for name in ("README.md", "runs.csv", "summary.csv", "index.html"):
        assert (out / name).is_file()
    figs = sorted(p.name for p in (out / "figures").iterdir())
    # volume-time and profiles, plus one terrain figure per planner, each as PNG and SVG
    assert len(figs) == 2 * (2 + 4)
    assert sum(f.endswith(".svg") for f in figs) == 6
    assert any("terrain-greedy" in f for f in figs)


def test_tables_ranked_with_rule_and_stamp(board, db):
    md = (board.out / "README.md").read_text()
    assert "Ranking: ranked by success rate (higher first), then median time per target m³" in md
    runs = load_runs(db)
    assert f"suite digest: {runs['suite_digest'].iloc[0]}" in md
    assert "code: earthbench " in md and "CPU: " in md and "generated " in md
    assert runs["cpu_model"].iloc[0] in md
    main_table = md.split("### Breakdowns")[0]
    rows = [line for line in main_table.splitlines() if re.match(r"\| \d+=? \|", line)]
    planners = [r.split(" | ")[1] for r in rows]
    # greedy succeeds everywhere; flaky times out on every second scenario; half loads half
    assert planners[0] == "greedy" and planners[1] == "flaky" and planners[-1] == "half"
    assert md_escape(EVIL) in planners
    assert "<script>" not in md


def test_a_board_from_two_machines_names_both_builds(db, tmp_path):
    """Runs from two machines (as a merge of their stores gives) with two builds: the stamp names each with its machine."""
    import shutil
    import sqlite3

    two = tmp_path / "two.db"
    shutil.copy(db, two)
    with sqlite3.connect(two) as con:
        env = con.execute("SELECT * FROM environments").fetchone()
        cols = [d[0] for d in con.execute("SELECT * FROM environments").description]
        other = dict(zip(cols, env))
        other.update(id=None, hash="other", hostname="second-host", project_commit="f" * 40 + "+dirty", earthbench_version="9.9")
        cur = con.execute(f"INSERT INTO environments ({', '.join(other)}) VALUES ({', '.join('?' * len(other))})", list(other.values()))
        con.execute("UPDATE runs SET environment_id=? WHERE planner='half'", (cur.lastrowid,))
    res = publish(two, tmp_path / "lb2", figures=False, generated="(fixed)")
    code = next(line for line in (res.out / "README.md").read_text().splitlines() if line.startswith("code: "))
    assert code.count("earthbench ") == 2
    assert "earthbench 9.9 (commit ffffffffffff, uncommitted changes) on second-host" in code
    assert f"earthbench {earthbench.__version__} (commit" in code


def test_csvs_match_the_store(board, db):
    runs = pd.read_csv(board.out / "runs.csv")
    assert len(runs) == len(load_runs(db)) == 24
    summary = pd.read_csv(board.out / "summary.csv")
    assert set(summary["scope"]) == {"suite", "target"}  # one family: no family breakdown
    g = summary[summary["scope"] == "suite"].set_index("planner")
    assert g.loc["greedy", "success_rate"] == 1.0 and g.loc["greedy", "runs"] == 6
    assert g.loc["flaky", "n_timeout"] == 3 and g.loc["flaky", "success_rate"] == 0.5
    assert g.loc["half", "success_rate"] == 0.0
    # medians recomputed from the CSV of runs
    ok = runs[(runs.planner == "greedy") & (runs.reason == "ok")]
    assert g.loc["greedy", "time_per_m3_median"] == pytest.approx(np.median(ok.time_per_m3))
    assert g.loc["greedy", "solve_time_p90"] == pytest.approx(np.percentile(runs[runs.planner == "greedy"].solve_time_s, 90))


def test_tables_and_page_show_the_ratio_to_each_bound(board, db):
    """Each table has a "× target bound" column beside "× lower bound" (issue 39), its text the
    configuration's median ratio to the scenario's lower bound per target m³; the page's run table
    shows each run's ratio to both bounds."""
    md = (board.out / "README.md").read_text()
    main_table = md.split("### Breakdowns")[0]
    head = next(line for line in main_table.splitlines() if line.startswith("| Rank"))
    cols = [c.strip() for c in head.strip("|").split("|")]
    assert cols.index("× target bound") == cols.index("× lower bound") + 1
    greedy = next(line for line in main_table.splitlines() if re.match(r"\| \d+=? \| greedy \|", line))
    cell = [c.strip() for c in greedy.strip("|").split("|")][cols.index("× target bound")]
    runs = load_runs(db)
    ok = runs[(runs.planner == "greedy") & (runs.reason == "ok")]
    assert (ok["time_per_target_m3_bound_ratio"] >= 1.0).all()
    assert cell.split(" ")[0] == f"{ok['time_per_target_m3_bound_ratio'].median():.2f}"
    page = html.unescape((board.out / "index.html").read_text())
    runs_table = page.split('class="sortable runs"')[1]
    assert "× lower bound</th>" in runs_table and "× target bound</th>" in runs_table
    ratio = float(ok["time_per_target_m3_bound_ratio"].iloc[0])
    assert f'data-v="{ratio!r}">{ratio:.3g}</td>' in runs_table


def test_html_is_self_contained_and_escaped(board):
    page = (board.out / "index.html").read_text()
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:|//)""", page)
    assert "<link" not in page and "@import" not in page and "url(" not in page
    assert EVIL not in page
    assert html.escape(EVIL) in page
    assert page.count("<script>") == 1  # only the page's own sorting script
    assert page.count('src="data:image/png;base64,') == 6
    assert "Content-Security-Policy" in page and "default-src 'none'" in html.unescape(page)


def test_suite_filter_and_unknown_suite(db, tmp_path):
    res = publish(db, tmp_path / "a", ["pubtest"], figures=False)
    assert len(res.runs) == 24
    assert main(["leaderboard", "--db", str(db), "--out", str(tmp_path / "b"), "--suite", "nope", "--no-figures"]) == 2


def test_board_limited_to_some_seeds(db, tmp_path, capsys):
    """A board over seed 0: its runs, and its denominators, are that seed's scenarios only."""
    res = publish(db, tmp_path / "s0", figures=False, seeds=[0])
    assert set(res.runs["seed"]) == {0} and len(res.runs) == 8  # 4 planners × 2 targets
    whole = res.summary[(res.summary["scope"] == "suite") if "scope" in res.summary else slice(None)]
    assert set(whole["of"]) == {2}  # a planner run on seed 0 alone is not charged the other seeds
    md = (res.out / "README.md").read_text()
    assert "scenarios: seed 0 of the suite only" in md
    assert "scenarios: seed" not in (publish(db, tmp_path / "all", figures=False).out / "README.md").read_text()
    assert main(["leaderboard", "--db", str(db), "--out", str(tmp_path / "cli"), "--no-figures", "--seeds", "1-2"]) == 0
    assert "16 run(s)" in capsys.readouterr().err
    assert "scenarios: seeds 1–2 of the suite only" in (tmp_path / "cli" / "README.md").read_text()


def test_seed_list():
    assert seed_list([5, 0, 2, 1]) == "0–2, 5" and seed_list([3]) == "3" and seed_list([0, 2]) == "0, 2"


def test_cli_leaderboard(db, tmp_path, capsys):
    assert main(["leaderboard", "--db", str(db), "--out", str(tmp_path / "lb"), "--no-terrain", "--jobs", "1"]) == 0
    assert "24 run(s), 1 table(s)" in capsys.readouterr().err
    assert len(list((tmp_path / "lb" / "figures").iterdir())) == 4


def test_mixed_cpu_models_are_said_to_be_mixed(tmp_path):
    db = fill_store(tmp_path / "m.db", suite_of(2), [Behaviour(ref("greedy")), Behaviour(ref("other"), keep=0.9, cpu_model="Other CPU 9")])
    res = publish(db, tmp_path / "lb", terrain=False)
    md = (res.out / "README.md").read_text()
    assert "Other CPU 9, " in md and "solve times mixed from several CPU models" in md


# -- compare -----------------------------------------------------------------------------------------


def test_wilcoxon_by_hand():
    a = pd.DataFrame({"scenario_digest": list("abcdef"), "planner": "a", "planner_version": "1", "config_hash": "x",
                      "success": True, "solve_time_s": [1.0] * 6, "volume_ratio": [1.0] * 6})
    b = a.assign(planner="b", solve_time_s=[2.0, 3.0, 4.0, 5.0, 6.0, 7.0])
    c = compare(a, b, ("solve_time_s", "volume_ratio"))
    st = c.table.set_index("metric")
    # six positive differences: the exact two-sided p is 2 / 2**6
    assert st.loc["solve_time_s", "p_value"] == pytest.approx(2 / 64)
    assert st.loc["solve_time_s", "median_diff"] == 3.5
    assert st.loc["solve_time_s", "median_diff_lo"] < 3.5 < st.loc["solve_time_s", "median_diff_hi"]  # the effect's 95 % CI
    assert st.loc["solve_time_s", "p_holm"] == pytest.approx(2 * 2 / 64)  # Holm over two metrics
    assert st.loc["solve_time_s", "verdict"] == "no significant difference"
    assert compare(a, b, ("solve_time_s",)).table.set_index("metric").loc["solve_time_s", "verdict"] == "B worse"
    assert st.loc["volume_ratio", "p_value"] == 1.0  # every difference zero
    assert st.loc["volume_ratio", "verdict"] == "no significant difference"
    assert c.success["both"] == 6 and c.success["p_value"] == 1.0


def test_selector():
    s = Selector.parse("greedy@1.0#07cd")
    assert (s.planner, s.version, s.config) == ("greedy", "1.0", "07cd")
    assert Selector.parse("greedy") == Selector("greedy")
    assert Selector.parse("a@b@2").planner == "a@b"


def test_cli_compare_in_one_store(db, capsys, tmp_path):
    assert main(["compare", str(db), "--a", "greedy", "--b", "half", "--csv", str(tmp_path / "c.csv")]) == 0
    out = capsys.readouterr().out
    assert "6 shared scenario(s)" in out
    t = pd.read_csv(tmp_path / "c.csv").set_index("metric")
    assert t.loc["volume_ratio", "median_diff"] < 0
    assert t.loc["volume_ratio", "p_value"] == pytest.approx(2 / 64)
    # six pairs give p = 1/32, but Holm across the table's metrics lifts it above 0.05, and the report says why
    assert t.loc["volume_ratio", "p_holm"] > 0.05 and t.loc["volume_ratio", "verdict"] == "no significant difference"
    assert "no difference can be significant here" in out


def test_cli_compare_two_stores(tmp_path, capsys):
    suite = suite_of(2)
    before = fill_store(tmp_path / "before.db", suite, [Behaviour(ref("mine", "1"), keep=0.5)])
    after = fill_store(tmp_path / "after.db", suite, [Behaviour(ref("mine", "2"))])
    assert main(["compare", str(before), str(after), "--metric", "volume_ratio", "--metric", "digs"]) == 0
    out = capsys.readouterr().out
    assert "A: mine 1" in out and "B: mine 2" in out and "4 shared scenario(s)" in out
    line = next(x for x in out.splitlines() if x.startswith("volume_ratio"))
    assert "0.125" in line and "no significant difference" in line  # 4 pairs, all B > A: exact p = 2 / 2**4
    assert "success: A 0%, B 100%" in out and "McNemar p = 0.125" in out
    assert main(["compare", str(before), str(after), "--metric", "volume_ratio", "--alpha", "0.2"]) == 0
    assert "B better" in next(x for x in capsys.readouterr().out.splitlines() if x.startswith("volume_ratio"))


def test_cli_compare_for_ci(db, capsys):
    args = ["compare", str(db), "--metric", "volume_ratio", "--format", "markdown"]
    # half loads half of greedy's volume on all 6 scenarios: p = 2 / 2**6 on one metric; success 6 vs 0 (McNemar)
    assert main([*args, "--a", "greedy", "--b", "half", "--fail-on-regression", "volume_ratio"]) == 1
    cap = capsys.readouterr()
    assert "| metric | pairs |" in cap.out and "| volume\\_ratio | 6 |" in cap.out and "B worse" in cap.out
    assert "regression: B is significantly worse on volume_ratio" in cap.err
    assert main([*args, "--a", "greedy", "--b", "half", "--fail-on-regression", "success"]) == 1
    assert main([*args, "--a", "half", "--b", "greedy", "--fail-on-regression", "volume_ratio,success"]) == 0  # B better
    assert main([*args, "--a", "greedy", "--b", "half"]) == 0  # no guard: a report only
    capsys.readouterr()
    assert main([*args, "--a", "greedy", "--b", "half", "--fail-on-regression", "volume_ration"]) == 2
    assert "Did you mean 'volume_ratio'" in capsys.readouterr().err


def test_cli_compare_errors(db, capsys):
    assert main(["compare", str(db), "--a", "greedy"]) == 2
    assert main(["compare", str(db), "--a", "nobody", "--b", "half"]) == 2
    assert "planner 'nobody' has no runs in" in capsys.readouterr().err  # with the planners there
    assert main(["compare", str(db), "--a", "greedy@9", "--b", "half"]) == 2
    assert "stored configurations" in capsys.readouterr().err  # a known planner, no such version


# -- merge -------------------------------------------------------------------------------------------


def _table(db) -> pd.DataFrame:
    cols = ["scenario_digest", "planner", "planner_version", "config_hash", "reason", "success", "volume_ratio",
            "time_per_m3", "solve_time_s", "cpu_model", "project_commit", "config"]
    return load_runs(db)[cols].sort_values(["scenario_digest", "planner"]).reset_index(drop=True)


def test_merge_two_machines(tmp_path):
    suite = suite_of(2)
    a = fill_store(tmp_path / "a.db", suite, [Behaviour(ref("greedy"))])
    b = fill_store(tmp_path / "b.db", suite, [Behaviour(ref("half"), keep=0.5, cpu_model="Other CPU")])
    assert main(["merge", str(tmp_path / "out.db"), str(a), str(b)]) == 0
    merged = _table(tmp_path / "out.db")
    both = pd.concat([_table(a), _table(b)]).sort_values(["scenario_digest", "planner"]).reset_index(drop=True)
    pd.testing.assert_frame_equal(merged, both)
    # plans survive, byte for byte
    from earthbench.results.store import Store

    with Store(tmp_path / "out.db", create=False) as out, Store(a, create=False) as src:
        got = {(r["scenario_digest"], r["planner"]): out.plan_json(r["id"]) for r in out.query()}
        for r in src.query():
            assert got[(r["scenario_digest"], r["planner"])] == src.plan_json(r["id"])


def test_merge_refuses_duplicates_and_writes_nothing(tmp_path, capsys):
    suite = suite_of(2)
    a = fill_store(tmp_path / "a.db", suite, [Behaviour(ref("greedy"))])
    b = fill_store(tmp_path / "b.db", suite, [Behaviour(ref("greedy")), Behaviour(ref("half"), keep=0.5)])
    assert main(["merge", str(tmp_path / "out.db"), str(a), str(b)]) == 2
    assert "duplicate run" in capsys.readouterr().err
    assert not (tmp_path / "out.db").exists()  # a refused merge creates no (empty) database
    merge(tmp_path / "out2.db", [a])
    with pytest.raises(MergeError, match="duplicate"):
        merge(tmp_path / "out2.db", [a])  # merging the same store twice


def test_merge_refuses_mismatched_suite_digests(tmp_path):
    a = fill_store(tmp_path / "a.db", suite_of(2), [Behaviour(ref("greedy"))])
    b = fill_store(tmp_path / "b.db", suite_of(3), [Behaviour(ref("half"), keep=0.5)])  # same name, other scenarios
    with pytest.raises(MergeError, match="different digests"):
        merge(tmp_path / "out.db", [a, b])
    with pytest.raises(MergeError, match="also an input"):
        merge(a, [a])
