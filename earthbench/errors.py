"""The exceptions a user can cause.

Every error that bad input can trigger derives from :class:`EarthbenchError`, so the CLI can
print its message and exit non-zero instead of showing a traceback. Messages say what to do.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Iterable
from pathlib import Path


class EarthbenchError(Exception):
    """Base class for errors caused by user input (names, files, plans, suites)."""


class UnknownNameError(EarthbenchError, KeyError):
    """A planner, terrain generator, metric or suite name that is not registered."""

    def __init__(self, kind: str, name: str, known: Iterable[str]):
        self.kind, self.name = kind, name
        self.known = sorted(known)
        close = difflib.get_close_matches(name, self.known, n=3, cutoff=0.5)
        hint = f" Did you mean {', '.join(repr(c) for c in close)}?" if close else ""
        listing = ", ".join(self.known) if self.known else "(none registered)"
        super().__init__(f"unknown {kind} {name!r}.{hint} Known {kind}s: {listing}.")

    def __str__(self) -> str:  # KeyError would otherwise quote the message
        return self.args[0]


def not_stored(kind: str, name: str, stored: Iterable[str], db: object) -> str:
    """The message for a ``kind`` (suite, planner) that names nothing in the store ``db``, with
    close matches: a typo would otherwise be an empty table that looks like an answer."""
    known = sorted(set(stored))
    close = difflib.get_close_matches(name, known, n=3, cutoff=0.5)
    return (f"{kind} {name!r} has no runs in {str(db)!r}" + (f"; did you mean {', '.join(map(repr, close))}?" if close else ".")
            + f" {kind.capitalize()}s there: {', '.join(known) or '(none)'}")


class PlanFormatError(EarthbenchError, ValueError):
    """A plan document that cannot be read: unknown action, missing field, NaN, bad times."""


class ScenarioError(EarthbenchError, ValueError):
    """A scenario or terrain file that is malformed or inconsistent."""


class SuiteError(EarthbenchError, ValueError):
    """A suite file with a typo, an unknown key or an impossible value."""


class StoreError(EarthbenchError):
    """A results database that is not earthbench's, is newer than this version, or is locked."""


class PluginError(EarthbenchError):
    """A plugin that cannot be loaded, or a planner that breaks the planner contract."""


def read_document(path: Path, what: str, error: type[EarthbenchError]) -> str:
    """The text of the ``what`` file at ``path``, or ``error`` with one line saying why not
    (missing, unreadable, not text): a bad file name is bad input, never a traceback."""
    try:
        return path.read_text()
    except FileNotFoundError:
        raise error(f"{what} file {str(path)!r} not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"cannot read {what} file {str(path)!r}: {getattr(exc, 'strerror', None) or exc}") from None


#: What a terminal acts on instead of showing: the C0 controls but newline and tab (escape
#: sequences start with ESC, a carriage return overwrites a line), DEL, the C1 controls, and
#: Unicode's zero-width, line-separator and bidirectional marks (text that reads other than it is).
_CONTROLS = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u200b-\u200f\u2028-\u202e\u2060-\u2069\ufeff]")


def printable(text: str) -> str:
    """``text`` with every character a terminal would act on written as its escape (``\\x1b``,
    ``\\u202e``): planner names, errors, log tails and suite names come from plugins and
    submitted stores, and must reach the operator's terminal as text, never as commands."""
    return _CONTROLS.sub(lambda m: f"\\x{ord(m[0]):02x}" if ord(m[0]) < 0x100 else f"\\u{ord(m[0]):04x}", text)
