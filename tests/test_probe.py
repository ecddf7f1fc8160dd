"""No plugin code outside the fences (issue 47; docs/DESIGN.md §6 "Plugin code").

A hostile plugin file and a hostile installed distribution whose top-level code has side
effects (a marker file written with the importing process's pid, the scoring function replaced)
go through every command that can name a planner; the side effects must never happen in the
earthbench process, and the stored figures stay the referee's. The probe's answers are cached
by the code's digest, a second plugin of one name and version is refused by a store that holds
the first, and the preparation key follows the code.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

import earthbench.results.scoring
from earthbench.cli import main
from earthbench.errors import PluginError
from earthbench.running.harness import probe
from earthbench.running.harness.prepare import prepare_key
from earthbench.results.records import PlannerRef
from earthbench.registry import plugin_module_name

HOSTILE = '''
import os
try:
    with open({marker!r}, "a") as f:
        f.write(str(os.getpid()) + "\\n")
except OSError:
    pass
import earthbench.results.scoring


def _forged(*args, **kwargs):
    raise RuntimeError("forged scoring")


earthbench.results.scoring.score = _forged
from dataclasses import dataclass
from earthbench import Plan, Planner


class Hostile(Planner):
    """Plans nothing; its import has side effects."""

    name = {name!r}
    version = "1.0"

    @dataclass(frozen=True)
    class Config:
        speed: float = 1.0
        tags: tuple[str, ...] = ()

    def prepare(self, folder, jobs=1):
        (folder / "made").write_text("x")
        return {{"made": 1}}

    def plan(self, scenario):
        return Plan(())
{extra}
'''


@pytest.fixture
def caches(tmp_path, monkeypatch):
    """The probe cache and preparations of this test alone."""
    monkeypatch.setenv(probe.ENV, str(tmp_path / "probes"))
    monkeypatch.setenv("EARTHBENCH_PREPARED", str(tmp_path / "prepared"))
    yield tmp_path
    probe.use_plugin_files([])


def hostile_file(folder: Path, name: str = "hostile", extra: str = "") -> tuple[Path, Path]:
    marker = folder / f"{name}.marker"
    plugin = folder / f"{name}.py"
    plugin.write_text(HOSTILE.format(marker=str(marker), name=name, extra=extra))
    return plugin, marker


def imported_here(marker: Path, pid: int) -> bool:
    """Whether the plugin's top level ran in the process ``pid`` (a fenced probe or case writes
    its own pid, where its fences let it write at all)."""
    return marker.exists() and str(pid) in marker.read_text().split()


def runs(db: Path) -> list[tuple]:
    with sqlite3.connect(db) as con:
        return con.execute("SELECT planner, reason, success, error, code_digest FROM runs").fetchall()


@pytest.mark.slow
def test_a_hostile_plugin_file_never_runs_in_the_earthbench_process(caches, capsys):
    tmp = caches
    plugin, marker = hostile_file(tmp)
    original = earthbench.results.scoring.score
    db, p = tmp / "r.db", ["--plugin", str(plugin)]
    sc, plan = tmp / "sc.json", tmp / "plan.json"
    commands = [
        ["list", *p], ["list", "planners", "--settings", *p],
        ["plan", "hostile", *p, "--terrain", "rbf", "-o", str(plan), "--save-scenario", str(sc)],
        ["validate", str(plan), "--scenario", str(sc)],
        ["show", "--scenario", str(sc), "--plan", str(plan), "-o", str(tmp / "shown.png")],
        ["run", "smoke", "--planner", "hostile", *p, "--db", str(db), "--seeds", "0-1", "--config", "speed=2"],
        ["prepare", "hostile", *p],
        ["verify", str(db)], ["verify", str(db), "--sample", "1", "--no-record", *p],
        ["run", "smoke", "--planner", "hostile", *p, "--db", str(db), "--seeds", "0-1", "--quiet"],
        ["runs", "--db", str(db)],
        ["compare", str(db), "--a", "hostile#{speed1}", "--b", "hostile#{speed2}"],
        ["export", "--db", str(db), "--suite", "smoke", "--planner", "hostile", str(tmp / "sub.db")],
        ["merge", str(tmp / "merged.db"), str(tmp / "sub.db")],
        ["leaderboard", "--db", str(db), "--suite", "smoke", "--out", str(tmp / "board"), "--no-figures", "--replays", "0"],
    ]
    for argv in commands:
        if argv[0] == "compare":
            hashes = {json.loads(c)["speed"]: h for h, c in sqlite3.connect(db).execute(
                "SELECT config_hash, config FROM planner_configs")}
            argv = [a.format(speed1=hashes[1.0][:8], speed2=hashes[2.0][:8]) for a in argv]
        code = main(argv)
        out = capsys.readouterr()
        assert code in (0, 1), (argv, out.err)
        assert not imported_here(marker, os.getpid()), argv
    assert earthbench.results.scoring.score is original
    assert plugin_module_name(plugin) not in sys.modules  # (other tests load other hostile files in-process)
    stored = runs(db)
    assert len(stored) >= 4 and all(r[:3] == ("hostile", "ok", 0) for r in stored)  # the referee's figures
    assert all(r[4] == "sha256:" + hashlib.sha256(plugin.read_bytes()).hexdigest() for r in stored)


def test_the_probe_is_cached_by_the_codes_digest(caches, monkeypatch):
    plugin, _ = hostile_file(caches)
    probes: list[str] = []
    real = probe._probe  # counting the fenced jobs

    def counted(source, asked):
        probes.append(source.digest)
        return real(source, asked)

    monkeypatch.setattr(probe, "_probe", counted)
    probe.use_plugin_files([plugin])
    first = probe.resolve("hostile")
    assert probe.resolve("hostile") == first and len(probes) == 1  # cached
    assert probe.resolve("hostile", {"speed": 2}).config == {"speed": 2.0, "tags": []} and len(probes) == 2
    assert probe.resolve("hostile", {"speed": 2}).config_hash != first.config_hash and len(probes) == 2
    plugin.write_text(plugin.read_text() + "\n# changed\n")  # new code: a new probe, a new digest
    changed = probe.resolve("hostile")
    assert len(probes) == 3 and changed.code_digest != first.code_digest
    assert (changed.name, changed.version, changed.config_hash) == (first.name, first.version, first.config_hash)
    assert prepare_key(changed) != prepare_key(first)  # a preparation never serves other code


def test_the_built_in_planners_keep_their_preparation_key():
    """Their code digest is the distribution's (earthbench's version is in the machine stamp)."""
    ref = PlannerRef.resolve("greedy")
    assert ref.code_digest == "earthbench"
    assert prepare_key(ref) == prepare_key(dataclasses.replace(ref, code_digest=""))


def test_a_second_plugin_of_one_name_and_version_is_refused_by_the_store(caches, capsys):
    first, _ = hostile_file(caches)
    other = caches / "other"
    other.mkdir()
    squatter, _ = hostile_file(other, extra="# other code\n")
    db = caches / "r.db"
    assert main(["run", "smoke", "--planner", "hostile", "--plugin", str(first), "--db", str(db), "--seeds", "0"]) == 0
    before = runs(db)
    capsys.readouterr()
    assert main(["run", "smoke", "--planner", "hostile", "--plugin", str(squatter), "--db", str(db), "--seeds", "0-1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "other code" in err and "another version" in err
    assert runs(db) == before
    assert main(["run", "smoke", "--planner", "hostile", "--plugin", str(first), "--plugin", str(squatter),
                 "--db", str(db)]) == 2
    assert "already registered" in capsys.readouterr().err


@pytest.mark.parametrize("field, value, why", [
    ("name", "'evil\\x1b[2J'", "planner name"),
    ("version", "'1' * 200", "version"),
    ("tracks", "('moon',)", "tracks"),
])
def test_the_probes_answer_is_read_as_hostile_data(caches, capsys, field, value, why):
    plugin = caches / "odd.py"
    plugin.write_text(HOSTILE.format(marker="/nonexistent/m", name="odd", extra="")
                      .replace('    version = "1.0"\n', f'    version = "1.0"\n    {field} = {value}\n'))
    assert main(["list", "planners", "--plugin", str(plugin)]) == 2
    err = capsys.readouterr().err
    assert "refused" in err and why in err and "\x1b" not in err


# -- an installed distribution ---------------------------------------------------------------------

PACKAGE = HOSTILE + '''

def metric(scenario, plan, verdict):
    return {{"success": True}}
'''


def install(site: Path, marker: Path) -> None:
    """A distribution ``hostile-dist`` as pip would leave it: its package and its dist-info."""
    pkg = site / "hostile_dist"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text(PACKAGE.format(marker=str(marker), name="hostile-pkg", extra=""))
    info = site / "hostile_dist-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: hostile-dist\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(
        "[earthbench.planners]\nhostile-pkg = hostile_dist:Hostile\n\n[earthbench.metrics]\nhostile-metric = hostile_dist:metric\n")
    (info / "RECORD").write_text("hostile_dist/__init__.py,,\nhostile_dist-1.0.dist-info/METADATA,,\n")


@pytest.mark.slow
def test_a_hostile_installed_package_never_runs_in_the_earthbench_process(caches):
    site = caches / "site-packages"
    marker = caches / "pkg.marker"
    install(site, marker)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]),
           probe.ENV: str(caches / "probes"), "EARTHBENCH_PREPARED": str(caches / "prepared")}
    db = caches / "r.db"

    def earthbench_(*argv: str) -> subprocess.CompletedProcess:
        proc = subprocess.Popen([sys.executable, "-m", "earthbench", *argv], env=env, cwd=caches,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        out, err = proc.communicate(timeout=300)
        assert proc.returncode in (0, 1), (argv, err)
        assert not imported_here(marker, proc.pid), argv
        return subprocess.CompletedProcess(argv, proc.returncode, out, err)

    listed = earthbench_("list").stdout
    assert "hostile-pkg" in listed and "hostile-metric" in listed and "NOT LOADED" in listed
    earthbench_("plan", "hostile-pkg", "--terrain", "rbf", "-o", str(caches / "p.json"))
    earthbench_("run", "smoke", "--planner", "hostile-pkg", "--db", str(db), "--seeds", "0")
    earthbench_("prepare", "hostile-pkg")
    earthbench_("verify", str(db), "--sample", "1", "--no-record")
    earthbench_("leaderboard", "--db", str(db), "--suite", "smoke", "--out", str(caches / "b"), "--no-figures", "--replays", "0")
    stored = runs(db)
    assert stored and all(r[:3] == ("hostile-pkg", "ok", 0) and r[4].startswith("sha256:") for r in stored)
    with sqlite3.connect(db) as con:
        metrics = [json.loads(m) for (m,) in con.execute("SELECT metrics FROM runs")]
    assert all(m["success"] is False for m in metrics)  # the package's metric never joined the scoring


def test_a_probe_that_dies_is_a_clear_error_and_imports_nothing_here(caches, capsys):
    plugin = caches / "dies.py"
    plugin.write_text("import os\nos._exit(5)\n")
    assert main(["list", "planners", "--plugin", str(plugin)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "could not be loaded (in a fenced probe)" in err and "status 5" in err


def test_a_given_plugin_file_that_fails_stops_a_suite_of_every_planner(caches):
    from earthbench.running.harness import build_cases
    from earthbench.results.suite import load_suite

    plugin = caches / "broken.py"
    plugin.write_text("raise ImportError('no such thing')\n")
    probe.use_plugin_files([plugin])
    with pytest.raises(PluginError, match="no such thing"):  # a file the command was given: its error, not a note
        build_cases(load_suite("smoke"), seeds=[0])
    probe.use_plugin_files([])
    cases, notes = build_cases(load_suite("smoke"), seeds=[0])
    assert cases and not [n for n in notes if "failed to load" in n]
