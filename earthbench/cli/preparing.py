"""A preparation on the terminal (``earthbench run``, ``earthbench prepare``): its start and end as
lines, and while it runs what it works on, how far it is and an estimate of the time left
(docs/running.md "Preparation"). On a terminal one line keeps time in place; in a log file a
line per step, at most one per :data:`LINE_EVERY_S`, and one every :data:`QUIET_EVERY_S` while
the planner says nothing."""

from __future__ import annotations

import sys
import time
from typing import TextIO

from ..errors import printable
from ..running.harness.prepare import PrepareStatus

#: Seconds between two progress lines in a log (not a terminal).
LINE_EVERY_S = 10.0
#: Seconds after which a log gets a line although the step has not changed.
QUIET_EVERY_S = 60.0


def duration(seconds: float) -> str:
    """``42 s``, ``8 min 20 s``, ``1 h 5 min``."""
    s = int(round(seconds))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60} s"
    return f"{s // 3600} h {s % 3600 // 60} min"


def status_line(s: PrepareStatus) -> str:
    """``stl-tamp: 3 of 7 · NLP global 4: building and compiling · 2 min 10 s, about 6 min 0 s left``."""
    p = s.progress
    where = "working" if p is None else f"{p.done} of {p.total}" + (f" · {p.what}" if p.what else "")
    left = f", about {duration(s.left_s)} left" if s.left_s is not None else ""
    return f"  {s.planner}: {where} · {duration(s.elapsed_s)}{left}"


class PrepareDisplay:
    """The ``log`` and ``on_progress`` of :func:`earthbench.running.harness.prepare.ensure` for a terminal or a log."""

    def __init__(self, stream: TextIO | None = None, live: bool | None = None):
        self.stream = stream or sys.stderr
        # the line's own controls (redraw in place) go to the terminal itself, its text through
        # printable() (as the run's progress line, earthbench.results.progress)
        self.terminal: TextIO = getattr(self.stream, "raw", self.stream)
        self.live = self.stream.isatty() if live is None else live
        self.showing = False
        self.printed_at = float("-inf")
        self.step: tuple[int, int] | None = None

    def log(self, message: str) -> None:
        """A line of its own (the preparation started or ended), below the progress line."""
        self._clear()
        print(f"earthbench: {message}", file=self.stream, flush=True)
        self.printed_at = time.monotonic()

    def progress(self, status: PrepareStatus) -> None:
        line = status_line(status)
        if self.live:
            self.terminal.write("\r" + printable(line) + "\x1b[K")
            self.terminal.flush()
            self.showing = True
            return
        now = time.monotonic()
        step = (status.progress.done, status.progress.total) if status.progress is not None else None
        if (step != self.step and now - self.printed_at >= LINE_EVERY_S) or now - self.printed_at >= QUIET_EVERY_S:
            print(line, file=self.stream, flush=True)
            self.printed_at, self.step = now, step

    def _clear(self) -> None:
        if self.showing:
            self.terminal.write("\r\x1b[K")
            self.terminal.flush()
            self.showing = False
