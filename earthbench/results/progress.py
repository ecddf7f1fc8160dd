"""The live progress line of ``earthbench run``: counts by termination reason and an ETA.

On a terminal the line is redrawn in place; elsewhere (CI logs, pipes) one line is printed
per finished case, so a log shows every case and its outcome.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO

from ..errors import printable
from .records import REASONS, Case, CaseResult


def _clock(seconds: float) -> str:
    s = int(round(seconds))
    h, rem = divmod(s, 3600)
    m, s = divmod(rem, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


class Progress:
    """Counts finished cases by reason; the ETA is the mean time per case so far × cases left."""

    def __init__(self, total: int, *, stream: TextIO | None = None, live: bool | None = None, quiet: bool = False,
                 run_id: Callable[[Case], int | None] | None = None, runs_command: str = "earthbench runs"):
        self.total = total
        self.planned = total  # the cases asked for; ``total`` becomes those left to run (the harness skips stored ones)
        self.stream = stream or sys.stderr
        # the line's own controls (redraw in place) go to the terminal itself; what it shows of a
        # case (planner names, errors) goes through printable() in _write
        self.terminal: TextIO = getattr(self.stream, "raw", self.stream)
        self.live = self.stream.isatty() if live is None else live
        self.quiet = quiet
        self.run_id = run_id  # the stored run of a case, for a pointer to `earthbench runs --id N`
        self.runs_command = runs_command  # `earthbench runs` with the options (``--db``) its pointer needs to run as printed
        self.counts = {r: 0 for r in REASONS}
        self.done = 0
        self.t0 = time.monotonic()

    def line(self) -> str:
        elapsed = time.monotonic() - self.t0
        counts = " ".join(f"{r} {n}" for r, n in self.counts.items() if n or r == "ok")
        eta = f"ETA {_clock(elapsed / self.done * (self.total - self.done))}" if self.done else "ETA –"
        width = len(str(self.total))
        return f"[{self.done:>{width}}/{self.total}] {counts} | {_clock(elapsed)} elapsed, {eta}"

    def start(self) -> None:
        self.t0 = time.monotonic()
        if not self.quiet and self.planned > self.total:  # say it before counting to fewer than the header's cases
            skipped = self.planned - self.total
            self.stream.write(f"{skipped} of the {self.planned} cases already stored: skipped (--rerun runs them again); "
                              f"running {self.total}\n")
        if self.live and not self.quiet and self.total:
            self._write("\r", self.line(), "\x1b[K")

    def update(self, case: Case, result: CaseResult) -> None:
        self.done += 1
        self.counts[result.reason] = self.counts.get(result.reason, 0) + 1
        if self.quiet:
            return
        t = f"{result.solve_time_s:.2f} s" if result.solve_time_s is not None else "–"
        detail = f"{case.label}: {result.reason} ({t})"
        if result.reason == "invalid" and result.violations:
            first = result.violations[0]
            where = "plan" if first.get("action") is None else f"action {first['action']}"
            more = len(result.violations) - 1
            detail += f" — {first['rule']} at {where}: {str(first.get('message', ''))[:120]}"
            detail += f" (+{more} more)" if more else ""
        elif result.reason in ("error", "crashed", "memory", "timeout") and result.error:
            detail += " — " + result.error.strip().splitlines()[-1][:160]
        rid = self.run_id(case) if self.run_id is not None and result.reason != "ok" else None
        if rid is not None:
            detail += f"; see: {self.runs_command} --id {rid}"
        if self.live:
            self._write("\r\x1b[K", detail + "\n" + self.line(), "\x1b[K")
        else:
            self._write("", self.line() + "  " + detail + "\n", "")

    def close(self) -> None:
        if self.live and not self.quiet and self.total:
            self._write("", "\n", "")

    def _write(self, before: str, text: str, after: str) -> None:
        """``text`` made printable between the line's own control sequences."""
        self.terminal.write(before + printable(text) + after)
        self.terminal.flush()
