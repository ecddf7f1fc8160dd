"""The realistic track: soil known to the referee only, scans instead of the heightmap, and the
harness handing the planner the observation (docs/DESIGN.md §3, §5, §6)."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from earthbench import Plan, Scenario, judge
from earthbench.errors import ScenarioError, SuiteError
from earthbench.results.scoring import score
from earthbench.sensing import ANONYMOUS_ID, observe, visible_cells
from earthbench.soil import MATERIALS, draw, fill_range, nominal, reach_cells, slump, slump_cells
from earthbench.results.suite import load_suite, parse_suite
from earthbench.world import Heightmap, Pose, Sensing, Soil
from helpers import block_scenario, dig_dump_plan

GOLDEN = Path(__file__).parent / "golden"
PLUGIN = str(Path(__file__).parent / "plugins" / "observing_planners.py")

LOAM = Soil("loam", fill_factor=0.8, swell=1.25, repose_deg=35.0, hard_depth=None)


# -- the exact track stays exactly as it was ----------------------------------------------------

@pytest.mark.parametrize("name, suite", [("backhoe", "paper-extensive"), ("loader", "pile")])
def test_without_soil_the_verdict_is_byte_for_byte_the_golden_one(name, suite):
    """Verdict and metrics of a fixed plan, written by the referee before soil existed."""
    sc = load_suite(suite).scenarios[0]
    verdict, metrics = score(sc, (GOLDEN / f"verdict_{name}_plan.json").read_text(), 0.9)
    text = json.dumps({"verdict": verdict.to_dict(), "metrics": metrics}, sort_keys=True, indent=1) + "\n"
    assert text == (GOLDEN / f"verdict_{name}.json").read_text()


def test_a_scenario_without_the_sections_keeps_its_json_and_is_its_own_observation_but_for_its_name():
    sc = load_suite("smoke").scenarios[0]
    doc = json.loads(sc.to_json())
    assert "soil" not in doc and "sensing" not in doc
    view = observe(sc)
    assert view.digest == sc.digest and view.terrain is sc.terrain
    assert (view.id, view.meta) == (ANONYMOUS_ID, {})  # the exact track's planner sees the truth, not its name
    assert Scenario.from_json(sc.to_json()).digest == sc.digest


# -- the sections: JSON, digests, bad input ----------------------------------------------------

def test_soil_and_sensing_round_trip_and_enter_the_digest():
    sc = block_scenario()
    real = sc.replace(soil=LOAM, sensing=Sensing(noise=0.02, bias=-0.01, cell_size=0.1, seed=3))
    back = Scenario.from_json(real.to_json())
    assert back == real and back.digest == real.digest
    assert real.digest != sc.digest
    assert real.replace(soil=dataclasses.replace(LOAM, fill_factor=0.81)).digest != real.digest


@pytest.mark.parametrize("section, field, value, message", [
    ("soil", "fill_factor", 0.0, "soil.fill_factor must be > 0"),
    ("soil", "fill_factor", -0.5, "soil.fill_factor must be > 0"),
    ("soil", "repose_deg", 90.0, "soil.repose_deg must be < 90"),
    ("soil", "swell", 0.9, "soil.swell must be ≥ 1"),
    ("soil", "hard_depth", -1.0, "soil.hard_depth must be ≥ 0"),
    ("soil", "fill_factr", 1.0, "soil.fill_factr is unknown (did you mean soil.fill_factor?)"),
    ("soil", "material", "", "soil.material must be a non-empty string"),
    ("sensing", "noise", -0.01, "sensing.noise must be ≥ 0"),
    ("sensing", "noise", "0.1", "sensing.noise must be a number"),
    ("sensing", "cell_size", 0.07, "sensing.cell_size (0.07 m) must be a whole multiple"),
    ("sensing", "seed", 1.5, "sensing.seed must be an integer"),
    ("sensing", "occlusion", "yes", "sensing.occlusion must be true or false"),
])
def test_out_of_range_parameters_are_refused_with_the_field_path(section, field, value, message):
    doc = block_scenario().replace(soil=LOAM, sensing=Sensing(noise=0.01)).to_dict()
    doc[section][field] = value
    with pytest.raises(ScenarioError) as err:
        Scenario.from_dict(doc)
    assert message in str(err.value)


def test_a_soil_without_its_material_names_the_missing_field():
    doc = block_scenario().replace(soil=LOAM).to_dict()
    del doc["soil"]["material"]
    with pytest.raises(ScenarioError, match="scenario field soil.material is missing"):
        Scenario.from_dict(doc)


def test_a_suite_refuses_an_unknown_material_or_sensing_key(tmp_path):
    base = """name = "bad"\ntrack = "backhoe"\n[[family]]\nname = "f"\ngenerator = "rbf"\ntargets = [1.0]\nseeds = [0]\n"""
    with pytest.raises(SuiteError, match="family 'f'.*material must be one of sand, loam, clay, got 'granite'"):
        parse_suite(base + '[family.soil]\nmaterial = "granite"\n')
    with pytest.raises(SuiteError, match="family 'f' sensing: unknown key 'nois'.*'noise'"):
        parse_suite(base + "[family.sensing]\nnois = 0.1\n")
    with pytest.raises(SuiteError, match="family 'f'.*sensing.noise must be ≥ 0"):
        parse_suite(base + "[family.sensing]\nnoise = -0.1\n")


def test_a_site_draws_its_soil_within_its_class_from_its_seed():
    for material, m in MATERIALS.items():
        for seed in range(5):
            s = draw({"material": material}, seed)
            assert s == draw({"material": material}, seed)
            assert m.swell[0] <= s.swell <= m.swell[1] and m.repose_deg[0] <= s.repose_deg <= m.repose_deg[1]
            assert m.fill_loose[0] / m.swell[1] - 1e-6 <= s.fill_factor <= m.fill_loose[1] / m.swell[0] + 1e-6
        assert draw({"material": material}, 0) != draw({"material": material}, 1)
    assert draw({"material": "sand", "fill_factor": 1.0}, 0).fill_factor == 1.0


@pytest.mark.parametrize("machines", ["compact", "20t"])
def test_fill_range_bounds_every_site_a_class_draws_and_its_nominal_fill(machines):
    for material in MATERIALS:
        lo, hi = fill_range(material, machines)
        fills = [draw({"material": material}, seed, machines=machines).fill_factor for seed in range(40)]
        assert lo - 1e-6 <= min(fills) and max(fills) <= hi + 1e-6
        assert max(fills) > hi - 0.25 * (hi - lo)  # the bound is near the class's end, not a loose one
        assert lo < nominal(material, machines).fill_factor < hi


# -- slumping --------------------------------------------------------------------------------------

@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**31), ny=st.integers(2, 30), nx=st.integers(2, 30),
    relief=st.floats(0.0, 3.0), depth=st.floats(0.0, 2.0), repose=st.floats(5.0, 85.0),
    box=st.tuples(st.integers(0, 10), st.integers(0, 10), st.integers(0, 10), st.integers(0, 10)),
)
def test_slumping_conserves_volume_and_touches_nothing_outside_its_box(seed, ny, nx, relief, depth, repose, box):
    rng = np.random.default_rng(seed)
    before_all = rng.uniform(0.0, relief, (ny, nx))
    j0, i0 = min(box[0], ny - 1), min(box[2], nx - 1)
    j1, i1 = max(ny - box[1], j0 + 1), max(nx - box[3], i0 + 1)
    z = before_all.copy()
    cut = rng.uniform(0.0, depth, (j1 - j0, i1 - i0)) * (rng.uniform(size=(j1 - j0, i1 - i0)) < 0.4)
    z[j0:j1, i0:i1] -= cut  # a cut, then the slump
    after_cut = z.copy()
    fell = slump(z, 0.05, repose, before_all[j0:j1, i0:i1].copy(), (j0, j1, i0, i1))
    r2 = 0.05 * 0.05
    assert fell >= 0.0
    assert abs(z.sum() * r2 - after_cut.sum() * r2) <= 1e-9
    outside = np.ones(z.shape, dtype=bool)
    outside[j0:j1, i0:i1] = False
    assert np.array_equal(z[outside], after_cut[outside])


def _steepest(z: np.ndarray) -> float:
    """The largest height difference between two 4-neighbours."""
    return max(np.abs(np.diff(z, axis=0)).max(initial=0.0), np.abs(np.diff(z, axis=1)).max(initial=0.0))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**31), depth=st.floats(0.01, 1.5), repose=st.floats(20.0, 60.0),
    size=st.tuples(st.integers(1, 14), st.integers(1, 14)), ragged=st.booleans(),
)
def test_a_slumped_cut_keeps_the_volume_stays_above_its_floor_and_stands_at_repose(seed, depth, repose, size, ragged):
    """Level ground, a flat-bottomed cut of any depth and outline (as the referee cuts: every cell
    of the bucket's path down to one level), then its slump: the volume is conserved to 1e-9 m³,
    no cell ends lower than the cut's level (so never below a floor the cut respected), and no
    two neighbouring cells differ by more than the repose slope over a cell.

    On sloping ground the last holds only near the cut: the slump reaches ``depth / tan(repose)``
    from the channel (docs/DESIGN.md §5), so ground that rises faster than that keeps its faces."""
    rng = np.random.default_rng(seed)
    res, n = 0.05, 48
    before = np.full((n, n), 2.0)
    z = before.copy()
    h, w = size
    j0, i0 = int(rng.integers(0, n - h)), int(rng.integers(0, n - w))
    cut = np.zeros((n, n), dtype=bool)
    cut[j0:j0 + h, i0:i0 + w] = True
    if ragged:  # the bucket filled before the end of its path, or some cells were already low
        cut &= rng.uniform(size=(n, n)) < 0.7
    z[cut] = 2.0 - depth
    after_cut = z.copy()
    slump(z, res, repose, before)
    assert abs(z.sum() - after_cut.sum()) * res * res <= 1e-9
    assert z.min() >= 2.0 - depth - 1e-12
    assert _steepest(z) <= math.tan(math.radians(repose)) * res * (1 + 1e-9) + 1e-12


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**31), depth=st.floats(0.02, 1.5), repose=st.floats(20.0, 60.0),
    size=st.tuples(st.integers(1, 12), st.integers(1, 12)), shallow=st.floats(0.0, 1.0),
)
def test_what_falls_fills_the_channel_to_one_level(seed, depth, repose, size, shallow):
    """A channel whose cells were cut to different depths (some barely, as where the bucket
    filled or the harder layer held): the cells the slump fills all end at one level, the
    level at which what falls equals what fills, and the cells it leaves unfilled stand at or
    above it (their floor was higher). Holds whether the level covers the whole floor or not."""
    rng = np.random.default_rng(seed)
    res, n = 0.05, 40
    before = np.full((n, n), 2.0)
    h, w = size
    j0, i0 = int(rng.integers(0, n - h)), int(rng.integers(0, n - w))
    lowered = rng.uniform(0.0, depth, (h, w))
    lowered[rng.uniform(size=(h, w)) < shallow] *= 0.05  # some cells barely cut
    z = before.copy()
    z[j0:j0 + h, i0:i0 + w] -= lowered
    after_cut = z.copy()
    assume(slump(z, res, repose, before) > 0.0)  # a cut shallower than the slope over a cell lets nothing fall
    channel = after_cut < before - 1e-12
    filled = channel & (z > after_cut + 1e-12)
    assert filled.any()
    level = z[filled]
    assert level.max() - level.min() <= 1e-9
    assert (z[channel & ~filled] >= level.min() - 1e-9).all()


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**31), depth=st.floats(0.02, 1.0), repose=st.floats(20.0, 60.0),
       grow=st.tuples(st.integers(0, 6), st.integers(0, 6), st.integers(0, 6), st.integers(0, 6)))
def test_a_window_beyond_the_slopes_reach_changes_nothing(seed, depth, repose, grow):
    """The referee slumps inside the window the slope can reach (``slump_box`` narrowed by the
    cut's deepest loss); any larger window gives the same heights, bit for bit."""
    rng = np.random.default_rng(seed)
    res, n = 0.05, 60
    z = 2.0 + rng.uniform(-0.3, 0.3, (n, n))
    jj, ii = np.nonzero(np.add.outer(np.arange(n), np.arange(n)) % 7 < 3)  # a diagonal band of cells
    keep = (jj > 20) & (jj < 35) & (ii > 18) & (ii < 40) & (rng.uniform(size=jj.size) < 0.8)
    jj, ii = jj[keep], ii[keep]
    lost = rng.uniform(0.01, depth, jj.size)
    z[jj, ii] -= lost
    pad = reach_cells(float(lost.max()), res, repose)
    window = (max(int(jj.min()) - pad, 0), min(int(jj.max()) + pad + 1, n), max(int(ii.min()) - pad, 0), min(int(ii.max()) + pad + 1, n))
    wider = (max(window[0] - grow[0], 0), min(window[1] + grow[1], n), max(window[2] - grow[2], 0), min(window[3] + grow[3], n))
    a, b = z.copy(), z.copy()
    fell = slump_cells(a, res, repose, jj, ii, float(lost.max()), window)
    assert fell == slump_cells(b, res, repose, jj, ii, float(lost.max()), wider)
    assert np.array_equal(a, b)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(material=st.sampled_from(sorted(MATERIALS)), seed=st.integers(0, 1000), floor=st.floats(0.55, 0.95),
       contact=st.tuples(st.floats(3.0, 5.0), st.floats(4.5, 5.5)), depth=st.floats(0.05, 0.4))
def test_with_soil_no_cell_ends_below_the_floor(material, seed, floor, contact, depth):
    """Two digs at one place with a drawn soil: the referee cuts at the floor at most and what
    slumps never carries the ground below it."""
    sc = block_scenario(floor=floor).replace(soil=draw({"material": material}, seed))
    first = dig_dump_plan(contact=contact, depth=depth)
    t = first[-1].t_end
    second = dig_dump_plan(contact=contact, depth=depth, t0=t)
    v = judge(sc, Plan(tuple(first + second)))
    assert v.final_terrain.z.min() >= floor - 1e-9
    assert "below_floor" not in {x.rule for x in v.violations}


@pytest.mark.parametrize("track", ["exact", "soil", "scan", "soil and scan"])
def test_a_cut_below_the_floor_is_flagged_only_where_the_planner_sees_the_truth(track):
    """The exact track flags it; where the planner's model is not the world (soil: slumping moves
    the ground it planned on; a scan: it never saw the true ground) the cut is made at the floor,
    and it removes what a dig to the floor removes: nothing more."""
    sc = block_scenario(floor=0.7)
    if "soil" in track:
        sc = sc.replace(soil=LOAM)
    if "scan" in track:
        sc = sc.replace(sensing=Sensing(noise=0.02, seed=1))
    deep = judge(sc, Plan(tuple(dig_dump_plan(depth=0.4))))  # level 0.6: 0.1 m below the floor
    to_floor = judge(sc, Plan(tuple(dig_dump_plan(depth=0.3))))  # level 0.7: the floor
    assert ("below_floor" in {x.rule for x in deep.violations}) == (track == "exact")
    assert deep.final_terrain.z.min() >= 0.7 - 1e-9
    assert deep.digs[0].volume == pytest.approx(to_floor.digs[0].volume, abs=1e-12)
    assert deep.loaded_volume == pytest.approx(to_floor.loaded_volume, abs=1e-12)


def test_a_cut_pit_collapses_to_the_repose_angle():
    before = np.zeros((40, 40))
    z = before.copy()
    z[10:24, 12:26] = -0.4
    fell = slump(z, 0.05, 35.0, before)
    limit = math.tan(math.radians(35.0)) * 0.05
    assert fell > 0.0
    assert max(np.abs(np.diff(z, axis=0)).max(), np.abs(np.diff(z, axis=1)).max()) <= limit + 1e-9
    assert z.sum() == pytest.approx(-0.4 * 14 * 14, abs=1e-9)
    assert -0.4 < z[17, 19] < 0.0  # the floor rose with what fell
    assert z[0, 0] == 0.0  # beyond the run of the slope over 0.4 m nothing moved


def test_undisturbed_ground_keeps_its_natural_slope():
    """Slopes steeper than the repose angle that no cut made stay (cohesion holds the bank)."""
    z = np.tile(np.linspace(0.0, 2.0, 30), (20, 1))  # 2 m over 1.5 m: about 53°
    before = z.copy()
    assert slump(z, 0.05, 30.0, before) == 0.0
    assert np.array_equal(z, before)


# -- the referee with soil --------------------------------------------------------------------------

def test_each_dig_reports_its_nominal_and_its_real_volume():
    sc = block_scenario(target=0.2)
    plan = Plan(tuple(dig_dump_plan()))
    exact = judge(sc, plan)
    real = judge(sc.replace(soil=LOAM), plan)
    (d_exact,), (d_real,) = exact.digs, real.digs
    assert d_exact.nominal is None and "nominal" not in d_exact.to_dict()
    assert d_real.nominal == pytest.approx(d_exact.volume) == pytest.approx(0.28)
    assert d_real.volume == pytest.approx(0.8 * 0.28)
    assert real.loaded_volume == pytest.approx(0.8 * 0.28) and real.valid
    assert real.removed_volume == pytest.approx(0.8 * 0.28)
    # the slab's material is conserved: what the grid lost is what the bucket took
    lost = (sc.terrain.z.sum() - real.final_terrain.z.sum()) * sc.terrain.cell_area
    assert lost == pytest.approx(real.removed_volume, abs=1e-9)


def test_the_truck_counts_loose_volume():
    sc = block_scenario(target=0.2)
    truck = dataclasses.replace(sc.machines.truck, capacity=0.25)
    sc = sc.replace(machines=dataclasses.replace(sc.machines, truck=truck))
    soil = dataclasses.replace(LOAM, fill_factor=1.0, swell=1.25)
    v = judge(sc.replace(soil=soil), Plan(tuple(dig_dump_plan())))
    assert v.digs[0].volume == pytest.approx(0.28)
    assert v.loaded_volume == pytest.approx(0.25 / 1.25)  # 0.25 loose m³ are 0.2 bank m³


def test_a_harder_layer_limits_the_cut_per_stroke():
    sc = block_scenario(target=0.2)
    soil = dataclasses.replace(LOAM, fill_factor=1.0, hard_depth=0.1, hard_penetration=0.05)
    v = judge(sc.replace(soil=soil), Plan(tuple(dig_dump_plan(depth=0.4))))
    # the stroke reaches 0.1 m of soft ground plus 0.05 m of the harder layer, not 0.4 m
    assert v.digs[0].volume == pytest.approx(0.15 * 0.7 * 1.0, rel=0.08)
    assert v.digs[0].nominal == pytest.approx(0.28)


def test_a_cut_face_slumps_and_keeps_the_volume():
    sc = block_scenario(target=0.2)
    soil = dataclasses.replace(LOAM, fill_factor=1.0, repose_deg=30.0)
    plan = Plan(tuple(dig_dump_plan()))
    exact, real = judge(sc, plan), judge(sc.replace(soil=soil), plan)
    assert exact.digs[0].volume == pytest.approx(real.digs[0].volume)
    area = sc.terrain.cell_area
    assert exact.final_terrain.z.sum() * area == pytest.approx(real.final_terrain.z.sum() * area, abs=1e-9)
    def steep(z):
        return np.abs(np.diff(z, axis=0)).max()
    assert steep(exact.final_terrain.z) == pytest.approx(0.4)
    assert steep(real.final_terrain.z) <= math.tan(math.radians(30.0)) * 0.05 + 1e-3


def test_a_loader_drives_over_what_slumped_but_the_truck_gets_less():
    """The wheels' step rule measures firm ground: loose material that slumped in front of the
    face is driven over (and cut again); the truck gets the soil's fill factor."""
    sc = load_suite("pile").scenarios[0]
    plan = (GOLDEN / "verdict_loader_plan.json").read_text()
    exact = judge(sc, plan)
    real = judge(sc.replace(soil=Soil("sand", 0.8, 1.0, 30.0, None)), plan)
    assert exact.valid and real.valid
    assert not np.array_equal(exact.final_terrain.z, real.final_terrain.z)
    assert real.loaded_volume < exact.loaded_volume
    for d in real.digs:
        assert d.volume <= 0.8 * 0.8 + 1e-9 and d.nominal is not None


# -- perception ---------------------------------------------------------------------------------------

def wall_scenario() -> Scenario:
    """Flat ground at 0 with a 2 m wall across x ∈ [4, 4.5) m; the excavator at x = 1 m."""
    sc = block_scenario(height=0.0)
    z = np.zeros(sc.terrain.shape)
    z[:, 80:90] = 2.0
    return sc.replace(terrain=Heightmap((0.0, 0.0), 0.05, z), machines=dataclasses.replace(sc.machines, excavator_pose=Pose(1.0, 3.0, 0.0)))


def test_cells_behind_a_wall_are_hidden_from_the_cab():
    sc = wall_scenario()
    seen = visible_cells(sc.terrain, (1.0, 3.0, 2.5), 0.0)
    assert seen[:, :80].all() and seen[:, 80:90].all()  # the ground before the wall and its top
    # the sight line over the wall's far edge (4.5 m, 2 m) from (1, 2.5) drops 1/7 m per m:
    # it meets the ground 17.5 m out, so every cell behind the wall is hidden
    assert not seen[:, 91:].any()


def test_the_observation_holds_the_scan_and_the_nominal_soil_only():
    truth = wall_scenario().replace(
        soil=draw({"material": "clay"}, 4), sensing=Sensing(noise=0.02, bias=0.01, seed=9), meta={"generator": "x", "seed": 4}
    )
    view = observe(truth)
    assert view.soil == nominal("clay") != truth.soil
    assert view.sensing is None and view.meta == {}
    assert view.machines == truth.machines and view.task == truth.task and view.site == truth.site
    err = view.terrain.z - truth.terrain.z
    assert abs(float(err[:, :80].mean()) - 0.01) < 0.002 and float(err[:, :80].std()) == pytest.approx(0.02, rel=0.05)
    # behind the wall the scan fills from the nearest seen cell, under the sight line
    assert float(view.terrain.z[:, 95:].mean()) > 0.5
    assert observe(truth) == view
    assert observe(truth, step=1) != view
    assert observe(truth, pose=Pose(7.0, 3.0, math.pi)) != view


def test_a_coarser_scan_averages_blocks_and_without_sensing_the_terrain_is_exact():
    truth = block_scenario().replace(sensing=Sensing(cell_size=0.1, occlusion=False))
    view = observe(truth)
    assert view.terrain.resolution == pytest.approx(0.1) and view.terrain.shape == (60, 80)
    assert np.allclose(view.terrain.z, 1.0)
    soil_only = block_scenario().replace(soil=LOAM)
    assert observe(soil_only).terrain == soil_only.terrain and observe(soil_only).soil == nominal("loam")


# -- the harness hands the planner the observation -------------------------------------------------

def test_the_case_process_gets_only_the_observation(tmp_path):
    from earthbench.running.harness import build_cases, run_case
    from earthbench.registry import load_plugin_file

    load_plugin_file(PLUGIN)
    suite_file = tmp_path / "real.toml"
    suite_file.write_text("""name = "real"\ntrack = "backhoe"\n[budget]\nwall_s = 60\ncores = 2\nmemory_mb = 2048
[[family]]\nname = "f"\ngenerator = "rbf"\ntargets = [1.0]\nseeds = [0]\n[family.params]\nn_bases = 14
[family.soil]\nmaterial = "sand"\n[family.sensing]\nnoise = 0.02\ncell_size = 0.1\n""")
    (case,), _ = build_cases(load_suite(suite_file), ["t-snoop"], plugins=[PLUGIN])
    truth = case.scenario
    result = run_case(case)
    seen = json.loads(result.plan_json)["info"]
    view = observe(truth)
    assert seen["digest"] == view.digest != truth.digest
    z = np.ascontiguousarray(view.terrain.z, dtype="<f8")
    assert seen["terrain_sha256"] == hashlib.sha256(z.tobytes()).hexdigest()
    assert seen["resolution"] == pytest.approx(0.1)
    assert seen["soil"] == json.loads(view.to_json())["soil"] != json.loads(truth.to_json())["soil"]
    assert seen["sensing"] is None and seen["meta"] == {}
    assert result.key[0] == truth.digest  # stored under the truth, judged on the truth
