"""The leaderboard page's own code as files: its style sheets and scripts, shipped as package data.

``page.css`` and ``page.js`` style the tables and sort and filter them (:mod:`earthbench.publishing.publish`);
``replay.css`` and ``replay.js`` are the replay viewer's (:mod:`earthbench.running.playback`). Files rather
than Python strings, so an editor and a linter read them as CSS and JavaScript; the page inlines
them and allows its one script by the SHA-256 of exactly the text read here.
"""

from __future__ import annotations

import functools
from importlib.resources import files


@functools.cache
def text(name: str) -> str:
    """The text of one asset file (``page.js`` …), read once per process."""
    return files(__name__).joinpath(name).read_text(encoding="utf-8")
