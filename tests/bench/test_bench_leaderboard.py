"""Speed of ``earthbench leaderboard`` on a store of 2,000 runs (goal: ≤ 3 s on 2 cores with the intervals).

The store: 400 small rbf scenarios × 5 planner configurations, greedy plans (some cut short,
some replaced by timeouts) judged by the referee and written with ``Store.record`` — about
half a minute to build, once per session. Each round writes every file: Markdown, both CSVs,
the HTML page and 9 figures (PNG and SVG), 5 of them terrain before/after re-judged from
stored plans, and every table gets its 95 % intervals (exact for rates, order statistics for
medians) and paired rank tests. The variant ``without_intervals`` makes the same files with
:func:`earthbench.stats.median_ci` and :func:`earthbench.stats.rate_ci` stubbed out, side by side,
to show what the intervals cost. Run with
``pytest tests/bench/test_bench_leaderboard.py --benchmark-only``.
"""

from __future__ import annotations

import resource
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from helpers.leaderboard import Behaviour, fill_store, ref, standard_behaviours, suite_of

from earthbench.publishing.publish import publish


@pytest.fixture(scope="module")
def store_2000(tmp_path_factory) -> Path:
    behaviours = standard_behaviours() + [Behaviour(ref("greedy", "1.0", {"min_fill": 0.5}), keep=0.9, cpu_model="Other CPU 9000")]
    return fill_store(tmp_path_factory.mktemp("bench") / "runs.db", suite_of(200), behaviours)


@pytest.mark.parametrize("variant", ["with_intervals", "without_intervals"])
def test_leaderboard_2000_runs(benchmark, store_2000, tmp_path, monkeypatch, variant):
    if variant == "without_intervals":
        import earthbench.results.aggregate

        monkeypatch.setattr(earthbench.results.aggregate, "median_ci", lambda values: (float("nan"),) * 2)
        monkeypatch.setattr(earthbench.results.aggregate, "rate_ci", lambda k, n: (float("nan"),) * 2)

    def cpu() -> float:
        return sum(resource.getrusage(who).ru_utime + resource.getrusage(who).ru_stime
                   for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))

    c0 = cpu()
    res = benchmark.pedantic(publish, args=(store_2000, tmp_path / "lb"), rounds=3, iterations=1)
    benchmark.extra_info["cpu_s_per_round"] = round((cpu() - c0) / 3, 2)  # this process and its figure workers
    assert len(res.runs) == 2000
    assert len(list((tmp_path / "lb" / "figures").iterdir())) == 2 * (2 + 5)
    benchmark.extra_info["runs"] = len(res.runs)
    benchmark.extra_info["files"] = len(res.files)
