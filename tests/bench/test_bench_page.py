"""Size and opening time of the leaderboard page with 2,000 runs and 20 replays (goal, issue 21: < 5 MB, ≤ 2 s).

The store is the one of ``test_bench_leaderboard.py`` (400 small rbf scenarios × 5 planner
configurations). One round opens ``index.html`` in a fresh tab of headless Chromium and waits
for the load event and for the first replay to be decoded and drawn. Run with
``pytest tests/bench/test_bench_page.py --benchmark-only``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from chromium import chromium_page, needs_browser
from helpers.leaderboard import Behaviour, fill_store, ref, standard_behaviours, suite_of

from earthbench.publishing.publish import publish

pytestmark = needs_browser


@pytest.fixture(scope="module")
def store_2000(tmp_path_factory) -> Path:
    behaviours = standard_behaviours() + [Behaviour(ref("jumpy"), teleport=4.0)]
    return fill_store(tmp_path_factory.mktemp("page") / "runs.db", suite_of(200), behaviours)


@pytest.fixture(scope="module")
def page_2000(store_2000) -> Path:
    publish(store_2000, store_2000.parent / "lb", terrain=False, replays=20)
    return store_2000.parent / "lb" / "index.html"


@pytest.mark.parametrize("replays", [0, 20])
def test_publish_page_with_replays(benchmark, store_2000, tmp_path, replays):
    """What the replays add to writing the tables, CSVs and page (no figures), side by side with none."""
    benchmark.pedantic(publish, args=(store_2000, tmp_path / "lb"), kwargs={"figures": False, "replays": replays},
                       rounds=3, iterations=1)


def test_page_2000_runs_20_replays(benchmark, page_2000):
    size_mb = page_2000.stat().st_size / 1e6
    assert size_mb < 5.0
    with chromium_page() as dt:
        dt.window(1400, 1000)

        def open_page() -> float:
            dt.open("about:blank")
            dt.drain(0.2)
            t0 = time.perf_counter()
            dt.open(page_2000.as_uri())
            assert dt.js("window.earthbenchReplayReady.then(() => earthbenchReplay.state() !== null)") is True
            return time.perf_counter() - t0

        benchmark.pedantic(open_page, rounds=5, iterations=1, warmup_rounds=1)
        assert dt.js("JSON.parse(document.getElementById('rp-data').textContent).length") == 20
        assert dt.js("document.querySelectorAll('table.runs tbody tr').length") == 2000
    benchmark.extra_info["page_mb"] = round(size_mb, 2)
