"""Pinned suite digests: an accidental change to a generator, a suite file or the world model
changes a digest here and fails, so published results stay tied to the scenarios they ran on.

If a change is intended, update the digest and say in the commit which suites changed and why
(stored runs of the old scenarios no longer count for the new suite).
"""

from __future__ import annotations

import re

import pytest

from earthbench.errors import SuiteError
from earthbench.results.suite import load_suite, parse_suite
from earthbench_terrains.common import dig_area_volume

PINNED = {
    "smoke": ("17d4380c5c43371f276a09a68ddbca1ca2f0a1dcebc5a5074e0f614493ed4f5c", 4),
    "quick": ("d932d20f08b28b37607f10d898b8d37e1bcf471d60b81ebdb1d0f57bac46b32e", 4),
    "paper-switch": ("44330e676a7c6f3cd5e8b4fa7c03fb69e1acc9e35e8230cbb15f78df967257a6", 30),
    "paper-extensive": ("7bcd71d54536530206b7fea12e231a6f55c8f0ab14406da31dfd52795f327caf", 40),
    "bench": ("7e0dffdf3e21c6384d1c8da2780a59918d75e64918212234d104925f6670f1a1", 20),
    "dem": ("5e856db285831e09db36da3d4bc7e9538095b4d270c183027760d14e1c684880", 20),
    "scale": ("bba4c64802b31e045fa16718ded99996bd69f0cffc70bca0b93c9a88e828cbb0", 40),
    "standard": ("ee060f3ffea5a59bde3690940dabe22d47930d1fe85dc85a313d5a1d04d36b55", 110),
    "paper-separate-sweep": ("2b7c6f2a2ff0652b89206f0b399c5a4e90d6b4262b6f603a5bd050cd26b6bfa8", 10),
    "paper-extensive-realistic": ("1566b145ff463b710cd4f99697eec18c6adbee98f548b693a7aed5828d6dce1a", 24),
    "bench-realistic": ("885c776aee8be79d087be2459681ae462fd6a0e94d043920e481cb07b4877943", 12),
    "dem-realistic": ("ec1d302612121fcb2e84b1753fdf81fada050ad8e611405a284636bb94813cf2", 12),
    "standard-realistic": ("bada4b0e98754785279bfe0c9ed464d53e7f97ec67b24c7dc68243d98b0de11c", 48),
    "standard-20t": ("f30b58c4d26ce734386fb206492d0c533ac326a597c769407bc0bc16ac84ec60", 90),
    "standard-20t-realistic": ("eac742cebbab4716a3aafc0a1bec880688e1219e11bbed503150962aaed76a19", 36),
}
#: The 20-t class's loader suites (docs/machine-classes.md).
PILE_20T = {"pile-20t": ("2c48a5655a1d52191ed88701491e1d2d4b5d40ec1777c4e41116c001c596e1a0", 20),
            "pile-20t-realistic": ("9de797dd32651d5294fe022f66b5237ca8dea007a429668a165fe9a0a6f81d31", 12)}
#: The realistic loader suite (a wheel-loader suite, so outside the backhoe checks below).
PILE_REALISTIC = ("03f40951c961f54705214a82d1d3a5c19c2ff3163efdf1e162ad609cbc602711", 12)


@pytest.fixture(scope="module")
def suites():
    return {name: load_suite(name) for name in PINNED}


@pytest.mark.parametrize("name", sorted(PINNED))
def test_suite_digest_is_pinned(suites, name):
    digest, count = PINNED[name]
    s = suites[name]
    assert len(s.scenarios) == count
    assert s.digest == digest


@pytest.mark.parametrize("name", sorted(PINNED))
def test_suite_scenarios_hold_twice_their_target(suites, name):
    for sc in suites[name].scenarios:
        assert re.fullmatch(rf"{name}/[\w.-]+/s\d+/v[\d.]+", sc.id), sc.id
        assert sc.track == "backhoe"
        assert dig_area_volume(sc) >= 2 * sc.task.target_volume, sc.id
        assert sc.machines.truck.capacity >= sc.task.target_volume, sc.id


#: Scenarios whose target exceeds what their truck holds in bank m³ (10 loose m³ ÷ their soil's
#: swell): no plan can reach it. Published before this was checked (docs/publishing.md, "Every
#: committed suite"); no other scenario may join them.
OVER_THE_HOLD = {"bench-loam-survey/s2/v8", "bench-clay-survey/s4/v8", "bench-clay-cab/s5/v8"}


@pytest.mark.parametrize("name", sorted(PINNED))
def test_the_truck_holds_the_target_in_bank_m3(suites, name):
    over = {"/".join([family.split(".", 1)[-1], *rest]) for sc in suites[name].scenarios
            if sc.truck_holds < sc.task.target_volume
            for family, *rest in [sc.id.split("/")[1:]]}
    assert over <= OVER_THE_HOLD
    assert (over == OVER_THE_HOLD) == (name in ("bench-realistic", "standard-realistic"))


def test_paper_suites_follow_the_paper(suites):
    ext = suites["paper-extensive"]
    assert sorted({s.task.target_volume for s in ext.scenarios}) == [4.0, 5.0, 6.0, 7.0]
    assert sorted({s.meta["seed"] for s in ext.scenarios}) == list(range(10))
    assert {s.meta["n_bases"] for s in ext.scenarios} == {30}
    sw = suites["paper-switch"]
    assert sorted({round(s.task.target_volume / 0.28, 6) for s in sw.scenarios}) == [2.0, 3.0, 4.0]
    assert {s.meta["n_bases"] for s in sw.scenarios} == {14}
    for s in ext.scenarios + sw.scenarios:
        m = s.machines
        assert (m.excavator_pose.x, m.excavator_pose.y, m.truck_pose.x, m.truck_pose.y) == (13.0, 7.2, 2.0, 13.0)
        assert s.terrain.extent == (0.0, 12.0, 0.0, 6.0)


def test_scale_targets_grow_with_area(suites):
    per_area = {
        round(s.task.target_volume / ((s.terrain.extent[1]) * (s.terrain.extent[3])), 9) for s in suites["scale"].scenarios
    }
    assert per_area == {round(4.0 / 72.0, 9)}


def test_scale_is_a_ladder_of_four_sizes_up_to_96_by_48_m(suites):
    by_size: dict[tuple[float, float], list] = {}
    for sc in suites["scale"].scenarios:
        by_size.setdefault((sc.terrain.extent[1], sc.terrain.extent[3]), []).append(sc)
    assert sorted(by_size) == [(12.0, 6.0), (24.0, 12.0), (48.0, 24.0), (96.0, 48.0)]
    capacity = {12.0: 10.0, 24.0: 20.0, 48.0: 80.0, 96.0: 320.0}
    for (lx, ly), scs in by_size.items():
        assert sorted(sc.meta["seed"] for sc in scs) == list(range(10))
        for sc in scs:
            assert sc.terrain.z.shape == (round(ly / 0.05), round(lx / 0.05))
            assert sc.meta["n_bases"] == round(30 * lx * ly / 72)
            assert sc.machines.truck.capacity == capacity[lx]
            # the paper's poses as offsets from the map's corners: the same drive onto every map
            m = sc.machines
            assert (m.excavator_pose.x, m.excavator_pose.y, m.truck_pose.x, m.truck_pose.y) == (lx + 1.0, ly + 1.2, 2.0, ly + 7.0)
            assert sc.budget.wall_s == 600.0


def test_standard_is_the_union_and_shares_digests(suites):
    parts = ("paper-switch", "paper-extensive", "bench", "dem")
    union = sorted(sc.digest for p in parts for sc in suites[p].scenarios)
    assert sorted(sc.digest for sc in suites["standard"].scenarios) == union
    ids = {sc.id for sc in suites["standard"].scenarios}
    assert "standard/paper-extensive.rbf30/s0/v4" in ids


def test_realistic_suites_carry_soil_and_sensing_on_their_exact_terrains(suites):
    pile = load_suite("pile-realistic")
    assert (pile.digest, len(pile.scenarios)) == PILE_REALISTIC
    parts = ("paper-extensive-realistic", "bench-realistic", "dem-realistic")
    union = sorted(sc.digest for p in parts for sc in suites[p].scenarios)
    assert sorted(sc.digest for sc in suites["standard-realistic"].scenarios) == union
    for name, plain in (("paper-extensive-realistic", "paper-extensive"), ("bench-realistic", "bench"), ("dem-realistic", "dem")):
        terrains = {sc.meta["seed"]: sc.terrain for sc in suites[plain].scenarios}
        for sc in suites[name].scenarios:
            assert sc.soil is not None and sc.sensing is not None and sc.sensing.seed == sc.meta["seed"]
            assert sc.terrain == terrains[sc.meta["seed"]]  # the exact suite's map, now with soil and a scan
    combos = {(sc.soil.material, sc.sensing.occlusion) for sc in suites["standard-realistic"].scenarios + pile.scenarios}
    assert combos == {(m, o) for m in ("sand", "loam", "clay") for o in (False, True)}


def test_include_errors(tmp_path):
    base = tmp_path / "a.toml"
    base.write_text('name = "a"\ninclude = ["b.toml"]\n')
    (tmp_path / "b.toml").write_text('name = "b"\ninclude = ["a.toml"]\n')
    with pytest.raises(SuiteError, match="cycle"):
        load_suite(base)
    wl = tmp_path / "w.toml"
    wl.write_text('name = "w"\ntrack = "wheel_loader"\ninclude = ["paper-switch"]\n')
    with pytest.raises(SuiteError, match="track"):
        load_suite(wl)
    with pytest.raises(SuiteError, match="Did you mean 'paper-switch'"):
        parse_suite('name = "x"\ninclude = ["paper-swich"]\n')
    with pytest.raises(SuiteError, match="list of suite names"):
        parse_suite('name = "x"\ninclude = "bench"\n')
    with pytest.raises(SuiteError, match="at least one"):
        parse_suite('name = "x"\n')


@pytest.mark.parametrize("name", sorted(PILE_20T))
def test_the_20t_loader_suites_are_pinned_and_of_their_class(name):
    s = load_suite(name)
    assert (s.digest, len(s.scenarios)) == PILE_20T[name]
    assert {sc.machines.machine_class for sc in s.scenarios} == {"20t"}
    assert all(sc.machines.truck.capacity >= sc.task.target_volume for sc in s.scenarios)
