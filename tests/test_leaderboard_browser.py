"""The leaderboard page in a real browser: headless Chromium driven over the DevTools protocol.

Checks: the page loads with no console error, no exception and no request other than the
file itself and its ``data:`` images; a click on a column heading sorts the table (and a
second click reverses it); a planner named ``<script>alert(1)</script>`` shows as text and
opens no dialog. Skipped, with the reason, when Chromium or websocket-client is missing
(``.ci/run`` installs Debian's ``chromium`` when it can).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path

import pytest

from earthbench.publish import publish
from leaderboard_fixtures import EVIL, fill_store, standard_behaviours, suite_of

websocket = pytest.importorskip("websocket", reason="websocket-client is not installed (pip install -e '.[test]')")

BROWSER = next((shutil.which(b) for b in ("chromium", "chromium-browser", "google-chrome") if shutil.which(b)), None)
pytestmark = pytest.mark.skipif(BROWSER is None, reason="no chromium on PATH (Debian: apt-get install -y chromium)")


class DevTools:
    """A minimal Chrome DevTools Protocol client on one page target."""

    def __init__(self, ws_url: str):
        self.ws = websocket.create_connection(ws_url, timeout=30, suppress_origin=True)
        self.next_id = 0
        self.events: list[dict] = []

    def call(self, method: str, **params):
        self.next_id += 1
        mid = self.next_id
        self.ws.send(json.dumps({"id": mid, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") == mid:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})
            self.events.append(msg)

    def wait_for(self, method: str, timeout: float = 30.0) -> dict:
        end = time.monotonic() + timeout
        for ev in self.events:
            if ev.get("method") == method:
                return ev
        while time.monotonic() < end:
            self.ws.settimeout(max(0.1, end - time.monotonic()))
            msg = json.loads(self.ws.recv())
            self.events.append(msg)
            if msg.get("method") == method:
                return msg
        raise TimeoutError(method)

    def drain(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.ws.settimeout(max(0.05, end - time.monotonic()))
            try:
                self.events.append(json.loads(self.ws.recv()))
            except websocket.WebSocketTimeoutException:
                break
        self.ws.settimeout(30)

    def js(self, expr: str):
        res = self.call("Runtime.evaluate", expression=expr, returnByValue=True, awaitPromise=True)
        if "exceptionDetails" in res:
            raise RuntimeError(f"{expr}: {res['exceptionDetails']}")
        return res["result"].get("value")

    def click(self, x: float, y: float) -> None:
        for kind in ("mouseMoved", "mousePressed", "mouseReleased"):
            self.call("Input.dispatchMouseEvent", type=kind, x=x, y=y, button="left", clickCount=1)

    def close(self) -> None:
        self.ws.close()


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    root = tmp_path_factory.mktemp("browser")
    db = fill_store(root / "runs.db", suite_of(2), standard_behaviours())
    publish(db, root / "lb", terrain=False)
    profile = tempfile.mkdtemp(prefix="earthbench-chromium-")
    proc = subprocess.Popen(
        [BROWSER, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run", "--no-default-browser-check",
         "--disable-extensions", "--disable-dev-shm-usage", f"--user-data-dir={profile}",
         "--remote-debugging-port=0", "--remote-allow-origins=*", "about:blank"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
    )
    try:
        port_file = Path(profile) / "DevToolsActivePort"
        end = time.monotonic() + 60
        while not (port_file.exists() and port_file.read_text().strip()):
            if proc.poll() is not None or time.monotonic() > end:
                pytest.skip(f"chromium did not start a DevTools endpoint (exit status {proc.poll()})")
            time.sleep(0.1)
        port = int(port_file.read_text().split()[0])
        targets = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10))
        ws_url = next(t["webSocketDebuggerUrl"] for t in targets if t.get("type") == "page")
        dt = DevTools(ws_url)
        for domain in ("Page", "Runtime", "Log", "Network"):
            dt.call(f"{domain}.enable")
        dt.events.clear()
        dt.call("Page.navigate", url=(root / "lb" / "index.html").as_uri())
        dt.wait_for("Page.loadEventFired")
        dt.drain(0.5)
        yield dt
        dt.close()
    finally:
        try:
            os.killpg(proc.pid, 15)
        except ProcessLookupError:
            pass
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, 9)
            proc.wait()
        shutil.rmtree(profile, ignore_errors=True)


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
    _click_heading(page, "Rank")
    ranks = [int(v.rstrip("=")) for v in _column(page, 0)]  # shared ranks read "1="
    assert ranks == sorted(ranks) and ranks[0] == 1


def test_script_name_shows_as_text(page):
    assert EVIL in _column(page, 1)
    assert page.js("document.scripts.length") == 1
    assert page.js("document.querySelectorAll('td script, th script, caption script').length") == 0
    assert not [e for e in page.events if e.get("method") == "Page.javascriptDialogOpening"]
