"""earthbench_planners.stl_tamp.surface: the Gaussian RBF fit (cvxpy) and its numpy/CasADi evaluation."""

import casadi as ca
import numpy as np
import pytest

from earthbench.errors import ScenarioError
from earthbench.world import Heightmap
from earthbench_terrains.rbf import rbf_surface
from earthbench_planners.stl_tamp.surface import fit_rbf


@pytest.fixture(scope="module")
def paper_map():
    return rbf_surface(3, n_bases=30)  # 12 m × 6 m at 0.05 m, the paper's extensive maps


@pytest.fixture(scope="module")
def fitted(paper_map):
    return fit_rbf(paper_map)


def test_fit_meets_the_rms_goal_on_paper_maps(paper_map, fitted):
    assert fitted.rms < 0.02
    direct = fitted.grid(paper_map) - paper_map.z
    assert np.sqrt(np.mean(direct**2)) == pytest.approx(fitted.rms, rel=1e-9)
    assert fitted.info["status"] in ("optimal", "optimal_inaccurate")


def test_cvxpy_solves_the_same_least_squares_as_the_normal_equations(paper_map, fitted):
    direct = fit_rbf(paper_map, solver="cholesky")
    assert np.max(np.abs(fitted.grid(paper_map) - direct.grid(paper_map))) < 1e-3
    assert fitted.rms == pytest.approx(direct.rms, abs=1e-4)


def test_gradient_matches_finite_differences(fitted):
    rng = np.random.default_rng(0)
    x, y = rng.uniform(0.5, 11.5, 20), rng.uniform(0.5, 5.5, 20)
    gx, gy = fitted.gradient(x, y)
    h = 1e-6
    assert np.allclose(gx, (fitted(x + h, y) - fitted(x - h, y)) / (2 * h), atol=1e-6)
    assert np.allclose(gy, (fitted(x, y + h) - fitted(x, y - h)) / (2 * h), atol=1e-6)


@pytest.mark.parametrize("kind", ["SX", "MX"])
def test_casadi_expression_equals_numpy(fitted, kind):
    f = fitted.casadi_function(kind)
    for x, y in ((1.0, 1.0), (6.2, 3.3), (11.0, 5.0)):
        val, grad = f(x, y)
        assert float(val) == pytest.approx(float(fitted(x, y)), abs=1e-10)
        gx, gy = fitted.gradient(x, y)
        assert np.allclose(np.array(grad).ravel(), [gx, gy], atol=1e-9)


def test_symbolic_weights_and_origin(fitted):
    """The parametric form a planner puts in its NLP: weights and lattice origin as parameters."""
    x, y = ca.SX.sym("x"), ca.SX.sym("y")
    w, o = ca.SX.sym("w", fitted.n_bases), ca.SX.sym("o", 2)
    f = ca.Function("f", [x, y, w, o], [fitted.casadi(x, y, weights=w, origin=o)])
    val = f(4.4, 2.2, fitted.weights.reshape(-1), [fitted.x0, fitted.y0])
    assert float(val) == pytest.approx(float(fitted(4.4, 2.2)), abs=1e-10)


def test_window_and_fixed_lattice_shape(paper_map):
    s = fit_rbf(paper_map, spacing=0.55, window=(3.0, 8.5, 0.5, 5.5), shape=(11, 11), margin=0)
    assert s.shape == (11, 11)
    xs, ys = paper_map.cell_centres()
    ix = (xs >= 3.0) & (xs <= 8.5)
    iy = (ys >= 0.5) & (ys <= 5.5)
    err = s.grid(paper_map)[np.ix_(iy, ix)] - paper_map.z[np.ix_(iy, ix)]
    assert np.sqrt(np.mean(err**2)) == pytest.approx(s.rms, rel=1e-9)
    assert s.rms < 0.02


def test_bad_arguments_are_clear_errors(paper_map):
    with pytest.raises(ScenarioError):
        fit_rbf(paper_map, spacing=0.0)
    with pytest.raises(ScenarioError):
        fit_rbf(paper_map, window=(20.0, 30.0, 0.0, 1.0))
    with pytest.raises(ScenarioError):
        fit_rbf(paper_map, solver="magic")


def test_flat_map_fits_exactly_enough():
    hm = Heightmap((0.0, 0.0), 0.1, np.full((20, 30), 0.5))
    assert fit_rbf(hm, spacing=0.4).rms < 0.01


@pytest.mark.parametrize("seed", [0, 1])
def test_dem_crops_fit_within_5_cm(seed):
    dem = pytest.importorskip("earthbench_terrains.dem")
    hm, _ = dem.dem_crop(seed)
    assert fit_rbf(hm).rms < 0.05
