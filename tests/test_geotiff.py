"""GeoTIFF terrain files: cell size, origin and no-data from the file, metres required, resampling only when asked.

Each test writes a small GeoTIFF with rasterio from a known surface on a real projected CRS
(UTM zone 33N, EPSG:32633) and reads it back through the ``file`` generator.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

rasterio = pytest.importorskip("rasterio")
from rasterio.transform import Affine  # noqa: E402

from earthbench import ScenarioError, judge  # noqa: E402
from earthbench.cli import main  # noqa: E402
from earthbench.results.suite import load_suite  # noqa: E402
from earthbench_terrains.files import heightmap_file, load_heightmap  # noqa: E402

WEST, SOUTH = 455_000.0, 5_330_000.0  # metres, UTM 33N


def surface(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A tilted plane (so orientation errors show) with a Gaussian mound of material to dig."""
    u, v = x - WEST, y - SOUTH
    return 300.0 + 0.02 * u + 0.05 * v + 0.9 * np.exp(-((u - 6.0) ** 2 + (v - 3.0) ** 2) / (2 * 1.5 ** 2))


def write_tif(path: Path, *, cell: float = 0.1, size=(12.0, 6.0), crs="EPSG:32633", nodata_cells=(), nodata=-9999.0) -> Path:
    nx, ny = int(round(size[0] / cell)), int(round(size[1] / cell))
    xs = WEST + (np.arange(nx) + 0.5) * cell
    ys = SOUTH + size[1] - (np.arange(ny) + 0.5) * cell  # row 0 is the northern edge
    z = surface(xs[None, :], ys[:, None])
    for r, c in nodata_cells:
        z[r, c] = nodata
    with rasterio.open(path, "w", driver="GTiff", width=nx, height=ny, count=1, dtype="float64", crs=crs,
                       transform=Affine(cell, 0.0, WEST, 0.0, -cell, SOUTH + size[1]), nodata=nodata) as ds:
        ds.write(z, 1)
    return path


def test_cell_size_origin_and_orientation_come_from_the_file(tmp_path):
    hm = load_heightmap(write_tif(tmp_path / "site.tif"))
    assert hm.resolution == pytest.approx(0.1) and hm.origin == (WEST, SOUTH)
    assert hm.z.shape == (60, 120)
    ny, nx = hm.z.shape
    xs = WEST + (np.arange(nx) + 0.5) * 0.1
    ys = SOUTH + (np.arange(ny) + 0.5) * 0.1  # earthbench's row 0 is the southern edge
    np.testing.assert_allclose(hm.z, surface(xs[None, :], ys[:, None]), atol=1e-9)
    local = load_heightmap(tmp_path / "site.tif", origin=(0.0, 0.0))
    assert local.origin == (0.0, 0.0) and np.array_equal(local.z, hm.z)


@pytest.mark.parametrize("crs, words", [("EPSG:4326", r"geographic CRS \(degrees\)"), ("EPSG:2227", "not metres")])
def test_a_crs_not_in_metres_is_refused(tmp_path, crs, words):
    path = write_tif(tmp_path / "deg.tif", crs=crs)
    with pytest.raises(ScenarioError, match=words):
        load_heightmap(path)


def test_no_data_cells_are_counted_and_a_window_avoids_them(tmp_path):
    path = write_tif(tmp_path / "holes.tif", nodata_cells=[(0, 0), (0, 1), (1, 0)])  # the north-west corner
    with pytest.raises(ScenarioError, match="3 of 7200 cells in the area read are no-data"):
        load_heightmap(path)
    hm = load_heightmap(path, bounds=(WEST + 1.0, SOUTH, WEST + 12.0, SOUTH + 5.0))
    assert hm.origin == (WEST + 1.0, SOUTH) and hm.z.shape == (50, 110)
    np.testing.assert_allclose(hm.z[0, 0], surface(np.array(WEST + 1.05), np.array(SOUTH + 0.05)), atol=1e-9)


def test_resampling_to_another_resolution_must_be_named(tmp_path):
    path = write_tif(tmp_path / "coarse.tif", cell=0.2)
    with pytest.raises(ScenarioError, match=r"0.2 m cells and 0.1 m were asked for: say how to resample"):
        load_heightmap(path, resolution=0.1)
    with pytest.raises(ScenarioError, match="unknown resampling 'spline'"):
        load_heightmap(path, resolution=0.1, resampling="spline")
    hm = load_heightmap(path, resolution=0.1, resampling="bilinear")
    assert hm.resolution == 0.1 and hm.z.shape == (60, 120)
    assert load_heightmap(path, resolution=0.4, resampling="average").z.shape == (15, 30)


def test_a_suite_file_and_plan_read_a_geotiff(tmp_path, capsys):
    write_tif(tmp_path / "site.tif")
    (tmp_path / "survey.toml").write_text('''
name = "survey"
track = "backhoe"
[budget]
wall_s = 60
cores = 2
memory_mb = 4096
[[family]]
name = "drone"
generator = "file"
targets = [0.56]
seeds = [0]
[family.params]
path = "site.tif"
''')
    (sc,) = load_suite(tmp_path / "survey.toml").scenarios
    assert sc.terrain.origin == (WEST, SOUTH) and sc.site.floor == pytest.approx(float(sc.terrain.z.min()))
    plan, scen = tmp_path / "p.json", tmp_path / "s.json"
    assert main(["plan", "greedy", "--terrain", "file", "--param", f"path={tmp_path / 'site.tif'}", "--target", "0.56",
                 "--save-scenario", str(scen), "-o", str(plan)]) == 0
    assert main(["validate", str(plan), "--scenario", str(scen)]) == 0
    from earthbench_planners.greedy.backhoe import GreedyPlanner

    verdict = judge(sc, GreedyPlanner().plan(sc))
    assert verdict.valid and verdict.loaded_volume >= 0.56 - 1e-6


def test_resampling_is_for_geotiff_only(tmp_path):
    np.save(tmp_path / "z.npy", np.zeros((4, 4)))
    with pytest.raises(ScenarioError, match="GeoTIFF files only"):
        heightmap_file(0, 0.1, path=str(tmp_path / "z.npy"), resolution=0.1, resampling="bilinear")


def test_without_rasterio_the_error_says_what_to_install(tmp_path, monkeypatch):
    path = write_tif(tmp_path / "site.tif")
    monkeypatch.setitem(sys.modules, "rasterio", None)
    with pytest.raises(ScenarioError, match=r"pip install 'earthbench\[geotiff\]'"):
        load_heightmap(path)
