"""``earthbench prepare PLANNER``: run a planner's scenario-blind preparation on this machine.

``earthbench run`` does the same before the planner's first case when the folder is missing;
this command runs it on its own (e.g. to time it, or before a run on a busy machine), under a
suite's ``[budget] prepare_s``, ``prepare_memory_mb`` and ``prepare_disk_mb`` (``--suite``; default: their defaults).
"""

from __future__ import annotations

import argparse
import json
import sys

from ..errors import EarthbenchError
from ..world import Budget
from ._common import add_config_arg, add_plugin_arg, load_plugins, parse_config

HELP = """Run PLANNER's preparation (docs/DESIGN.md §6 "Preparation"): scenario-blind work, such as
compiling code, run once per planner, version, configuration, earthbench version and machine, in
a fenced process of its own with no scenario and no store. Its folder is kept under
$EARTHBENCH_PREPARED (default ~/.cache/earthbench/prepared) and read by every later case.

Prints the folder, the wall and CPU seconds and the peak memory the harness measured, and the
planner's summary. A preparation already on this machine is reported, not run again, unless
--again. Exit status 1 when the planner declares no preparation or it failed."""


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("prepare", help="run a planner's preparation on this machine (compiled code, once per machine)",
                       description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("planner", help="planner name (see `earthbench list planners`)")
    add_plugin_arg(p)
    add_config_arg(p)
    p.add_argument("--suite", metavar="SUITE", help="take the prepare_* limits (and cores) from this suite's budget")
    p.add_argument("--again", action="store_true", help="run it again even if this machine has it")
    return p


def run(args: argparse.Namespace) -> int:
    load_plugins(args)
    from ..running.harness.prepare import PrepareError, ensure, forget, prepare_key
    from ..running.harness.probe import info, resolve
    from .preparing import PrepareDisplay

    overrides = parse_config(args.config, info(args.planner)) if args.config else {}
    if args.suite:
        from ..results.suite import load_suite

        suite = load_suite(args.suite)
        budget = suite.budget
        overrides = {**suite.config.get(args.planner, {}), **overrides}
    else:
        budget = Budget()
    ref = resolve(args.planner, overrides)
    if not ref.prepares:
        print(f"earthbench: planner {ref.name!r} declares no preparation: its cases need none", file=sys.stderr)
        return 1
    if args.again:
        forget(ref)
    try:
        shown = PrepareDisplay()
        done = ensure(ref, budget, log=shown.log, on_progress=shown.progress)
    except PrepareError as exc:
        raise EarthbenchError(str(exc)) from None
    assert done is not None  # ref.prepares
    state = "ran now" if done.ran else "found on this machine (use --again to run it anew)"
    print(f"{ref.name} {ref.version} [{ref.config_hash[:8]}]: {state}\n"
          f"  folder   {done.path}\n  key      {prepare_key(ref)}\n"
          f"  wall     {done.wall_s:.1f} s\n  CPU      {done.cpu_s:.1f} s\n"
          f"  memory   {done.peak_rss_mb or 0:.0f} MB peak resident\n"
          f"  summary  {json.dumps(done.summary)}")
    return 0
