"""The README leads and the docs hold the rest: it stays short, links every page, and no link is broken."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LINK = re.compile(r"\]\(([^)\s]+)\)")


def _links(md: Path) -> list[str]:
    return [m.group(1) for m in LINK.finditer(md.read_text()) if not m.group(1).startswith(("http://", "https://", "#"))]


def test_readme_is_short_and_links_every_page():
    readme = ROOT / "README.md"
    assert len(readme.read_text().splitlines()) <= 300
    linked = {(ROOT / link.split("#")[0]).resolve() for link in _links(readme)}
    pages = list((ROOT / "docs").glob("*.md")) + list((ROOT / "planners").glob("*/README.md"))
    missing = [str(p.relative_to(ROOT)) for p in pages if p.resolve() not in linked]
    assert not missing, f"pages the README does not link: {missing}"


def test_relative_links_resolve():
    docs = [ROOT / "README.md", *(ROOT / "docs").glob("*.md"), *(ROOT / "planners").glob("*/*.md"),
            ROOT / "leaderboard" / "COMMANDS.md"]
    broken = []
    for md in docs:
        for link in _links(md):
            target = (md.parent / link.split("#")[0]).resolve()
            if not target.exists():
                broken.append(f"{md.relative_to(ROOT)}: {link}")
    assert not broken, broken


def test_readme_quick_start_is_what_ci_runs():
    """`.ci/run` runs the README's test command; the two must not drift apart."""
    readme = (ROOT / "README.md").read_text()
    assert "pip install -e '.[test]' && python -m pytest\n" in readme
    ci = (ROOT / ".ci" / "run").read_text()
    assert "pip install --quiet -e '.[test]'" in ci and ci.rstrip().endswith("python -m pytest")
