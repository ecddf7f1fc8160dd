"""What sealing adds to ``earthbench verify`` beyond re-judging (goal, issue 34: ≤ 10 ms per run).

:func:`earthbench.publishing.verify.check_seal` is that cost: the commitment recomputed from the revealed
key (every sealed scenario regenerated with the public generators), the store's draw compared
with it, and the draw's runs gathered for re-judging (which :func:`earthbench.publishing.verify.audit` then
does, as for any store; ``test_bench_merge.py`` times that part).

Two measurements, each reported per run in ``extra_info``:

* a generated sealed store (greedy and a second planner on a sealed draw of 2 × 12 rbf
  scenarios), or the store in ``EARTHBENCH_BENCH_SEALED_STORE`` with its key in
  ``EARTHBENCH_BENCH_SEALED_KEY``;
* the sealed draw of ``standard`` regenerated from a key (its 110 scenarios, the dominant cost),
  divided by the 440 runs a board of four planners stores for it. The public suite is
  generated beforehand, untimed: its digest is what :mod:`earthbench.results.identity` checks in every
  store that lists ``standard``, sealed or not, and ``verify`` generates it once for both.

Run with ``pytest tests/bench/test_bench_seal.py --benchmark-only``.
"""

from __future__ import annotations

import os
import sqlite3
import statistics
import sys
import time
from contextlib import closing
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from helpers.leaderboard import Behaviour, fill_store, ref, suite_of

from earthbench.seal import SealKey
from earthbench.results.store import Store
from earthbench.results.suite import load_suite, new_key, open_sealed
from earthbench.publishing.verify import check_seal

#: Runs a board of every built-in backhoe planner stores for one sealed draw of ``standard``.
STANDARD_RUNS = 440


@pytest.fixture(scope="module")
def sealed_store(tmp_path_factory) -> tuple[Path, SealKey]:
    store, key = os.environ.get("EARTHBENCH_BENCH_SEALED_STORE"), os.environ.get("EARTHBENCH_BENCH_SEALED_KEY")
    if store and key:
        return Path(store), SealKey.read(key)
    key_, sealed = new_key(suite_of(12))
    db = fill_store(tmp_path_factory.mktemp("bench") / "sealed.db", sealed,
                    [Behaviour(ref("greedy")), Behaviour(ref("half"), keep=0.5)])
    return db, key_


def test_check_a_sealed_store_beyond_rejudging(benchmark, sealed_store, monkeypatch):
    db, key = sealed_store
    if not key.path:  # a generated suite: let the check find it as `earthbench seal` would have recorded it
        suite = suite_of(12)
        monkeypatch.setattr("earthbench.results.suite.public_suite", lambda k: suite)

    cpu: list[float] = []

    def run():
        c0 = time.process_time()
        with Store(db, read_only=True) as st:
            out = check_seal(st, key)
        cpu.append(time.process_time() - c0)
        return out

    result = benchmark.pedantic(run, rounds=3, iterations=1)
    with closing(sqlite3.connect(f"file:{db}?mode=ro", uri=True)) as con:
        n = con.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
    assert result.problems == [] and len(result.run_rows) == n
    # CPU time too: on a shared machine the wall time mostly measures the other jobs
    benchmark.extra_info.update(runs=n, ms_per_run=round(1000 * benchmark.stats.stats.median / n, 2),
                                cpu_ms_per_run=round(1000 * statistics.median(cpu) / n, 2))


def test_regenerate_the_sealed_draw_of_standard(benchmark):
    public = load_suite("standard")
    key, _ = new_key(public)
    cpu: list[float] = []

    def run():
        c0 = time.process_time()
        out = open_sealed(public, key)
        cpu.append(time.process_time() - c0)
        return out

    suite = benchmark.pedantic(run, rounds=3, iterations=1)
    assert len(suite.scenarios) == len(public.scenarios)
    benchmark.extra_info.update(scenarios=len(suite.scenarios), runs=STANDARD_RUNS,
                                ms_per_run=round(1000 * benchmark.stats.stats.median / STANDARD_RUNS, 2),
                                cpu_ms_per_run=round(1000 * statistics.median(cpu) / STANDARD_RUNS, 2))
