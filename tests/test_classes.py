"""Machine classes as data (docs/machine-classes.md): the compact class is the specs' defaults,
a scenario names its class and its digest covers the class's parameters, suites name or sweep
classes, and `earthbench calibration` holds every calibrated class inside its handbook bands."""

from __future__ import annotations

import dataclasses

import pytest

from earthbench.results.calibration import backhoe_cycle, calibration
from earthbench.classes import fit, machine_class, machine_classes, parse_class
from earthbench.cli import main
from earthbench.errors import ScenarioError, SuiteError, UnknownNameError
from earthbench.machines import ExcavatorSpec, LoaderSpec, Machines, TruckSpec
from earthbench.soil import draw, nominal
from earthbench.results.suite import parse_suite
from earthbench.world import Scenario
from earthbench_terrains.rbf import rbf


def test_the_compact_class_is_the_specs_defaults():
    c = machine_class("compact")
    assert (c.excavator, c.truck, c.loader) == (ExcavatorSpec(), TruckSpec(), LoaderSpec())
    assert Machines().machine_class == "compact" and not c.calibrated


def test_every_class_value_that_differs_from_compact_names_its_source():
    compact = machine_class("compact")
    for mc in machine_classes().values():
        for machine in ("excavator", "truck", "loader"):
            mine, base = getattr(mc, machine), getattr(compact, machine)
            for f in dataclasses.fields(mine):
                if getattr(mine, f.name) != getattr(base, f.name):
                    assert f"{machine}.{f.name}" in mc.sources, f"{mc.name}: {machine}.{f.name} has no source"


def test_a_class_file_is_checked_like_a_scenario_document():
    with pytest.raises(ScenarioError, match=r"\[excavator\].bucket_capacity must be positive"):
        parse_class('name = "x"\n[excavator]\nbucket_capacity = -1\n', "x.toml")
    with pytest.raises(ScenarioError, match="did you mean 'excavator'"):
        parse_class('name = "x"\n[excavatr]\n', "x.toml")
    with pytest.raises(UnknownNameError, match="Did you mean '20t'"):
        machine_class("20")


def test_a_scenario_of_another_class_names_it_and_its_digest_covers_the_parameters():
    sc = rbf(0, 4.0 / 3.375, n_bases=30)
    big = fit(sc, machine_class("20t"), 4.0)
    assert "machine_class" not in sc.to_dict()["machines"]  # the compact class keeps the old document
    assert big.to_dict()["machines"]["machine_class"] == "20t"
    assert Scenario.from_dict(big.to_dict()) == big and Scenario.from_dict(big.to_dict()).digest == big.digest
    assert big.terrain.resolution == pytest.approx(sc.terrain.resolution * 1.5) and big.terrain.shape == sc.terrain.shape
    assert big.machines.excavator == machine_class("20t").excavator
    tweaked = big.replace(machines=dataclasses.replace(big.machines, excavator=dataclasses.replace(
        big.machines.excavator, swing_rate=1.0)))
    assert tweaked.digest != big.digest
    with pytest.raises(ScenarioError, match="truck carries 11 m³, less than the target 12"):
        fit(sc, machine_class("20t"), 12.0)


def test_a_suite_names_a_class_or_sweeps_classes():
    text = ('name = "s"\n{head}\n[[family]]\nname = "rbf"\ngenerator = "rbf"\ntargets = [4.0]\nseeds = [0]\n'
            '[family.params]\nn_bases = 30\n')
    one = parse_suite(text.format(head='class = "20t"'))
    assert [sc.machines.machine_class for sc in one.scenarios] == ["20t"]
    sweep = parse_suite(text.format(head='classes = ["compact", "20t"]'))
    assert [sc.id for sc in sweep.scenarios] == ["s/rbf@compact/s0/v4", "s/rbf@20t/s0/v4"]
    plain = parse_suite(text.format(head=""))
    assert sweep.scenarios[0].digest == plain.scenarios[0].digest  # the compact class: the same scenario
    assert sweep.scenarios[1].digest == one.scenarios[0].digest
    with pytest.raises(SuiteError, match="Did you mean '20t'"):
        parse_suite(text.format(head='class = "20T"'))


def test_a_class_s_fill_factors_replace_the_material_s_in_its_scenarios_only():
    assert draw({"material": "clay"}, 3) == draw({"material": "clay"}, 3, machines="compact")
    lo, hi = machine_class("20t").fill_loose["clay"]
    soil = draw({"material": "clay"}, 3, machines="20t")
    assert lo <= soil.fill_factor * soil.swell <= hi
    assert nominal("clay", "20t").fill_factor * nominal("clay", "20t").swell == pytest.approx((lo + hi) / 2, abs=1e-5)


def test_every_calibrated_class_lies_inside_its_handbook_bands(capsys):
    assert main(["calibration", "--sources"]) == 0
    out = capsys.readouterr().out
    assert "OUTSIDE" not in out and "Caterpillar Performance Handbook ed. 47" in out
    rows = [r for r in calibration(["20t"])]
    assert rows and all(r.inside for r in rows)
    assert {r.what for r in rows} == {"cycle", "fill"} and {r.machine for r in rows} == {"excavator", "loader"}


def test_the_calibration_s_figures_are_the_referee_s_and_a_slower_machine_leaves_its_band(monkeypatch):
    mc = machine_class("20t")
    assert backhoe_cycle(mc, 180.0) > backhoe_cycle(mc, 90.0) > backhoe_cycle(mc, 45.0)
    slow = dataclasses.replace(mc, excavator=dataclasses.replace(mc.excavator, min_stroke_time=14.0))
    monkeypatch.setattr("earthbench.results.calibration.machine_classes", lambda: {"20t": slow})
    assert main(["calibration"]) == 1


def test_production_is_bank_m3_an_hour_and_the_stamp_names_the_class_s_band():
    from earthbench.results.aggregate import production
    from earthbench.publishing.board.tables import production_note

    assert production(18.0) == pytest.approx(200.0) and production(float("inf")) == 0.0
    note = production_note({"20t"}, "backhoe")
    assert "bank m³ an hour" in note and "44–107 m³/h" in note
    assert "uncalibrated" in production_note({"compact"}, "backhoe")
    # the board says where its best median lies against the band, and by how much
    assert "226 m³/h, lies 2.1 × the band's top" in production_note({"20t"}, "backhoe", best=226.3)
    assert "lies inside it" in production_note({"20t"}, "backhoe", best=80.0)
    assert "2.2 × below its bottom" in production_note({"20t"}, "backhoe", best=20.0)
    assert "best median" not in production_note({"20t"}, "backhoe", best=0.0)  # no run reached the target
