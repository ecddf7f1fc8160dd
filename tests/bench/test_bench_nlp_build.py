"""What a case process pays for the STL-TAMP NLPs before IPOPT starts, and one Hessian evaluation.

- ``test_build``: the local NLP (4 phases of 8 steps, 11 × 11 lattice) and the global one of
  ``paper-extensive`` at 7 m³ (8 phases, 9 × 15 lattice), each built from scratch (the disk
  cache off), built and stored (a miss), and loaded (a hit), IPOPT's solver included;
  ``extra_info`` has the SX instruction counts of the Hessian of the Lagrangian and of the
  constraint Jacobian, and the size of the cache file.
- ``test_hessian``: one evaluation of the local NLP's Hessian of the Lagrangian (IPOPT calls it
  once per iteration).

Reported, never asserted: ``pytest tests/bench/test_bench_nlp_build.py --benchmark-only``.
"""

from __future__ import annotations

import numpy as np
import pytest

from earthbench.results.suite import load_suite
from earthbench_planners.stl_tamp import StlTampPlanner, nlp_cache
from earthbench_planners.stl_tamp.hierarchy import global_lattice, site_box
from earthbench_planners.stl_tamp.model import PhaseNLP
from earthbench_planners.stl_tamp.problem import Shape


def _shapes():
    sc = next(s for s in load_suite("paper-extensive").scenarios if abs(s.task.target_volume - 7.0) < 1e-9)
    pl = StlTampPlanner()
    c, e = pl.config, sc.machines.excavator
    side = pl.area_side(sc)
    cap = e.bucket_capacity * c.fill_estimate
    glob = Shape(phases=8, steps=c.n_global, contact_step=c.n_global // 2, unit_width=side, unit_length=side,
                 unit_depth=c.dig_depth, vmax=c.area_vmax,
                 work_time=c.area_vmax / cap * (e.min_stroke_time + e.min_dump_time + 2.0),
                 terrain_shape=global_lattice(c.global_window, c.global_fit_spacing), terrain_spacing=1.0,
                 terrain_sigma=1.0, dtm_max=6.0, dtw_max=15.0, sigmoid_k=c.sigmoid_k, widen=c.quad_widen,
                 eps_eta=c.eps_eta, eps_v=c.eps_v, eps_d=c.eps_d, beta=c.beta)
    return sc, pl, {"local": pl.local_shape(sc), "global": glob}


@pytest.mark.parametrize("cache", ["off", "miss", "hit"])
@pytest.mark.parametrize("which", ["local", "global"])
def test_build(benchmark, which, cache, tmp_path, monkeypatch):
    sc, pl, shapes = _shapes()
    monkeypatch.setenv(nlp_cache.ENV, "off" if cache == "off" else str(tmp_path))
    args = (shapes[which], sc.machines.excavator, sc.machines.truck, site_box(sc))
    if cache == "hit":
        PhaseNLP(*args)

    def build():
        if cache == "miss":
            for f in tmp_path.glob("*.nlp"):
                f.unlink()
        nlp = PhaseNLP(*args)
        return nlp, nlp.solver(pl.config.max_iter, pl._ipopt_options())

    nlp, solver = benchmark.pedantic(build, rounds=2, iterations=1)
    assert nlp.cache == cache
    files = list(tmp_path.glob("*.nlp"))
    benchmark.extra_info.update(hess_instructions=solver.get_function("nlp_hess_l").n_instructions(),
                                jac_g_instructions=solver.get_function("nlp_jac_g").n_instructions(),
                                file_mb=round(files[0].stat().st_size / 1e6, 1) if files else None)


def test_hessian(benchmark, monkeypatch, tmp_path):
    sc, pl, shapes = _shapes()
    monkeypatch.setenv(nlp_cache.ENV, str(tmp_path))
    nlp = PhaseNLP(shapes["local"], sc.machines.excavator, sc.machines.truck, site_box(sc))
    hess = nlp.solver(pl.config.max_iter, pl._ipopt_options()).get_function("nlp_hess_l")
    rng = np.random.default_rng(0)
    args = [rng.normal(size=nlp.nw), rng.normal(size=sum(n for _, n in nlp.p_parts)), 1.0, rng.normal(size=nlp.ng)]
    benchmark(hess.call, args)
    benchmark.extra_info.update(instructions=hess.n_instructions(), nonzeros=hess.nnz_out(0))
