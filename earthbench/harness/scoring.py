"""Scoring a plan: the referee's verdict and every registered metric, in one call.

The harness, ``earthbench rescore`` and the test fixtures all score through :func:`score`.
"""

from __future__ import annotations

from typing import Any

from ..world import Scenario


def score(scenario: Scenario, plan_json: str, threshold: float) -> tuple[Any, dict[str, Any]]:
    """Judge a plan and compute every registered metric; shared with ``earthbench rescore``."""
    from metrics import evaluate  # the built-in metrics package; extra metrics come from plugins

    from ..plan import Plan
    from ..referee import judge

    verdict = judge(scenario, plan_json)
    try:
        plan = Plan.from_json(plan_json)
    except Exception:  # noqa: BLE001 - malformed: the verdict already says so
        plan = Plan()
    return verdict, evaluate(scenario, plan, verdict, threshold)
