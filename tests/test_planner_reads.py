"""The folders a planner declares it reads (``Planner.reads``, docs/plugins.md "Folders a planner
reads"): the harness, which names no planner, resolves each on the machine that runs the case,
gives the case its variable and shows it that folder read only, and nothing else beside it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from earthbench.errors import PluginError
from earthbench.running.harness import build_cases, isolation, run_case
from earthbench.running.harness.visible import check_shared, shared_folders
from earthbench.planner import SharedFolder
from earthbench.results.suite import parse_suite

from helpers import tiny_suite_toml

PLUGIN = str(Path(__file__).parent / "plugins" / "reading_planners.py")

pytestmark = pytest.mark.usefixtures("forget_test_planners")


def _info(name: str) -> dict:
    (case,), _ = build_cases(parse_suite(tiny_suite_toml("reads")), [name], plugins=[PLUGIN])
    res = run_case(case, (0,))
    assert res.reason == "ok", res.error
    return json.loads(res.plan_json)["info"]


@pytest.fixture
def folders(tmp_path, monkeypatch):
    shared, other = tmp_path / "shared", tmp_path / "other"
    shared.mkdir()
    other.mkdir()
    (shared / "built.bin").write_text("x")
    (other / "secret.txt").write_text("y")
    monkeypatch.setenv("EARTHBENCH_TEST_SHARED", str(shared))
    return shared


def test_a_case_reads_the_folder_its_planner_declares_and_is_told_where(folders):
    info = _info("t-reads-shared")
    assert info["env"] == str(folders.resolve()) and info["shared"] == ["built.bin"]
    if isolation.support().bwrap:  # nothing else beside it
        assert info["other"] == "FileNotFoundError"


def test_a_planner_that_declares_nothing_is_shown_nothing(folders):
    info = _info("t-reads-nothing")
    assert info["env"] is None and info["shared"] == "unset"


def test_off_is_passed_on_and_shows_no_folder(folders, monkeypatch):
    monkeypatch.setenv("EARTHBENCH_TEST_SHARED", "off")
    assert shared_folders([SharedFolder("EARTHBENCH_TEST_SHARED", "earthbench/x")]) == ({"EARTHBENCH_TEST_SHARED": "off"}, ())
    assert _info("t-reads-shared")["env"] == "off"


def test_the_default_lies_under_the_users_cache_folder(tmp_path, monkeypatch):
    monkeypatch.delenv("EARTHBENCH_TEST_SHARED", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    (tmp_path / "earthbench" / "test-shared").mkdir(parents=True)
    env, seen = shared_folders([SharedFolder("EARTHBENCH_TEST_SHARED", "earthbench/test-shared")])
    assert env == {"EARTHBENCH_TEST_SHARED": str((tmp_path / "earthbench" / "test-shared").resolve())}
    assert seen == (env["EARTHBENCH_TEST_SHARED"],)


@pytest.mark.parametrize("env, default", [
    ("EARTHBENCH_DB", "a/b"), ("HOME", "a"), ("EARTHBENCH_X", "/etc"), ("EARTHBENCH_X", "../x"), ("EARTHBENCH_X", "a/../../b"),
    ("EARTHBENCH_X", "earthbench"), ("EARTHBENCH_X", "earthbench/probes"), ("EARTHBENCH_X", "earthbench/prepared/k"),
    ("EARTHBENCH_X", ".ssh"), ("EARTHBENCH_X", ""), ("EARTHBENCH_X", "huggingface"), ("EARTHBENCH_X", "earthbench/.hidden"),
    ("EARTHBENCH_x", "earthbench/a"),
])
def test_a_declaration_that_could_show_more_is_refused(env, default):
    assert check_shared([SharedFolder(env, default)])
    assert shared_folders([SharedFolder(env, default)]) == ({}, ())
    assert not check_shared([SharedFolder("EARTHBENCH_X_CACHE", "earthbench/nlp"), SharedFolder("EARTHBENCH_Y", "earthbench/my-p/x")])
    assert check_shared([SharedFolder(f"EARTHBENCH_X{i}", "earthbench/a") for i in range(9)])


def test_a_plugins_bad_declaration_is_refused_when_it_is_described(tmp_path):
    bad = tmp_path / "bad_reads.py"
    bad.write_text("from earthbench.planner import Planner, SharedFolder\n\n\n"
                   "class ReadsTheStore(Planner):\n"
                   "    name = 't-reads-bad'\n"
                   "    reads = (SharedFolder('EARTHBENCH_DB', 'earthbench/test-shared'),)\n\n"
                   "    def plan(self, scenario):\n"
                   "        raise NotImplementedError\n")
    with pytest.raises(PluginError, match="t-reads-bad.*EARTHBENCH_DB.*one of the harness's own"):
        build_cases(parse_suite(tiny_suite_toml("reads")), ["t-reads-bad"], plugins=[str(bad)])


def test_stl_tamp_and_separate_declare_the_nlp_cache_where_it_looks(tmp_path, monkeypatch):
    from earthbench_planners.separate.planner import SeparatePlanner
    from earthbench_planners.stl_tamp import StlTampPlanner, nlp_cache

    assert SeparatePlanner.reads == StlTampPlanner.reads and not check_shared(StlTampPlanner.reads)
    monkeypatch.delenv(nlp_cache.ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    env, _ = shared_folders(StlTampPlanner.reads)
    assert env == {nlp_cache.ENV: str(nlp_cache.directory().resolve())}
