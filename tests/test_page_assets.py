"""The page's style sheets and scripts are package files (earthbench/assets), inlined as they are, and the
page's content-security-policy allows exactly its one inline script, by the hash of what it holds."""

from __future__ import annotations

import base64
import hashlib
import html
import re
import shutil
import subprocess

import pytest

from earthbench import assets
from earthbench.publishing.board.page import html_page
from earthbench.running.playback import SCRIPT


def _page() -> str:
    return html_page([], "2026-01-01 00:00 UTC", '<section id="replay"></section>')


def test_the_page_inlines_every_asset_file_as_it_is():
    page = _page()
    for name in ("page.css", "page.js", "replay.css", "replay.js"):
        text = assets.text(name)
        assert text.strip() and text in page, name
    assert SCRIPT == assets.text("replay.js")


def test_the_policy_allows_exactly_the_page_script_by_its_hash():
    page = _page()
    policy = html.unescape(re.search(r'http-equiv="Content-Security-Policy" content="([^"]*)"', page).group(1))
    (script,) = re.findall(r"<script>(.*?)</script>", page, flags=re.S)  # the one executable script (data blocks are typed)
    digest = base64.b64encode(hashlib.sha256(script.encode()).digest()).decode()
    assert f"script-src 'sha256-{digest}'" in policy and "unsafe-inline" not in policy.split("script-src")[1].split(";")[0]
    assert assets.text("page.js") in script and assets.text("replay.js") in script



@pytest.mark.skipif(shutil.which("node") is None, reason="needs Node.js to parse the scripts")
@pytest.mark.parametrize("name", ["page.js", "replay.js"])
def test_each_script_parses_as_javascript(name, tmp_path):
    """A syntax error in a script would only show in a reader's browser; Node's parser finds it here."""
    path = tmp_path / name
    path.write_text(assets.text(name))
    out = subprocess.run(["node", "--check", str(path)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
