"""Bad input: a one-line error naming the problem, a non-zero exit, no traceback, nothing lost."""

from __future__ import annotations

import copy
import errno
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd
import pytest

from earthbench.cli import main
from earthbench.errors import ScenarioError, SuiteError
from earthbench.registry import TERRAINS
from earthbench.results.store import Store, load_runs
from earthbench.results.suite import load_suite, parse_suite
from earthbench.world import Scenario

from helpers import tiny_suite_toml

FAULTY = str(Path(__file__).parent / "plugins" / "faulty_planners.py")


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.startswith("earthbench: error: ") and err.count("\n") == 1, err
    return err


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("validate")
    sc = TERRAINS.get("rbf")(0, 1.12, n_bases=3, size=[4.0, 3.0], resolution=0.1)
    sc.to_json(d / "s.json")
    (d / "other.json").write_text('{"schema": "earthbench.plan/1", "actions": []}')
    return d


@pytest.mark.parametrize("content", [
    "OTHER", "hello, plain text", b"\x00\xff\xfe binary", "", "[1, 2]", "x" * 5000, "9" * 400,
])
def test_validate_only_ever_reads_its_argument_as_a_file(files, capsys, content):
    plan = files / "plan.json"
    if content == "OTHER":  # a file whose content is the path of another (valid) plan file
        content = str(files / "other.json")
    plan.write_bytes(content if isinstance(content, bytes) else content.encode())
    status = main(["validate", str(plan), "--scenario", str(files / "s.json")])
    out = capsys.readouterr()
    assert status in (1, 2) and "Traceback" not in out.err
    assert "not found" not in out.out + out.err and "verdict: valid" not in out.out
    assert status == 2 or "malformed" in out.out


def test_validate_a_missing_file_says_so(files, capsys):
    assert main(["validate", str(files / "nope.json"), "--scenario", str(files / "s.json")]) == 2
    assert "plan file" in _one_line_error(capsys)


@pytest.mark.parametrize(("path", "value", "message"), [
    ("machines.excavator.boom_length", "long", "machines.excavator.boom_length must be a number"),
    ("machines.excavator.bucket_capacity", -1, "machines.excavator.bucket_capacity must be positive"),
    ("budget.wall_s", "fast", "budget.wall_s must be a number"),
    ("budget.wall_s", float("inf"), "budget.wall_s must be finite"),
    ("budget.cores", 2.5, "budget.cores must be an integer"),
    ("machines.truck_pose.x", None, "machines.truck_pose.x must be a number"),
    ("machines.excavator.boom_lenght", 3.0, "did you mean machines.excavator.boom_length"),
    ("task", [1], "task must be an object"),
])
def test_scenario_documents_are_checked_field_by_field(files, path, value, message):
    doc = Scenario.from_json(files / "s.json").to_dict()
    node = doc
    *parents, last = path.split(".")
    for k in parents:
        node = node[k]
    node[last] = value
    with pytest.raises(ScenarioError, match=message.replace(".", r"\.")):
        Scenario.from_dict(copy.deepcopy(doc))


def test_suite_files_are_checked_before_generating(tmp_path):
    binary = tmp_path / "bin.toml"
    binary.write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff")
    with pytest.raises(SuiteError, match="not UTF-8 text"):
        load_suite(binary)
    base = tiny_suite_toml("t")
    with pytest.raises(SuiteError, match="wall_s must be a positive finite number"):
        parse_suite(base.replace("wall_s = 20.0", "wall_s = inf"))
    with pytest.raises(SuiteError, match="n_bases must be int"):
        parse_suite(base.replace("n_bases = 3", 'n_bases = "many"'))
    with pytest.raises(SuiteError, match="size must be tuple"):
        parse_suite(base.replace("size = [4.0, 3.0]", 'size = ["4", 3.0]'))
    with pytest.raises(SuiteError, match="over the limit of 4,000,000 cells"):
        parse_suite(base.replace("size = [4.0, 3.0]", "size = [100000.0, 100000.0]"))


def test_a_relative_path_resolves_against_the_suite_folder(tmp_path, monkeypatch):
    import numpy as np

    folder = tmp_path / "suites"
    folder.mkdir()
    z = np.zeros((40, 60))
    z[10:30, 20:40] = 0.5
    np.save(folder / "map.npy", z)
    (folder / "mine.toml").write_text('''
name = "mine"
[[family]]
name = "f"
generator = "file"
targets = [0.28]
seeds = "0-0"
[family.params]
path = "map.npy"
resolution = 0.1
''')
    monkeypatch.chdir(tmp_path)  # not the suite's folder
    suite = load_suite(folder / "mine.toml")
    assert suite.families[0].params["path"] == str((folder / "map.npy").resolve())


def test_a_plugin_that_exits_on_import_gets_a_message(tmp_path, capsys):
    plugin = tmp_path / "exits.py"
    plugin.write_text("import sys\nsys.exit(3)\n")
    assert main(["list", "planners", "--plugin", str(plugin)]) == 2
    assert "called sys.exit(3) while being imported" in _one_line_error(capsys)


def test_new_planner_refuses_a_newline_and_a_file_as_dir(tmp_path, capsys):
    assert main(["new-planner", "abc\n", "--dir", str(tmp_path / "x")]) == 2
    assert "planner name" in _one_line_error(capsys) and not (tmp_path / "x").exists()
    (tmp_path / "f").write_text("keep me")
    assert main(["new-planner", "abc", "--dir", str(tmp_path / "f")]) == 2
    assert "is a file" in _one_line_error(capsys) and (tmp_path / "f").read_text() == "keep me"


@pytest.mark.usefixtures("forget_test_planners")
def test_a_full_temp_directory_stops_the_run_with_a_message(tmp_path, capsys, monkeypatch):
    (tmp_path / "tiny.toml").write_text(tiny_suite_toml("tiny"))

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(tempfile, "mkdtemp", full)
    db = tmp_path / "r.db"
    status = main(["run", str(tmp_path / "tiny.toml"), "--planner", "t-fast", "--plugin", FAULTY, "--db", str(db)])
    err = capsys.readouterr().err
    assert status == 2 and "Traceback" not in err and "No space left on device" in err and "TMPDIR" in err
    # nothing stored for a case that never ran (the planner's probe may stop it before the store is made)
    assert not db.exists() or len(load_runs(db)) == 0


def test_output_piped_into_head_ends_quietly():
    p = subprocess.Popen([sys.executable, "-m", "earthbench", "suites", "standard"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()  # the reader is gone before the first line
    err = p.stderr.read().decode()
    assert p.wait() == 141 and err == ""


def test_a_refused_leaderboard_writes_nothing(tmp_path, capsys):
    out = tmp_path / "board"
    assert main(["leaderboard", "--db", str(tmp_path / "missing.db"), "--out", str(out)]) == 2
    _one_line_error(capsys)
    with Store(tmp_path / "empty.db"):
        pass
    assert main(["leaderboard", "--db", str(tmp_path / "empty.db"), "--out", str(out), "--suite", "nope"]) == 2
    _one_line_error(capsys)
    assert not out.exists()


def test_published_csv_cells_never_run_as_formulas(tmp_path):
    from earthbench.publishing.publish import publish

    from helpers.leaderboard import Behaviour, fill_store, ref, suite_of

    hostile = "=HYPERLINK(\"http://example.invalid\",\"x\")"
    db = fill_store(tmp_path / "r.db", suite_of(1), [Behaviour(ref("greedy")), Behaviour(ref(hostile), fail="error")])
    publish(db, tmp_path / "board", figures=False)
    for name in ("runs.csv", "summary.csv"):
        table = pd.read_csv(tmp_path / "board" / name, dtype=str, keep_default_na=False)
        cells = [c for col in table.columns for c in table[col] if isinstance(c, str)]
        assert "'" + hostile in cells and hostile not in cells
        assert not [c for c in cells if c and (c[0] in "=+@" or (c[0] == "-" and not _number(c)))]


def _number(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False
