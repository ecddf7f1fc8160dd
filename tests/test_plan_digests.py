"""Pinned plan digests: every built-in planner's plan on ``smoke``, ``quick`` and ``pile`` is
byte-identical to the one recorded in ``tests/golden/plan_digests.json``.

A refactor must leave every plan as it was; a change that is meant to move plans bumps the
planner's version, updates the golden file (the command is in the module's ``__main__``), and
says in its commit which plans moved and why — the published leaderboards then need a rerun.

Where the golden file holds a list, each entry is the digest of the same code on another CPU
model: the wheel-loader planners' plans on some ``pile`` scenarios differ between the AMD EPYC
and the Intel Xeon these were run on (stl-tamp's do not: it rounds what it hands IPOPT, see
planners/stl_tamp/NOTES.md). A list is a known irreproducibility of that planner, not a tolerance: a
refactor still has to give one of the recorded plans, and ``write_golden`` records only the
machine it runs on. A planner whose plans are known to depend on the CPU but that has been
recorded on some models only (``recorded_on`` in the golden file) is checked on those models and
skipped, with the reason, on any other: its digests there are unknown, not wrong.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from earthbench.plan import Plan
from earthbench.registry import PLANNERS
from earthbench.results.suite import load_suite

GOLDEN = Path(__file__).parent / "golden" / "plan_digests.json"
SUITES = ("smoke", "quick", "pile")


def cpu_model() -> str:
    """The CPU's model name as the kernel reports it (empty where it does not)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return ""
    return next((line.split(":", 1)[1].strip() for line in text.splitlines() if line.startswith("model name")), "")


def plan_digest(plan: Plan) -> str:
    """sha256 (first 16 hex digits) of the plan's actions; ``info`` and predictions are left out."""
    return hashlib.sha256(json.dumps(plan.to_dict()["actions"], sort_keys=True).encode()).hexdigest()[:16]


def _cases() -> list[tuple[str, str]]:
    pinned = json.loads(GOLDEN.read_text())["plans"]
    return [(planner, sid) for planner in sorted(pinned) for sid in sorted(pinned[planner])]


@pytest.fixture(scope="module")
def scenarios():
    return {sc.id: sc for name in SUITES for sc in load_suite(name).scenarios}


@pytest.mark.slow
@pytest.mark.parametrize(("planner", "scenario_id"), _cases())
def test_plan_is_byte_identical(scenarios, planner, scenario_id):
    golden = json.loads(GOLDEN.read_text())
    models = golden.get("recorded_on", {}).get(planner)
    if models and not any(m in cpu_model() for m in models):
        pytest.skip(f"{planner}'s plans depend on the CPU and were recorded on {', '.join(models)} only, not on {cpu_model()!r}")
    expected = golden["plans"][planner][scenario_id]
    plan = PLANNERS.get(planner)().plan(scenarios[scenario_id])
    assert plan_digest(plan) in ([expected] if isinstance(expected, str) else expected)


def test_every_built_in_planner_is_pinned():
    pinned = json.loads(GOLDEN.read_text())["plans"]
    assert set(pinned) == {"greedy", "greedy-loader", "separate", "singh-cannon-backhoe", "singh-cannon-loader", "stl-tamp", "strip-loader"}
    assert all(len(v) >= 4 for v in pinned.values())


def write_golden() -> None:
    """Record every built-in planner's current plans: ``python tests/test_plan_digests.py``."""
    plans: dict[str, dict[str, str]] = {}
    for name in SUITES:
        suite = load_suite(name)
        for planner in suite.planners or [p for p in PLANNERS.names() if suite.track in PLANNERS.get(p).tracks]:
            for sc in suite.scenarios:
                plans.setdefault(planner, {})[sc.id] = plan_digest(PLANNERS.get(planner)().plan(sc))
    doc = {"note": "sha256 (first 16 hex) of each plan's actions as sorted-key JSON; see tests/test_plan_digests.py",
           "plans": plans, "recorded_on": json.loads(GOLDEN.read_text()).get("recorded_on", {})}
    GOLDEN.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")


if __name__ == "__main__":
    write_golden()
