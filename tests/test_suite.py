"""Suite files: the format, the checks on every key, ids, budgets and the digest."""

from __future__ import annotations

import pytest

from earthbench.errors import SuiteError, UnknownNameError
from earthbench.results.suite import known_suites, load_suite, parse_seed_range, parse_suite

GOOD = """
name = "mini"
description = "two tiny maps"
track = "backhoe"
success_threshold = 0.8
planners = ["greedy"]
[budget]
wall_s = 7
cores = 2
memory_mb = 2048
[[family]]
name = "rbf2"
generator = "rbf"
targets = [0.28, 0.56]
seeds = "3-4"
[family.params]
n_bases = 2
size = [3.0, 2.0]
resolution = 0.1
[config.greedy]
min_fill = 0.5
"""


def test_a_suite_builds_labelled_scenarios_under_its_budget():
    s = parse_suite(GOOD)
    assert [sc.id for sc in s.scenarios] == ["mini/rbf2/s3/v0.28", "mini/rbf2/s4/v0.28", "mini/rbf2/s3/v0.56", "mini/rbf2/s4/v0.56"]
    assert all(sc.budget.wall_s == 7.0 and sc.budget.memory_mb == 2048 for sc in s.scenarios)
    assert s.scenarios[0].meta["seed"] == 3 and s.scenarios[0].meta["family"] == "rbf2"
    assert s.success_threshold == 0.8 and s.planners == ("greedy",) and s.config == {"greedy": {"min_fill": 0.5}}
    assert [sc.id for sc in s.select([4])] == ["mini/rbf2/s4/v0.28", "mini/rbf2/s4/v0.56"]


def test_digest_is_stable_and_sensitive():
    a, b = parse_suite(GOOD), parse_suite(GOOD)
    assert a.digest == b.digest and len(a.digest) == 64
    assert parse_suite(GOOD.replace("wall_s = 7", "wall_s = 7.0")).digest == a.digest
    assert parse_suite(GOOD.replace("success_threshold = 0.8", "success_threshold = 0.9")).digest != a.digest
    assert parse_suite(GOOD.replace('seeds = "3-4"', "seeds = [3, 5]")).digest != a.digest


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("success_threshold = 0.8", "sucess_threshold = 0.8", "unknown key 'sucess_threshold'.*'success_threshold'"),
        ("wall_s = 7", "wal_s = 7", r"\[budget\]: unknown key 'wal_s'.*'wall_s'"),
        ('generator = "rbf"', 'generater = "rbf"', "unknown key 'generater'.*'generator'"),
        ("n_bases = 2", "n_base = 2", "unknown key 'n_base'.*'n_bases'"),
        ('generator = "rbf"', 'generator = "rbff"', "unknown terrain generator 'rbff'.*'rbf'"),
        ('track = "backhoe"', 'track = "backhoes"', "did you mean 'backhoe'"),
        ('seeds = "3-4"', 'seeds = "4-3"', "empty"),
        ('seeds = "3-4"', 'seeds = "three"', "range 'A-B'"),
        ("targets = [0.28, 0.56]", "targets = [-1.0]", "positive"),
        ("memory_mb = 2048", "memory_mb = 0", "positive"),
        ("success_threshold = 0.8", "success_threshold = 1.5", r"\(0, 1\]"),
        ('name = "mini"', "name = 'a/b'", "without '/'"),
        ("[[family]]", "[[families]]", "unknown key 'families'.*'family'"),
        ("wall_s = 7", "wall_s = 7\nwall_s = 8", "not valid TOML"),
    ],
)
def test_mistakes_are_named_with_a_suggestion(old, new, message):
    assert old in GOOD
    with pytest.raises(SuiteError, match=message):
        _ = parse_suite(GOOD.replace(old, new, 1)).scenarios  # expanding the scenarios raises


def test_builtin_suites_are_found_through_the_entry_point():
    suites = known_suites()
    assert {"smoke", "quick"} <= set(suites)
    smoke = load_suite("smoke")
    assert smoke.planners == ("greedy",) and len(smoke.scenarios) == 4 and smoke.budget.wall_s == 60.0
    quick = load_suite("quick")
    assert quick.planners is None and quick.track == "backhoe"


def test_unknown_suite_lists_known_ones():
    with pytest.raises(UnknownNameError, match="unknown suite 'smok'. Did you mean 'smoke'.*Known suites:.*quick"):
        load_suite("smok")


def test_suite_by_path(tmp_path):
    f = tmp_path / "mine.toml"
    f.write_text(GOOD.replace('name = "mini"\n', ""))
    s = load_suite(str(f))
    assert s.name == "mine" and s.path == str(f)
    with pytest.raises(SuiteError, match="not found"):
        load_suite(str(tmp_path / "absent.toml"))


def test_seed_ranges():
    assert parse_seed_range("0-3") == (0, 1, 2, 3)
    assert parse_seed_range("7") == (7,)
    assert parse_seed_range("2,4") == (2, 4) and parse_seed_range("0-2, 7") == (0, 1, 2, 7)
    with pytest.raises(SuiteError, match="twice"):
        parse_seed_range("0-3,2")
    with pytest.raises(SuiteError, match="comma-separated"):
        parse_seed_range("2;4")
    with pytest.raises(SuiteError):
        parse_seed_range("x")


def test_quick_runs_every_builtin_planner_of_its_track():
    from earthbench.registry import PLANNERS
    from earthbench.running.harness import build_cases

    quick = load_suite("quick")
    cases, _ = build_cases(quick)
    expected = {n for n, c in PLANNERS.items() if "backhoe" in c.tracks and c.__module__.startswith("planners.")}
    assert expected <= {c.planner.name for c in cases}
    assert len(cases) == len(quick.scenarios) * len({c.planner.name for c in cases})
