"""stl-tamp's NLPs compiled in its preparation (``earthbench_planners.stl_tamp.compiled``): a small
shape compiled here evaluates to the bit as CasADi's virtual machine does, and IPOPT takes the
same iterates on it. The real shapes are compiled by ``earthbench prepare stl-tamp`` and
tests/bench/ (a minute of compiler time and more each)."""

from __future__ import annotations

import numpy as np
import pytest

from earthbench.world import ExcavatorSpec, TruckSpec
from earthbench_planners.stl_tamp import StlTampPlanner, compiled, model, nlp_cache
from earthbench_planners.stl_tamp.problem import Shape

needs_cc = pytest.mark.skipif(compiled.compiler() is None, reason="no C compiler")

SHAPE = Shape(phases=1, steps=3, contact_step=1, unit_width=0.7, unit_length=1.0, unit_depth=0.4, vmax=0.28,
              work_time=5.0, terrain_shape=(3, 4), terrain_spacing=0.6, terrain_sigma=0.6)
BOX = (0.0, 6.0, 0.0, 3.0)


class Small(StlTampPlanner):
    """stl-tamp whose preparation compiles one small shape (what the test can afford)."""

    def prepared_shapes(self):
        return [("small", SHAPE, ExcavatorSpec(), TruckSpec())]


@pytest.fixture(scope="module")
def prepared(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("compiled")
    mp = pytest.MonkeyPatch()
    mp.setenv(nlp_cache.ENV, str(tmp / "nlp"))
    # split every function of more than 300 instructions into pieces of 50 statements, 4 to a
    # file, as the real shapes' large functions are
    mp.setattr(compiled, "SPLIT_ABOVE", 300)
    mp.setattr(compiled, "PART_STATEMENTS", 50)
    mp.setattr(compiled, "PART_FILE_STATEMENTS", 200)
    folder = tmp / "prepared"
    summary = Small().prepare(folder, jobs=2)
    yield folder, summary
    model.use_prepared(None)
    mp.undo()


@needs_cc
def test_compiled_functions_evaluate_as_the_virtual_machine(prepared):
    folder, summary = prepared
    key = model.nlp_key(SHAPE, ExcavatorSpec(), TruckSpec())
    assert summary["nlps"]["small"]["key"] == key
    assert set(summary["nlps"]["small"]["compile_s"]) == set(compiled.NAMES)
    model.use_prepared(None)
    vm = model.PhaseNLP(SHAPE, ExcavatorSpec(), TruckSpec(), BOX)
    model.use_prepared(folder)
    cc = model.PhaseNLP(SHAPE, ExcavatorSpec(), TruckSpec(), BOX)
    assert (vm.cache, cc.cache) == ("hit", "compiled")  # the preparation filled the NLP cache too
    sv, sc = vm.solver(50), cc.solver(50)
    assert sorted(sc.get_function()) == sorted(compiled.SOLVER_NAMES[1:])
    assert all(sc.get_function(k).class_name() == "External" for k in sc.get_function())
    rng = np.random.default_rng(0)
    for _ in range(3):
        w, p = rng.normal(size=vm.nw), rng.normal(size=sum(n for _, n in vm.p_parts))
        lam = rng.normal(size=vm.ng)
        for name in compiled.SOLVER_NAMES[1:]:
            f, g = sv.get_function(name), sc.get_function(name)
            args = [w, p, 1.0, lam][:f.n_in()]
            for a, b in zip(f.call(args), g.call(args)):
                assert np.array_equal(np.array(a), np.array(b))
        ev, ec = vm.evaluate(w, p), cc.evaluate(w, p)
        assert all(np.array_equal(ev[k], ec[k]) for k in ev)
    assert np.array_equal(vm.lbg, cc.lbg) and np.array_equal(vm.ubg, cc.ubg)


@needs_cc
def test_ipopt_takes_the_same_iterates_on_compiled_functions(prepared):
    folder, _ = prepared
    sols = []
    for where in (None, folder):
        model.use_prepared(where)
        nlp = model.PhaseNLP(SHAPE, ExcavatorSpec(), TruckSpec(), BOX)
        p = nlp.pack_p(w=np.full(nlp.K, 0.3), o=(0.0, 0.0), s0=np.array([3.0, 1.5, 0, 0, 0.3, -1.5, 6.0, 1.5, 0]), vt=0.3,
                       alpha=(0.01, 1.0, 2e4, 2.0, 0.2), goal=(3.0, 1.5), floor=0.0)
        w0 = np.zeros(nlp.nw)
        sols.append(nlp.solve(p, w0, BOX, max_iter=40))
    a, b = sols
    assert a.status == b.status and a.iterations == b.iterations
    assert np.array_equal(a.info["w"], b.info["w"])


@needs_cc
def test_an_nlp_without_its_compiled_library_is_loaded_as_before(prepared, tmp_path):
    import shutil

    folder = tmp_path / "partial"
    shutil.copytree(prepared[0], folder)
    key = model.nlp_key(SHAPE, ExcavatorSpec(), TruckSpec())
    compiled.library(folder, key).unlink()
    model.use_prepared(folder)
    assert model.PhaseNLP(SHAPE, ExcavatorSpec(), TruckSpec(), BOX).cache == "hit"  # the preparation filled the cache too
    assert compiled.load(folder, key) is None


@needs_cc
def test_the_nlps_prepared_for_the_benchmarks_truck_serve_a_truck_of_any_size(prepared):
    """No constraint reads the truck's capacity, so the ``scale`` ladder's larger trucks load the
    prepared NLP (they had solved uncompiled); anything else of the truck is still its own NLP."""
    folder, _ = prepared
    model.use_prepared(folder)
    assert model.PhaseNLP(SHAPE, ExcavatorSpec(), TruckSpec(capacity=320.0), BOX).cache == "compiled"
    other = model.PhaseNLP(SHAPE, ExcavatorSpec(), TruckSpec(loading_radius=1.5), BOX)
    assert other.cache != "compiled"
    assert np.isnan(other.truck.capacity)  # what the NLP's constraints could read: nothing


def test_without_a_compiler_the_preparation_compiles_nothing(tmp_path, monkeypatch):
    monkeypatch.setattr(compiled, "compiler", lambda: None)
    summary = Small().prepare(tmp_path / "none", jobs=1)
    assert summary["nlps"] == {} and "no C compiler" in summary["note"]


def test_split_keeps_every_statement_in_order_over_a_work_array():
    import casadi as ca

    x = ca.SX.sym("x", 3)
    e = x[0]
    for i in range(40):
        e = ca.sin(e * x[1] + x[2] * i)
    f = ca.Function("f", [x], [e, e * x[0]])
    cg = ca.CodeGenerator("f.c", {"with_header": False})
    cg.add(f)
    pieces = compiled.split(cg.dump(), "pre", statements=10, per_file=20)
    assert pieces is not None and len(pieces) >= 3
    main, parts = pieces[0], "".join(pieces[1:])
    calls = [ln.strip() for ln in main.splitlines() if ln.strip().startswith("pre_part")]
    assert calls == [f"pre_part{j}(arg, res, w);" for j in range(len(calls))]
    assert "a0" not in parts.replace("casadi_", "") and "w[0]" in parts
    assert compiled.split("int main(void) { return 0; }", "pre") is None  # not CasADi's form: compiled whole
