"""What makes the STL-TAMP local solve fast: CasADi/IPOPT variants side by side on one problem.

The problem is ``test_bench_stl_tamp``'s local solve (seed 0: m = 4 phases, n = 8 steps,
1 m³ in the richest area of a 30-basis map), solved from the IK initial guess by

- ``sx-exact``: what the planner uses — SX graphs, exact Hessian;
- ``mx``: the same model built from MX (matrix) symbols, no expansion;
- ``mx-expand``: MX expanded to SX by ``nlpsol(..., {"expand": True})``;
- ``sx-lbfgs``: SX with IPOPT's limited-memory Hessian approximation;
- ``sx-warm``: SX, exact Hessian, started from the solution of a neighbouring problem (the same
  area with 0.9 m³), as a re-solve or a continued solve is;
- ``sx-jit``: SX compiled to C by CasADi's JIT (gcc -O1); the compile takes minutes, so this one
  runs only with ``EARTHBENCH_BENCH_JIT=1``.

Each variant gets the planner's caps (150 iterations, 4 s of CPU); ``extra_info`` keeps the
status, iterations and the time to build the model and the solver. Reported, never asserted:

    pytest tests/bench/test_bench_casadi_variants.py --benchmark-only
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_bench_stl_tamp import _local_case

from earthbench_planners.stl_tamp.model import NX, PhaseNLP

VARIANTS = ["sx-exact", "mx", "mx-expand", "sx-lbfgs", "sx-warm", "sx-jit"]


@pytest.fixture(scope="module")
def case():
    return _local_case(0, 1.0)


@pytest.mark.parametrize("variant", VARIANTS)
def test_local_solve_variant(benchmark, case, variant, tmp_path, monkeypatch):
    if variant == "sx-jit" and os.environ.get("EARTHBENCH_BENCH_JIT") != "1":
        pytest.skip("the JIT compile takes minutes; set EARTHBENCH_BENCH_JIT=1 to include it")
    pl, nlp, p, w0, box = case
    c = pl.config
    options, casadi_options = pl._ipopt_options(), {}
    t0 = time.perf_counter()
    if variant.startswith("mx"):
        nlp = PhaseNLP(dataclasses.replace(nlp.shape, symbolic="MX"), nlp.exc, nlp.truck, nlp.site_box)
        if variant == "mx-expand":
            casadi_options = {"expand": True}
    elif variant == "sx-lbfgs":
        options = dict(options, hessian_approximation="limited-memory")
    elif variant == "sx-jit":
        monkeypatch.chdir(tmp_path)  # the generated C and the shared object
        casadi_options = {"jit": True, "compiler": "shell", "jit_options": {"flags": ["-O1"]}}
    elif variant == "sx-warm":
        near = p.copy()
        near[nlp.K + 2 + NX] = 0.9  # the target volume parameter
        w0 = nlp.solve(near, w0, box, max_iter=c.max_iter, accept_feasible=c.accept_feasible, options=options).info["w"]
    nlp.solver(c.max_iter, options, casadi_options)
    setup_s = time.perf_counter() - t0

    def solve():
        return nlp.solve(p, w0, box, max_iter=c.max_iter, accept_feasible=c.accept_feasible, options=options, casadi_options=casadi_options)

    sol = benchmark.pedantic(solve, rounds=3, iterations=1)
    benchmark.extra_info.update(status=sol.status, iterations=sol.iterations, setup_s=round(setup_s, 2))
    assert sol.X.shape[0] == nlp.N + 1
