"""``earthbench calibration``: each machine class's cycles and fills, judged by the referee,
beside the handbook's bands (docs/machine-classes.md)."""

from __future__ import annotations

import argparse

from ..results.calibration import calibration
from ..classes import machine_class


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "calibration",
        help="each machine class's cycle times and bucket fills, judged by the referee, against the handbooks' bands",
        description="Judge a dig–swing–dump–return cycle (a wheel loader's V-pattern) and a full stroke for each machine "
                    "class and condition with the referee, and print earthbench's figure beside the handbook's band. "
                    "Exit status 1 when a calibrated class's figure lies outside its band.",
    )
    p.add_argument("classes", nargs="*", metavar="CLASS", help="machine classes (default: every class)")
    p.add_argument("--sources", action="store_true", help="also print the source of every band")
    return p


def run(args: argparse.Namespace) -> int:
    for name in args.classes:
        machine_class(name)  # an unknown name: one line with the close ones
    rows = calibration(args.classes or None)
    outside = 0
    head = f"{'class':<8} {'machine':<9} {'what':<5} {'condition':<34} {'earthbench':>10}  {'handbook':>11}  verdict"
    print(head)
    print("-" * len(head))
    for r in rows:
        fig = f"{r.figure:.2f} {r.unit}".strip() if r.unit else f"{r.figure:.3f}"
        band = "—" if r.band is None else (f"{r.band[0]:g}–{r.band[1]:g} {r.unit}".strip())
        verdict = {None: "uncalibrated", True: "inside", False: "OUTSIDE"}[r.inside]
        outside += r.inside is False
        print(f"{r.machine_class:<8} {r.machine:<9} {r.what:<5} {r.condition:<34} {fig:>10}  {band:>11}  {verdict}")
        if args.sources:
            print(f"{'':>8}   source: {r.source}")
    uncal = sorted({r.machine_class for r in rows if r.band is None})
    for name in uncal:
        print(f"\n{name}: uncalibrated, compared with {machine_class(name).compared_with}")
    print(f"\n{len(rows)} rows; {outside} outside their band. Figures: the referee's judgement of a constructed cycle plan "
          "(earthbench.results.calibration); cycles in s, fills as loose m³ ÷ heaped capacity.")
    return 1 if outside else 0
