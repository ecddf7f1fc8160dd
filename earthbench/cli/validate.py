"""``earthbench validate PLAN.json --scenario S.json``: the referee's verdict and the metrics."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from ..errors import PlanFormatError
from ..plan import Plan
from ..referee import judge
from ..results.scoring import DEFAULT_SUCCESS_THRESHOLD
from ..world import Scenario


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "validate",
        help="judge a plan with the referee and print the verdict, violations and metrics",
        description="Replay PLAN on the scenario with the referee. Exit status 0 for a valid plan, 1 for an invalid one.",
    )
    p.add_argument("plan", metavar="PLAN.json", help="the plan document (`earthbench plan -o` or `earthbench runs --id N --plan-out`)")
    p.add_argument("--scenario", required=True, metavar="SCENARIO.json",
                   help="the scenario it was planned for (`earthbench plan --save-scenario` or `earthbench runs --id N --scenario-out`)")
    p.add_argument("--threshold", type=float, default=DEFAULT_SUCCESS_THRESHOLD,
                   help=f"volume ratio needed for success (default: {DEFAULT_SUCCESS_THRESHOLD:g})")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    return p


def run(args: argparse.Namespace) -> int:
    from ..results.scoring import evaluate

    scenario = Scenario.from_json(Path(args.scenario))
    # the argument is only ever a file: its content is judged as a plan, never followed as a path
    try:
        text = Path(args.plan).read_text()
    except FileNotFoundError:
        raise PlanFormatError(f"plan file {args.plan!r} not found") from None
    except UnicodeDecodeError:
        raise PlanFormatError(f"plan file {args.plan!r} is not UTF-8 text") from None
    except OSError as exc:
        raise PlanFormatError(f"cannot read plan file {args.plan!r}: {exc.strerror}") from None
    verdict = judge(scenario, text)  # a malformed document is an invalid verdict, not a crash
    plan = None if any(v.rule == "malformed" for v in verdict.violations) else Plan.from_json(text)
    metrics = evaluate(scenario, plan, verdict, args.threshold) if plan is not None else {}
    if args.json:
        print(
            json.dumps(
                {"valid": verdict.valid, "violations": [v.to_dict() for v in verdict.violations], "metrics": metrics}, indent=1, default=str
            )
        )
    else:
        print(f"verdict: {verdict.summary()}")
        for v in verdict.violations:
            where = "plan" if v.action is None else f"action {v.action}"
            print(f"  {where}: {v.rule} (magnitude {v.magnitude:.4g}) {v.message}")
        for k, val in metrics.items():
            if val is None:  # e.g. solve times: measured by the harness around a planner call, not here
                continue
            if isinstance(val, float) and math.isfinite(val):
                val = f"{val:.4g}"
            print(f"  {k:<26} {val}")
    return 0 if verdict.valid else 1
