"""The CLI guides: the broken rule inline with the command to see more, exit status, plurals,
violations first, a stored run's scenario exported, planner settings and generator parameters
checked with close matches."""

from __future__ import annotations

import json
import shlex
from pathlib import Path

import pytest

from earthbench.cli import main
from earthbench.results.store import load_runs
from earthbench.world import Scenario

from helpers import load_script, tiny_suite_toml

PLUGIN = str(Path(__file__).parent / "plugins" / "faulty_planners.py")

pytestmark = pytest.mark.usefixtures("forget_test_planners")


def hints(text: str) -> list[list[str]]:
    """Every earthbench command ``text`` tells the user to run, as argv lists, read as
    ``scripts/newcomer_route.py`` reads them (placeholders such as ``N`` excluded)."""
    return [shlex.split(h)[1:] for h in load_script("newcomer_route").hints(text) if h.startswith("earthbench ")]


def run_hints(text: str, capsys) -> dict[str, str]:
    """Run every hint of ``text`` as printed; each must exit 0 and say something. Returns command line → its output."""
    seen = {}
    for argv in hints(text):
        line = " ".join(argv)
        if line in seen:
            continue
        assert main(argv) == 0, f"hint failed: earthbench {line}"
        cap = capsys.readouterr()
        seen[line] = cap.out + cap.err
        assert seen[line].strip(), line
    return seen


@pytest.fixture
def suite(tmp_path):
    f = tmp_path / "g.toml"
    f.write_text(tiny_suite_toml("g"))
    return str(f)


def test_invalid_case_names_its_rule_and_the_run_to_see(tmp_path, suite, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)  # hints that write files (a board, P.json) write here
    db = str(tmp_path / "g.db")
    assert main(["run", suite, "--planner", "t-invalid", "--plugin", PLUGIN, "--db", db]) == 1  # no valid plan
    err = capsys.readouterr().err
    run_id = int(load_runs(db)["id"].iloc[0])
    assert "1 case (1 scenario × t-invalid), 1 slot of" in err
    assert "invalid" in err and "cut_depth at action 0" in err and f"see: earthbench runs --db {db} --id {run_id}" in err
    assert "no case has a valid plan (exit status 1)" in err
    assert f"next: earthbench runs --db {db} --suite g --planner t-invalid --reason invalid  (the 1 failed run: 1 invalid" in err
    # every command it printed runs as printed, and the failure filter shows the failure
    done = run_hints(err, capsys)
    assert f"runs --db {db} --id {run_id}" in done and "leaderboard --db " + db + " --suite g" in done
    assert "invalid" in done[f"runs --db {db} --suite g --planner t-invalid --reason invalid"].splitlines()[2]  # a row
    assert (tmp_path / "board" / "README.md").exists()  # the leaderboard hint's default folder
    more = done[f"runs --db {db} --id {run_id}"]
    assert [a[0] for a in hints(more)] == ["runs", "show"]  # "to see it": export the pair, then draw it
    run_hints(more, capsys)
    assert (tmp_path / "earthbench-show.png").stat().st_size > 0

    scen, plan = tmp_path / "s.json", tmp_path / "p.json"
    assert main(["runs", "--db", db, "--id", str(run_id), "--scenario-out", str(scen), "--plan-out", str(plan)]) == 0
    out = capsys.readouterr().out
    assert out.index("violation: action 0: cut_depth") < out.index("metrics:")
    assert Scenario.from_json(scen).digest == load_runs(db)["scenario_digest"].iloc[0]
    assert main(["validate", str(plan), "--scenario", str(scen)]) == 1  # the exported pair reproduces the verdict
    assert "cut_depth" in capsys.readouterr().out


def test_next_names_the_failures_that_happened_and_keeps_the_selection(tmp_path, capsys, monkeypatch):
    """A run whose failures are errors and short plans is pointed at those, never at an empty `--reason invalid`;
    the leaderboard hint keeps `--seeds`, and every hint runs as printed."""
    monkeypatch.chdir(tmp_path)
    f = tmp_path / "two.toml"
    f.write_text(tiny_suite_toml("two", seeds="0-1"))
    db = str(tmp_path / "two.db")
    for planner in ("t-raise", "t-fast"):
        main(["run", str(f), "--planner", planner, "--plugin", PLUGIN, "--db", db, "--seeds", "0"])
    err = capsys.readouterr().err
    assert "--reason invalid" not in err
    assert f"earthbench runs --db {db} --suite two --seeds 0 --planner t-raise --reason error  (the 1 failed run: 1 error" in err
    assert f"earthbench runs --db {db} --suite two --seeds 0 --planner t-fast --short  (the 1 valid run short of the target" in err
    assert f"earthbench leaderboard --db {db} --suite two --seeds 0  (" in err
    done = run_hints(err, capsys)
    assert "t-raise" in done[f"runs --db {db} --suite two --seeds 0 --planner t-raise --reason error"]
    assert "(1 run(s)" in done[f"runs --db {db} --suite two --seeds 0 --planner t-fast --short"]
    # a run on the other seed is not the selection's: --seeds keeps the listing to the run's scenarios
    assert main(["run", str(f), "--planner", "t-fast", "--plugin", PLUGIN, "--db", db, "--seeds", "1", "--quiet"]) == 0
    capsys.readouterr()
    assert main(["runs", "--db", db, "--suite", "two", "--seeds", "0", "--short"]) == 0
    assert "(1 run(s)" in capsys.readouterr().err
    assert main(["runs", "--db", db, "--suite", "two", "--short"]) == 0
    assert "(2 run(s)" in capsys.readouterr().err
    assert main(["runs", "--db", db, "--seeds", "0"]) == 2
    assert "--seeds needs --suite" in capsys.readouterr().err
    assert "leaderboard: 2 run(s)" in done[f"leaderboard --db {db} --suite two --seeds 0"]
    assert "scenarios: seed 0 of the suite only" in (tmp_path / "board" / "README.md").read_text()  # not 2 of 4 at 50 %


def test_runs_refuses_names_it_has_no_run_of(tmp_path, suite, capsys):
    db = str(tmp_path / "n.db")
    assert main(["run", suite, "--planner", "greedy", "--db", db, "--quiet"]) == 0
    capsys.readouterr()
    for argv, said in ((["runs", "--planner", "gredy"], "planner 'gredy' has no runs in"),
                       (["runs", "--suite", "gg"], "suite 'gg' has no runs in"),
                       (["rescore", "--planner", "gredy"], "did you mean 'greedy'?"),
                       (["verify", db, "--planner", "near-truk"], "Planners there: greedy"),
                       (["compare", db, "--a", "gredy@1.2", "--b", "greedy"], "did you mean 'greedy'?"),
                       (["compare", db, "--suite", "gg", "--a", "greedy", "--b", "greedy"], "suite 'gg' has no runs in"),
                       (["leaderboard", "--suite", "gg", "--out", str(tmp_path / "b")], "suite 'gg' has no runs in")):
        own_db = argv[0] in ("verify", "compare")
        assert main([*argv[:1], *([] if own_db else ["--db", db]), *argv[1:]]) == 2, argv
        assert said in capsys.readouterr().err
    assert main(["runs", "--db", db, "--short"]) == 0
    assert "(0 run(s)" in capsys.readouterr().err  # greedy reaches the target: no short run


def test_exit_status_and_legend(tmp_path, suite, capsys):
    db = str(tmp_path / "ok.db")
    assert main(["run", suite, "--planner", "greedy", "--db", db]) == 0
    cap = capsys.readouterr()
    assert "solve CPU s: median CPU time" in cap.out and "(s)" not in cap.err
    # t-fast's plans are valid but load nothing: exit 0, unless success is required
    assert main(["run", suite, "--planner", "t-fast", "--plugin", PLUGIN, "--db", db, "--quiet"]) == 0
    assert main(["run", suite, "--planner", "t-fast", "--plugin", PLUGIN, "--db", db, "--quiet", "--require-success"]) == 1
    assert "no case succeeded" in capsys.readouterr().err
    assert main(["run", suite, "--planner", "greedy", "--db", db, "--quiet", "--require-success"]) == 0


def test_config_is_checked_against_the_planners_config(tmp_path, suite, capsys):
    db = str(tmp_path / "c.db")
    assert main(["run", suite, "--planner", "greedy", "--config", "min_fil=0.5", "--db", db]) == 2
    assert "Did you mean 'min_fill'?" in capsys.readouterr().err
    assert main(["run", suite, "--planner", "greedy", "--config", "max_actions=many", "--db", db]) == 2
    assert "max_actions=many: expected an integer" in capsys.readouterr().err
    assert main(["run", suite, "--config", "min_fill=0.5", "--db", db]) == 2
    assert "--config needs --planner" in capsys.readouterr().err
    assert main(["run", suite, "--planner", "greedy", "--config", "min_fill=0.5", "--config", "max_actions=50", "--db", db,
                 "--quiet"]) == 0
    cfg = load_runs(db)["config"].iloc[0]
    cfg = json.loads(cfg) if isinstance(cfg, str) else cfg
    assert cfg["min_fill"] == 0.5 and cfg["max_actions"] == 50 and isinstance(cfg["max_actions"], int)


def test_plan_takes_config_and_checks_params(tmp_path, capsys):
    out = tmp_path / "p.json"
    assert main(["plan", "greedy", "--config", "min_fill=0.3", "--param", "n_bases=14", "-o", str(out)]) == 0
    assert main(["plan", "greedy", "--param", "n_base=14", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "unknown rbf parameter 'n_base'. Did you mean 'n_bases'?" in err and "Traceback" not in err
    assert main(["plan", "greedy", "--param", "n_bases", "-o", str(out)]) == 2
    assert "expected KEY=VALUE" in capsys.readouterr().err
    assert main(["plan", "greedy", "--config", "min_fill=lots", "-o", str(out)]) == 2
    assert "expected a number" in capsys.readouterr().err


def test_validate_prints_no_missing_values(tmp_path, capsys):
    plan, scen = tmp_path / "p.json", tmp_path / "s.json"
    assert main(["plan", "greedy", "-o", str(plan), "--save-scenario", str(scen)]) == 0
    capsys.readouterr()
    assert main(["validate", str(plan), "--scenario", str(scen)]) == 0
    out = capsys.readouterr().out
    assert "None" not in out and "solve_time_s" not in out and "volume_ratio" in out


def test_settings_are_listed_and_typed(capsys):
    from earthbench.cli._common import parse_config
    from earthbench.registry import PLANNERS

    assert main(["list", "--settings"]) == 0
    out = capsys.readouterr().out
    assert "settings: min_fill=0.6" in out and "params: n_bases=14" in out
    cls = PLANNERS.get("singh-cannon-backhoe")
    assert parse_config(["relax_fills=[0.5, 0.2]", "max_digs=7", "fill_min=1"], cls) == {
        "relax_fills": (0.5, 0.2), "max_digs": 7, "fill_min": 1.0}
    assert parse_config(["retime_moves=false", "mu_strategy=monotone"], PLANNERS.get("stl-tamp")) == {
        "retime_moves": False, "mu_strategy": "monotone"}


def test_help_says_where_to_start_and_each_first_step_runs(tmp_path, capsys, monkeypatch):
    from earthbench.cli import START_HERE, build_parser

    assert build_parser().format_help().rstrip().endswith(START_HERE)
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("EARTHBENCH_DB", raising=False)
    done = run_hints(START_HERE, capsys)
    assert sorted(done) == ["new-planner my-planner", "run smoke --planner greedy"]
    assert (tmp_path / "earthbench.db").exists() and (tmp_path / "earthbench-my-planner").is_dir()


def test_suites_line_up_and_runs_validate_have_help(capsys):
    assert main(["suites"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len({line.index(" scenarios ") for line in lines}) == 1, "a long suite name pushed its row out of line"
    import argparse

    from earthbench.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert "--short" in sub.choices["runs"].description
    for command, p in sub.choices.items():
        bare = [a.dest for a in p._actions if not a.help and not isinstance(a, argparse._HelpAction)]
        assert not bare, f"earthbench {command}: arguments without help: {bare}"


def test_a_ranking_on_partial_data_says_so(tmp_path, capsys, monkeypatch):
    """Runs on one of two scenarios: the run's table, the board's README and page and the command's note
    call the ranking partial; once complete, none does."""
    monkeypatch.chdir(tmp_path)
    f = tmp_path / "two.toml"
    f.write_text(tiny_suite_toml("two", seeds="0-1"))
    db = str(tmp_path / "p.db")
    assert main(["run", str(f), "--planner", "greedy", "--db", db, "--seeds", "0", "--quiet"]) == 0
    capsys.readouterr()
    from earthbench.cli.run import print_summary
    from earthbench.results.store import Store

    from earthbench_planners.greedy.backhoe import GreedyPlanner

    v = GreedyPlanner.version
    with Store(db) as store:
        print_summary(store, "two")
    assert f"partial: not every scenario has a run (greedy {v} 1 of 2)" in capsys.readouterr().out
    assert main(["leaderboard", "--db", db, "--no-figures"]) == 0
    assert "partial data on two" in capsys.readouterr().err
    note = f"partial: not every scenario has a run (greedy {v}: 1 of 2)"
    assert note in (tmp_path / "board" / "README.md").read_text() and note in (tmp_path / "board" / "index.html").read_text()
    assert main(["run", str(f), "--planner", "greedy", "--db", db, "--quiet"]) == 0
    assert "partial" not in capsys.readouterr().out
    assert main(["leaderboard", "--db", db, "--no-figures"]) == 0
    assert "partial" not in capsys.readouterr().err and "partial:" not in (tmp_path / "board" / "README.md").read_text()


def test_seal_and_export_hints_run_as_printed(tmp_path, capsys, monkeypatch):
    """`seal`'s next step runs the sealed draw; `export`'s merge command merges the bundle; each as printed."""
    monkeypatch.chdir(tmp_path)
    key = tmp_path / "my key.json"  # a space: the printed command must quote it
    assert main(["seal", "smoke", "--key", str(key)]) == 0
    out = capsys.readouterr().out
    assert f"next: earthbench run smoke --sealed '{key}'" in out
    done = run_hints(out, capsys)
    (command,) = done
    assert "smoke~sealed-" in done[command] and "4 cases" in done[command]
    sealed = out.split("sealed suite: ")[1].split()[0]
    assert main(["export", "--suite", sealed, "--planner", "greedy", "mine.db"]) == 0
    done = run_hints(capsys.readouterr().out, capsys)
    assert list(done) == ["merge ALL.db mine.db"] and (tmp_path / "ALL.db").exists()
