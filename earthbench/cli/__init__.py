"""The ``earthbench`` command line.

Each sub-command lives in its own module of this package with two functions:
``add_parser(subparsers)`` (declares its arguments and help) and ``run(args) -> int`` (the exit
status). Add a command by writing such a module and naming it in ``COMMANDS``.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import traceback
import types

from ..errors import EarthbenchError, printable
from ._common import PrintableStream
from ._common import parse_config as parse_config  # public: scripts convert KEY=VALUE settings as --config does

#: Sub-command modules, in the order ``earthbench --help`` lists them.
COMMANDS = [
    "list_",
    "plan",
    "validate",
    "show",
    "suites",
    "seal",
    "run",
    "prepare",
    "runs",
    "rescore",
    "new_planner",
    "leaderboard",
    "compare",
    "merge",
    "export",
    "verify",
    "best",
    "calibration",
]


#: The first steps, under ``earthbench --help`` (the README's route, docs/commands.md for every command).
START_HERE = """start here:
  earthbench run smoke --planner greedy      a first run: 4 small scenarios, seconds, a table and what to do next
  earthbench new-planner my-planner          a planner package of your own to edit (README.md, docs/plugins.md)
  earthbench COMMAND --help                  one command's options; every command: docs/commands.md"""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="earthbench",
        description="Benchmark earthmoving planners on shared terrain suites, judged by an independent referee.",
        epilog=START_HERE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    from .. import __version__

    parser.add_argument("--version", action="version", version=f"earthbench {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        module = importlib.import_module(f"{__name__}.{name}")
        p = module.add_parser(sub)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run one command; everything it prints goes through :class:`PrintableStream`, and so does
    the traceback of an exception it does not handle (a planner's, under `earthbench plan`)."""
    out, err = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = PrintableStream(out), PrintableStream(err)  # type: ignore[assignment]
    if sys.excepthook is sys.__excepthook__:
        sys.excepthook = _printable_traceback
    try:
        return _main(argv)
    finally:
        sys.stdout, sys.stderr = out, err


def _printable_traceback(kind: type[BaseException], exc: BaseException, tb: types.TracebackType | None) -> None:
    """An unhandled exception's traceback, its message made printable: it may quote a plugin."""
    sys.stderr.write(printable("".join(traceback.format_exception(kind, exc, tb))))


def _main(argv: list[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except EarthbenchError as exc:
        print(f"earthbench: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("earthbench: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader left (`earthbench runs | head`): end quietly, as a pipe tool does
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # so the interpreter's final flush does not complain
        return 128 + signal.SIGPIPE


if __name__ == "__main__":
    sys.exit(main())
