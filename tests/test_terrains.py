"""Terrain generators: determinism, volumes, and poses the referee accepts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from earthbench.errors import ScenarioError
from earthbench.plan import Dig, Dump, Plan
from earthbench.referee import judge
from earthbench.registry import TERRAINS
from earthbench.world import Scenario
from terrains.bench import bench
from terrains.common import dig_area_volume, polygon_mask, reachable_volume
from terrains.rbf import rbf


def _one_cycle(sc: Scenario, contact: tuple[float, float]) -> Plan:
    """One dig toward the base at ``contact`` and one dump, with generous durations."""
    base = sc.machines.excavator_pose
    heading = math.atan2(base.y - contact[1], base.x - contact[0])
    return Plan(
        actions=(
            Dig("excavator", 0.0, 20.0, contact, heading, 0.3, 1.0),
            Dump("excavator", 20.0, 40.0),
        )
    )


# -- rbf -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("n_bases", [14, 30])
def test_rbf_reproduces_the_papers_setup(n_bases):
    sc = rbf(0, 4.0, n_bases=n_bases)
    assert sc.terrain.extent == (0.0, 12.0, 0.0, 6.0)
    assert sc.terrain.shape == (120, 240)
    m = sc.machines
    assert (m.excavator_pose.x, m.excavator_pose.y) == (13.0, 7.2)
    assert (m.truck_pose.x, m.truck_pose.y) == (2.0, 13.0)
    assert math.hypot(13.0 - 2.0, 7.2 - 13.0) >= m.excavator.clearance
    assert sc.site.floor == 0.0 and dig_area_volume(sc) >= 2 * 7.0
    assert rbf(0, 4.0, n_bases=n_bases).digest == sc.digest
    assert rbf(1, 4.0, n_bases=n_bases).digest != sc.digest


def test_rbf_local_area_is_the_richest_window():
    sc = rbf(5, 1.12, local_area=(2.0, 1.75))
    xs = sorted({p[0] for p in sc.site.dig_area})
    ys = sorted({p[1] for p in sc.site.dig_area})
    assert xs[1] - xs[0] == pytest.approx(2.0) and ys[1] - ys[0] == pytest.approx(1.75)
    mask = polygon_mask(sc.terrain, sc.site.dig_area)
    assert mask.sum() == 40 * 35  # cell centres strictly inside the window, none on its edges
    held = dig_area_volume(sc)
    assert held >= 2 * 1.12
    # No shifted window holds more (sampled shifts of whole cells).
    z = sc.terrain.z
    j0, i0 = np.argwhere(mask)[0]
    for dj, di in [(-3, 0), (3, 0), (0, -3), (0, 3), (5, 5)]:
        j, i = j0 + dj, i0 + di
        if 0 <= j <= z.shape[0] - 35 and 0 <= i <= z.shape[1] - 40:
            assert z[j : j + 35, i : i + 40].sum() * 0.0025 <= held + 1e-9


def test_rbf_scaled_maps_keep_the_corner_offsets_and_take_a_truck_capacity():
    sc = rbf(0, 16.0, n_bases=120, size=[24, 12], truck_capacity=20.0)
    assert sc.terrain.extent == (0.0, 24.0, 0.0, 12.0)
    m = sc.machines
    assert (m.excavator_pose.x, m.excavator_pose.y) == (25.0, 13.2)
    assert (m.truck_pose.x, m.truck_pose.y) == (2.0, 19.0)
    assert m.truck.capacity == 20.0
    with pytest.raises(ScenarioError, match="truck_capacity"):
        rbf(0, 16.0, n_bases=120, size=[24, 12])


def test_rbf_rejects_a_target_the_map_cannot_hold():
    with pytest.raises(ScenarioError, match="holds"):
        rbf(7, 2.0, local_area=(2.0, 1.75))


# -- bench -------------------------------------------------------------------------------------
def test_bench_is_deterministic_and_seeded():
    a, b, c = bench(3, 4.0), bench(3, 4.0), bench(4, 4.0)
    assert a.digest == b.digest
    assert a.digest != c.digest
    assert Scenario.from_json(a.to_json()).digest == a.digest


@pytest.mark.parametrize("seed", range(10))
def test_bench_holds_twice_the_suite_target_within_reach(seed):
    sc = bench(seed, 8.0)
    assert dig_area_volume(sc) >= 2 * 8.0
    # A planner that never moves the base can still reach the target.
    assert reachable_volume(sc) >= 8.0
    m = sc.machines
    d = math.hypot(m.truck_pose.x - m.excavator_pose.x, m.truck_pose.y - m.excavator_pose.y)
    assert m.excavator.clearance <= d <= m.excavator.reach_max + m.truck.loading_radius
    # The truck stands on the floor, west of every toe.
    assert sc.terrain.height_at(m.truck_pose.x, m.truck_pose.y) == 0.0
    assert sc.site.floor == 0.0


def test_bench_face_can_be_dug_and_loaded_from_the_initial_pose():
    sc = bench(0, 4.0)
    base = sc.machines.excavator_pose
    # Contact on the bench just behind the crest, 3.2 m in front of the base.
    verdict = judge(sc, _one_cycle(sc, (base.x - 3.2, base.y)))
    assert verdict.valid, verdict.violations
    assert verdict.loaded_volume == pytest.approx(sc.machines.excavator.bucket_capacity, rel=1e-6)


def test_bench_rejects_a_target_the_site_cannot_hold():
    with pytest.raises(ScenarioError, match="holds"):
        bench(0, 30.0, truck_capacity=40.0)
    with pytest.raises(ScenarioError, match="truck carries"):
        bench(0, 12.0)


def test_generators_are_registered():
    for name in ("rbf", "bench"):
        assert name in TERRAINS.names()
