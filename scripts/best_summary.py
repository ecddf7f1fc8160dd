"""The best known plans kept in a folder, one Markdown row per suite: how many of its scenarios
have one, their best known / target bound, and who produced them (board runs, witnesses).

    python scripts/best_summary.py leaderboard/best
"""

from __future__ import annotations

import argparse
import collections
import gzip
import json
import statistics
from pathlib import Path

from earthbench.results.suite import load_suite


def producer_kind(producer: dict) -> tuple[bool, str]:
    """(a board run?, a short name): the planner of a run, or the witness's kind and planner."""
    if producer.get("kind") == "planner":
        return True, str(producer["planner"])
    name = str(producer.get("name", "?"))
    planner = name.split("--planner ")[1] if "--planner " in name else "greedy"
    for kind in ("rollout", "closed", "truth"):
        if f"--kind {kind}" in name:
            return False, "rollout" if kind == "rollout" else f"{kind}: {planner}"
    return False, name


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", nargs="?", default="leaderboard/best")
    root = Path(ap.parse_args().folder)
    print("| suite | kept / scenarios | best known / target bound: median (min–max) | kept plans: board runs; witnesses |")
    print("|---|---:|---:|---|")
    for folder in sorted(p for p in root.iterdir() if p.is_dir()):
        ratios, counts = [], {True: collections.Counter(), False: collections.Counter()}
        for f in sorted(folder.glob("*.json.gz")):
            doc = json.loads(gzip.decompress(f.read_bytes()))
            ratios.append(doc["time_per_target_m3"] / doc["time_per_target_m3_lower_bound"])
            run, name = producer_kind(doc.get("producer") or {})
            counts[run][name] += 1
        if not ratios:
            continue
        text = [", ".join(f"{k} {n}" for k, n in c.most_common()) or "–" for c in (counts[True], counts[False])]
        print(f"| `{folder.name}` | {len(ratios)} / {len(load_suite(folder.name).scenarios)} | {statistics.median(ratios):.3f} "
              f"({min(ratios):.3f}–{max(ratios):.3f}) | {text[0]}; {text[1]} |")


if __name__ == "__main__":
    main()
