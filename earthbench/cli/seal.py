"""``earthbench seal SUITE --key FILE``: a fresh secret key for a sealed draw of a suite, and its commitment.

The key (32 random bytes) goes to FILE, readable by its owner only; keep it secret until the
board is published. The command prints the sealed suite's name and the commitment (sha256 over
the key, the suite's digest and the sealed scenarios' digests): publish the commitment before
the run. Then `earthbench run SUITE --sealed FILE` runs the draw; afterwards, reveal FILE and
anyone can check the board with `earthbench verify STORE --key FILE` (docs/sealed-evaluation.md).
"""

from __future__ import annotations

import argparse
import shlex
import sys


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("seal", help="make a secret key for a sealed draw of a suite and print its commitment",
                       description=__doc__.replace("``", "`"), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("suite", help="suite name (see `earthbench suites`) or path of a suite TOML file")
    p.add_argument("--key", required=True, metavar="FILE", help="where to write the new key file (never overwritten)")
    return p


def run(args: argparse.Namespace) -> int:
    from ..results.suite import load_suite, new_key

    suite = load_suite(args.suite)
    key, sealed = new_key(suite)
    key.write(args.key)
    print(f"sealed suite: {sealed.name} ({len(sealed.scenarios)} scenarios drawn from {suite.name} {suite.digest[:12]}…)")
    print(f"commitment:   {key.commitment}")
    print(f"key:          {args.key} (secret until the board is published)")
    print(f"next: earthbench run {shlex.quote(args.suite)} --sealed {shlex.quote(str(args.key))}")
    same = sum(a.terrain.z.tobytes() == b.terrain.z.tobytes() for a, b in zip(suite.scenarios, sealed.scenarios))
    if same:  # a sealed draw changes only the seeds (docs/sealed-evaluation.md): nothing else may tell it apart
        print(f"earthbench: note: {same} of {len(sealed.scenarios)} sealed scenarios have their public terrain (a generator "
              "that ignores its seed, as `file` does): a case can recognise those; sealing hides nothing there", file=sys.stderr)
    return 0
