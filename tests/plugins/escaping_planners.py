"""Planners whose error and output carry raw terminal control sequences (issue 47): a line
erased and overwritten with a fake green "ok", a clipboard write (OSC 52), a bell, a
right-to-left override. Printed by earthbench, each must show as text. A name carrying them
(:data:`HOSTILE_NAME`) never gets that far: the probe refuses it (docs/isolation.md).
"""

from __future__ import annotations

import sys

from earthbench import Plan, Planner

#: What a hostile name, error or log line carries.
TRICKS = "\x1b[2K\r\x1b[32m ok \x1b[0m\x1b]52;c;ZXZpbA==\x07\u202e\x9b31m"
#: A planner name that carries them.
HOSTILE_NAME = "t-esc" + TRICKS


class Escaping(Planner):
    """Prints control sequences and raises with them."""

    name = "t-esc"
    tracks = ("backhoe",)

    def plan(self, scenario):
        print("log line " + TRICKS, flush=True)
        print("stderr line " + TRICKS, file=sys.stderr, flush=True)
        raise RuntimeError("error text " + TRICKS)


class EscapingQuiet(Planner):
    """Returns an empty plan (a stored, valid run) under a plain name."""

    name = "t-esc-ok"
    tracks = ("backhoe",)

    def plan(self, scenario):
        return Plan()
