"""Speed of scenario generation (each generator call includes its volume and pose checks).

Run with ``pytest tests/bench --benchmark-only``; reported, not asserted.
"""

from __future__ import annotations

import pytest

from earthbench_terrains.bench import bench
from earthbench_terrains.dem import dem
from earthbench_terrains.rbf import rbf

CASES = {
    "rbf30-12x6": lambda: rbf(0, 7.0, n_bases=30),
    "rbf480-48x24": lambda: rbf(0, 64.0, n_bases=480, size=(48.0, 24.0), truck_capacity=80.0),
    "bench": lambda: bench(0, 8.0),
    "dem": lambda: dem(0, 7.0),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_generate(benchmark, name):
    sc = benchmark(CASES[name])
    benchmark.extra_info["cells"] = int(sc.terrain.z.size)
