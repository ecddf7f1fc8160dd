"""Speed of the STL-TAMP pieces: one local solve (the planner's shape: m = 4 phases, n = 8 steps) and the surface fit.

Run with ``pytest tests/bench/test_bench_stl_tamp.py --benchmark-only``; reported, not asserted.
The local NLP is built once (as in a run) and each round solves it from the IK initial guess.
"""

from __future__ import annotations

import pytest

from earthbench_planners.stl_tamp.guess import build_guess, fill_volumes
from earthbench_planners.stl_tamp.hierarchy import local_seeds
from earthbench_planners.stl_tamp.surface import fit_rbf
from earthbench_terrains.rbf import rbf, rbf_surface
from helpers.stl_tamp import richest_local_area


def _local_case(seed: int, target: float):
    sc, pl, nlp, st, area, surf = richest_local_area(rbf(seed, 4.0, n_bases=30), solver="cholesky")
    c = pl.config
    cx, cy = area.centre
    k = int(-(-target // (0.28 * c.fill_estimate)))
    seeds = local_seeds(area, k, c.m_local, 0.7, 1.0, surf, c.eta_init, area.truck)
    p = nlp.pack_p(w=surf.weights.reshape(-1), o=(surf.x0, surf.y0), s0=st.s0, vt=target,
                   alpha=(c.alpha_u, c.alpha_t, c.alpha_v, c.alpha_eta, c.alpha_term), goal=area.base, floor=0.0)
    w0 = fill_volumes(nlp, build_guess(nlp, st.s0, seeds, 0.0), p)
    half = 1.45
    box = (cx - half, cx + half, cy - half, cy + half)
    return pl, nlp, p, w0, box


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_local_solve(benchmark, seed):
    pl, nlp, p, w0, box = _local_case(seed, 1.0)
    c = pl.config
    sol = benchmark.pedantic(
        lambda: nlp.solve(p, w0, box, max_iter=c.max_iter, accept_feasible=c.accept_feasible, options=pl._ipopt_options()),
        rounds=5,
        iterations=1,
    )
    benchmark.extra_info.update(status=sol.status, iterations=sol.iterations, variables=nlp.nw,
                                constraints=nlp.ng, build_s=nlp.build_time_s)


def test_surface_fit_paper_map(benchmark):
    hm = rbf_surface(0, n_bases=30)
    s = benchmark(lambda: fit_rbf(hm))
    benchmark.extra_info.update(rms_m=s.rms, bases=s.n_bases)
