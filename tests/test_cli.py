"""The command line, driven in-process through ``earthbench.cli.main``."""

from __future__ import annotations

import json

import pytest

from earthbench.cli import main


def test_list(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "greedy" in out and "rbf" in out and "core" in out


def test_plan_then_validate(tmp_path, capsys):
    plan, scen = tmp_path / "p.json", tmp_path / "s.json"
    assert main(["plan", "greedy", "--seed", "2", "--target", "1.4", "-o", str(plan), "--save-scenario", str(scen)]) == 0
    assert main(["validate", str(plan), "--scenario", str(scen)]) == 0
    out = capsys.readouterr().out
    assert "verdict: valid" in out and "volume_ratio" in out
    assert main(["validate", str(plan), "--scenario", str(scen), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["valid"] and doc["metrics"]["success"]


def test_validate_an_invalid_plan_exits_non_zero(tmp_path, capsys):
    plan, scen = tmp_path / "p.json", tmp_path / "s.json"
    main(["plan", "greedy", "-o", str(plan), "--save-scenario", str(scen)])
    doc = json.loads(plan.read_text())
    dig = next(a for a in doc["actions"] if a["type"] == "dig")
    dig["depth"] = 0.5
    plan.write_text(json.dumps(doc))
    assert main(["validate", str(plan), "--scenario", str(scen)]) == 1
    assert "cut_depth" in capsys.readouterr().out
    plan.write_text('{"schema": "earthbench.plan/1", "actions": [{"type": "fly"}]}')
    assert main(["validate", str(plan), "--scenario", str(scen)]) == 1
    assert "malformed" in capsys.readouterr().out


def test_unknown_planner_is_a_clear_error(capsys):
    assert main(["plan", "gredy"]) == 2
    assert "Did you mean 'greedy'" in capsys.readouterr().err


def test_missing_files_are_clear_errors(tmp_path, capsys):
    assert main(["validate", str(tmp_path / "none.json"), "--scenario", str(tmp_path / "none.json")]) == 2
    assert "not found" in capsys.readouterr().err


def test_show_writes_a_png(tmp_path):
    plan, scen, png = tmp_path / "p.json", tmp_path / "s.json", tmp_path / "x.png"
    main(["plan", "greedy", "-o", str(plan), "--save-scenario", str(scen)])
    assert main(["show", "--scenario", str(scen), "--plan", str(plan), "-o", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_every_command_has_help(capsys):
    from earthbench.cli import COMMANDS, build_parser

    parser = build_parser()
    for name in [c.rstrip("_").replace("_", "-") for c in COMMANDS]:
        with pytest.raises(SystemExit):
            parser.parse_args([name, "--help"])
        assert "usage:" in capsys.readouterr().out
