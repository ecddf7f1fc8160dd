"""stl-tamp's preparation and what it buys a case (docs/DESIGN.md §6 "Preparation").

- ``test_prepare``: the whole preparation of stl-tamp's default configuration as ``earthbench
  prepare`` runs it (a fenced job on 2 cores, a fresh folder): ``extra_info`` has the harness's
  wall and CPU seconds, the peak memory and each NLP's compile seconds. One round: several
  minutes of compiler time.
- ``test_load``: what a case pays for the two NLPs of ``paper-extensive`` at 7 m³ (the local
  one and the 8-phase global one) before IPOPT starts, IPOPT's solver included: loaded from the
  disk cache (CasADi's serialization) against loaded compiled from the preparation.

Reported, never asserted: ``pytest tests/bench/test_bench_prepare.py --benchmark-only``.
"""

from __future__ import annotations

import pytest

from earthbench.results.records import PlannerRef
from earthbench.running.harness.prepare import find, forget, run
from earthbench.world import Budget
from earthbench_planners.stl_tamp import model
from earthbench_planners.stl_tamp.hierarchy import site_box

from test_bench_nlp_build import _shapes


def test_prepare(benchmark, tmp_path, monkeypatch):
    monkeypatch.setenv("EARTHBENCH_PREPARED", str(tmp_path / "prepared"))
    monkeypatch.setenv("EARTHBENCH_NLP_CACHE", str(tmp_path / "nlp"))
    ref = PlannerRef.resolve("stl-tamp")
    done = benchmark.pedantic(lambda: run(ref, Budget()), rounds=1, iterations=1)
    benchmark.extra_info.update(wall_s=done.wall_s, cpu_s=done.cpu_s, peak_rss_mb=done.peak_rss_mb,
                                nlps={k: sum(v["compile_s"].values()) for k, v in done.summary["nlps"].items()})
    forget(ref)


@pytest.mark.parametrize("how", ["cache", "compiled"])
def test_load(benchmark, how):
    ref = PlannerRef.resolve("stl-tamp")
    prepared = find(ref)
    if how == "compiled" and prepared is None:
        pytest.skip("stl-tamp is not prepared on this machine: run `earthbench prepare stl-tamp` first")
    sc, pl, shapes = _shapes()
    model.use_prepared(prepared.path if how == "compiled" else None)

    def load():
        out = []
        for which, shape in shapes.items():
            nlp = model.PhaseNLP(shape, sc.machines.excavator, sc.machines.truck, site_box(sc))
            nlp.solver(pl.config.max_iter if which == "local" else pl.config.global_max_iter, pl._ipopt_options(which == "local"))
            out.append(nlp.cache)
        return out

    try:
        load()  # the disk cache warm (a fresh machine's first case builds the NLPs: test_bench_nlp_build)
        states = benchmark.pedantic(load, rounds=3, iterations=1)
    finally:
        model.use_prepared(None)
    assert states == (["compiled"] * 2 if how == "compiled" else ["hit"] * 2)

