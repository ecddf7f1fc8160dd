"""The STL module: exact robustness by definition, smooth robustness against exact."""

import casadi as ca
import numpy as np
import pytest

from earthbench_planners.stl_tamp.stl import And, Const, Finally, Globally, Not, Or, Predicate, smooth_max, smooth_min


def _spec():
    above = Predicate.gt("x", 0.5)
    below = Predicate.lt("y", 1.0)
    return Or((And((Finally(above, 0, 4), Globally(below, 1, 6))), Globally(Not(above), 0, 2)))


def test_exact_robustness_matches_the_definition():
    x = np.array([0.0, 0.2, 0.9, 0.1, 0.3, 0.0, 0.0, 0.0])
    y = np.array([0.0, 0.5, 0.7, 0.2, 0.9, 0.4, 0.1, 3.0])
    sig = {"x": x, "y": y}
    rho = _spec().rho(sig)
    f = max(x[0:5] - 0.5)
    g = min(1.0 - y[1:7])
    h = min(0.5 - x[0:3])
    assert rho == pytest.approx(max(min(f, g), h))
    assert Finally(Predicate.gt("x", 0.5), 5, 10).rho(sig, 0) == pytest.approx(-0.5)  # window clipped at the end
    with pytest.raises(ValueError):
        Finally(Predicate.gt("x", 0.5), 9, 10).rho(sig, 0)
    assert (Const(2.0) & Predicate.gt("x", 0.0)).rho(sig, 2) == pytest.approx(0.9)


@pytest.mark.parametrize("seed", range(5))
def test_smooth_converges_to_exact(seed):
    rng = np.random.default_rng(seed)
    sig = {"x": rng.normal(size=12), "y": rng.normal(size=12)}
    spec = _spec()
    exact = spec.rho(sig)
    errs = [abs(spec.rho(sig, smooth=b) - exact) for b in (5.0, 50.0, 500.0, 5000.0)]
    assert errs[-1] < 2e-3
    assert errs[-1] <= errs[0]


def test_smooth_bounds_and_no_overflow():
    x = [1000.0, -1000.0, 3.0]
    assert 1000.0 <= smooth_max(x, 50.0) <= 1000.0 + np.log(3) / 50
    assert -1000.0 - np.log(3) / 50 <= smooth_min(x, 50.0) <= -1000.0
    # far-away values (a truck 1e3 m away) neither overflow nor underflow in CasADi either
    s = ca.SX.sym("s", 3)
    f = ca.Function("f", [s], [smooth_min([s[0], s[1], s[2]], 50.0)])
    assert float(f([1e3, 2e3, 5e2])) == pytest.approx(5e2, abs=1e-9)
    assert np.isfinite(float(f([-1e4, 1e4, 0.0])))


def test_sign_agrees_on_random_signals_away_from_zero():
    rng = np.random.default_rng(7)
    spec = _spec()
    beta = 200.0
    checked = 0
    for _ in range(400):
        sig = {"x": rng.normal(size=10), "y": rng.normal(0.5, 1.0, size=10)}
        exact = spec.rho(sig)
        if abs(exact) < 0.05:  # log(N)/β ≤ log(10)/200 ≈ 0.012 per level
            continue
        assert np.sign(spec.rho(sig, smooth=beta)) == np.sign(exact)
        checked += 1
    assert checked > 200


def test_casadi_expressions_match_numpy():
    xs = ca.SX.sym("x", 8)
    ys = ca.SX.sym("y", 8)
    spec = _spec()
    sym = {"x": [xs[i] for i in range(8)], "y": [ys[i] for i in range(8)]}
    smooth = ca.Function("r", [xs, ys], [spec.rho(sym, smooth=30.0)])
    exact = ca.Function("r", [xs, ys], [spec.rho(sym)])
    rng = np.random.default_rng(3)
    for _ in range(20):
        x, y = rng.normal(size=8), rng.normal(size=8)
        sig = {"x": x, "y": y}
        assert float(smooth(x, y)) == pytest.approx(spec.rho(sig, smooth=30.0), abs=1e-9)
        assert float(exact(x, y)) == pytest.approx(spec.rho(sig), abs=1e-12)
    # the smooth robustness is differentiable: its gradient exists and is finite everywhere
    g = ca.Function("g", [xs, ys], [ca.gradient(spec.rho(sym, smooth=30.0), ca.vertcat(xs, ys))])
    assert np.all(np.isfinite(np.array(g(np.zeros(8), np.zeros(8)))))


def test_robustness_constraints_decompose_top_level_min():
    from earthbench_planners.stl_tamp.stl import robustness_constraints

    rng = np.random.default_rng(11)
    spec = And((Globally(Predicate.lt("y", 1.0), 1, 6), Finally(Predicate.gt("x", 0.5), 0, 4)))
    for _ in range(50):
        sig = {"x": rng.normal(size=8), "y": rng.normal(size=8)}
        parts = robustness_constraints(spec, sig)
        assert len(parts) == 7
        assert min(parts) == pytest.approx(spec.rho(sig))


def test_robustness_constraints_keep_a_top_level_constant():
    """``G(x > 0) ∧ −1`` has robustness −1; its constraints must not allow the signal's 0.5."""
    from earthbench_planners.stl_tamp.stl import robustness_constraints

    spec = And((Globally(Predicate.gt("x", 0.0), 0, 2), Const(-1.0)))
    sig = {"x": np.array([0.5, 2.0, 3.0])}
    assert spec.rho(sig) == -1.0
    assert min(robustness_constraints(spec, sig)) == -1.0


def _formulas():
    from hypothesis import strategies as st

    windows = st.tuples(st.integers(0, 3), st.integers(0, 4)).map(lambda ab: (ab[0], ab[0] + ab[1]))
    leaves = st.one_of(
        st.builds(Predicate.gt, st.sampled_from(["x", "y"]), st.floats(-2, 2)),
        st.builds(Predicate.lt, st.sampled_from(["x", "y"]), st.floats(-2, 2)),
        st.builds(Const, st.floats(-3, 3)),
    )

    def extend(children):
        return st.one_of(
            st.lists(children, min_size=1, max_size=3).map(lambda xs: And(tuple(xs))),
            st.lists(children, min_size=1, max_size=3).map(lambda xs: Or(tuple(xs))),
            st.builds(Not, children),
            st.builds(lambda f, w: Globally(f, *w), children, windows),
            st.builds(lambda f, w: Finally(f, *w), children, windows),
        )

    return st.recursive(leaves, extend, max_leaves=8)


def test_robustness_constraints_min_is_the_exact_robustness():
    """For any formula (constants anywhere, nested ∧/G at the top), ``min_j r_j = ρ^φ`` exactly."""
    from hypothesis import given, settings
    from hypothesis import strategies as st
    from hypothesis.extra.numpy import arrays

    from earthbench_planners.stl_tamp.stl import robustness_constraints

    values = arrays(float, 40, elements=st.floats(-3, 3))

    @settings(max_examples=300, deadline=None)
    @given(_formulas(), values, values)
    def check(spec, x, y):
        sig = {"x": x, "y": y}
        assert min(float(r) for r in robustness_constraints(spec, sig)) == spec.rho(sig)

    check()
