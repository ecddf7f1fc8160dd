"""The leaderboard page in a real browser: headless Chromium driven over the DevTools protocol.

Checks: the page loads with no console error, no exception and no request other than the
file itself and its ``data:`` images; a click on a column heading sorts the table (and a
second click reverses it); a planner named ``<script>alert(1)</script>`` shows as text and
opens no dialog; the filters hide rows; the tables fit a 1400 px window. Skipped, with the
reason, when Chromium or websocket-client is missing (``.ci/run`` installs Debian's
``chromium`` when it can).
"""

from __future__ import annotations

import json

import pytest

from chromium import chromium_page, needs_browser
from earthbench.publishing.publish import publish
from helpers.leaderboard import EVIL, fill_store, standard_behaviours, suite_of

pytestmark = needs_browser


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    root = tmp_path_factory.mktemp("browser")
    db = fill_store(root / "runs.db", suite_of(2), standard_behaviours())
    publish(db, root / "lb", terrain=False)
    with chromium_page() as dt:
        dt.window(1400, 1000)
        dt.open((root / "lb" / "index.html").as_uri())
        dt.drain(0.5)
        yield dt


def test_loads_without_errors_or_network(page):
    errors = [e for e in page.events if e.get("method") == "Runtime.exceptionThrown"
              or (e.get("method") == "Runtime.consoleAPICalled" and e["params"]["type"] in ("error", "assert"))
              or (e.get("method") == "Log.entryAdded" and e["params"]["entry"]["level"] == "error")]
    assert errors == []
    urls = [e["params"]["request"]["url"] for e in page.events if e.get("method") == "Network.requestWillBeSent"]
    assert urls, "the page load itself should be seen"
    assert [u for u in urls if not (u.startswith("file:") or u.startswith("data:"))] == []
    assert page.js("document.title") == "earthbench leaderboard"
    # every figure decoded
    assert page.js("Array.from(document.images).every(i => i.complete && i.naturalWidth > 0)") is True
    assert page.js("document.images.length") == 2


def _column(page, col: int) -> list[str]:
    return page.js(f"Array.from(document.querySelector('table.sortable').tBodies[0].rows).map(r => r.cells[{col}].textContent)")


def _click_heading(page, text: str) -> None:
    box = page.js(
        "(() => { const th = Array.from(document.querySelector('table.sortable').tHead.rows[0].cells)"
        f".find(c => c.textContent === {json.dumps(text)}); th.scrollIntoView(); const r = th.getBoundingClientRect();"
        " return [r.left + r.width / 2, r.top + r.height / 2]; })()")
    page.click(*box)


def test_tables_sort_on_click(page):
    before = _column(page, 1)
    assert before[0] == "greedy"  # ranked order
    _click_heading(page, "Planner")
    asc = _column(page, 1)
    assert asc == sorted(before, key=str.lower) and asc != before
    _click_heading(page, "Planner")
    assert _column(page, 1) == sorted(before, key=str.lower, reverse=True)
    _click_heading(page, "Success")
    success = [float(v.split("%")[0]) for v in _column(page, 5)]  # "50% [12%–88%]": the rate, then its interval
    assert success == sorted(success)
    _click_heading(page, "Rank ‡")  # 4 scenarios: too few to separate two planners
    ranks = [int(v.rstrip("=")) for v in _column(page, 0)]  # shared ranks read "1="
    assert ranks == sorted(ranks) and ranks[0] == 1


def test_script_name_shows_as_text(page):
    assert EVIL in _column(page, 1)
    assert page.js("document.querySelectorAll('script:not([type=\"application/json\"])').length") == 1
    assert page.js("document.querySelectorAll('td script, th script, caption script').length") == 0
    assert not [e for e in page.events if e.get("method") == "Page.javascriptDialogOpening"]


def test_tables_fit_a_1400px_window_and_link_their_csvs(page):
    assert page.js("(() => { const w = document.querySelector('table.sortable').closest('.wrap');"
                   " return w.scrollWidth <= w.clientWidth; })()") is True
    assert page.js("Array.from(document.links).map(a => a.getAttribute('href')).filter(h => h.endsWith('.csv'))") == [
        "summary.csv", "runs.csv"]


def test_the_ranking_leads_the_page_and_links_to_replays(page):
    """At 1400 × 900 the ranked table starts above the fold; the stamp is folded; all-zero failure columns are one.

    (Before the filter test, which opens every details element.)"""
    page.window(1400, 900)
    page.js("window.scrollTo(0, 0)")
    top = page.js("document.querySelector('table.sortable').getBoundingClientRect().top")
    assert 0 < top < 900 - 100
    assert page.js("document.querySelector('.stamp').closest('details').open") is False
    heads = page.js("Array.from(document.querySelector('table.sortable').tHead.rows[0].cells).map(c => c.textContent)")
    folded = [h for h in heads if " · " in h]
    assert folded == ["invalid · memory · error · crashed"] and "timeout" in heads  # the fixture's failures are timeouts
    # a link under the table opens that run in the viewer, far down the page
    link = page.js("(() => { const a = document.querySelector('a.rp-link[href]'); a.click(); return a.getAttribute('data-run'); })()")
    page.js("window.earthbenchReplayReady")
    page.drain(0.5)
    assert str(page.js("window.earthbenchReplay.state().run")) == link
    assert page.js("location.hash") == "#replay"


def test_filters_hide_rows(page):
    visible = "Array.from(document.querySelectorAll('table.sortable tbody tr')).filter(r => r.offsetParent !== null).length"
    total = page.js("document.querySelectorAll('table.sortable tbody tr').length")
    page.js("document.querySelectorAll('details').forEach(d => d.open = true)")
    assert page.js(visible) == total
    page.js("(() => { const s = document.querySelector('.filters select[data-key=planner]'); s.value = 'greedy';"
            " s.dispatchEvent(new Event('change')); })()")
    shown = page.js("Array.from(document.querySelectorAll('table.sortable tbody tr')).filter(r => r.offsetParent !== null)"
                    ".map(r => r.getAttribute('data-planner'))")
    assert shown and set(shown) == {"greedy"} and len(shown) < total
    page.js("(() => { const s = document.querySelector('.filters select[data-key=planner]'); s.value = '';"
            " s.dispatchEvent(new Event('change')); })()")
    assert page.js(visible) == total
