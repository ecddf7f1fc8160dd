"""Stores of real runs for the publishing tests, written through the store's own API.

Plans come from the greedy planner run in this process (its call timed as the harness
would), judged by the referee through :func:`earthbench.results.scoring.score`, and stored with
:meth:`earthbench.results.store.Store.record`. Other "planners" reuse those plans cut short (so they
load less) or fail without a plan, to give the tables and profiles something to separate.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from earthbench.plan import Plan
from earthbench.running.harness import Case, CaseResult, PlannerRef
# From its module: once any harness module has imported ``.environment``, the package attribute
# ``environment`` is that submodule, not the function of the same name.
from earthbench.running.harness.environment import environment
from earthbench.results.scoring import score
from earthbench.results.store import Store
from earthbench.results.suite import Suite, parse_suite, load_suite
from earthbench_planners.greedy.backhoe import GreedyPlanner

EVIL = "<script>alert(1)</script>"


def suite_of(n_seeds: int, name: str = "pubtest", targets: Sequence[float] = (0.56, 1.12)) -> Suite:
    """An rbf suite of ``n_seeds × len(targets)`` small scenarios (generated in milliseconds)."""
    text = f"""
name = "{name}"
track = "backhoe"
[budget]
wall_s = 60
cores = 2
memory_mb = 4096
[[family]]
name = "rbf14"
generator = "rbf"
targets = [{", ".join(repr(float(t)) for t in targets)}]
seeds = "0-{n_seeds - 1}"
[family.params]
n_bases = 14
"""
    return parse_suite(text, path="", default_name=name)


def ref(name: str, version: str = "1.0", config: dict[str, Any] | None = None) -> PlannerRef:
    config = config or {}
    return PlannerRef(name=name, version=version, source="tests.helpers.leaderboard:none", config=config,
                      config_hash=hashlib.sha256(json.dumps([name, version, config], sort_keys=True).encode()).hexdigest()[:16])


@dataclasses.dataclass(frozen=True)
class Behaviour:
    """How a fake planner turns the greedy plan into its own: keep a fraction of the actions, or fail."""

    ref: PlannerRef
    keep: float = 1.0
    fail: str | None = None  # a termination reason without a plan: timeout, error, memory, crashed
    slow: float = 1.0  # solve time = greedy's measured time × slow
    cpu_model: str | None = None  # override the environment's CPU model
    fail_every: int = 1  # with ``fail``: fail on every n-th scenario only
    teleport: float = 0.0  # shift the truck's moves this far east: an invalid plan (discontinuous, dump reach)
    solve_s: float | None = None  # a fixed solve time instead of the measured one (for golden tables)


def fill_store(db: Path, suite: Suite, behaviours: Sequence[Behaviour]) -> Path:
    """Run greedy on every scenario of ``suite``, derive each behaviour's result, record all of them."""
    env = environment("")
    greedy = GreedyPlanner()
    with Store(db) as store:
        store.register_suite(suite)
        for n, sc in enumerate(suite.scenarios):
            t0, c0 = time.perf_counter(), time.process_time()
            plan = greedy.plan(sc)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            for b in behaviours:
                case = Case(suite.name, suite.digest, suite.success_threshold, sc, b.ref)
                e = dict(env, cpu_model=b.cpu_model) if b.cpu_model else env
                w, c = (wall, cpu) if b.solve_s is None else (b.solve_s * (1 + n % 3), b.solve_s * (1 + n % 3))
                common = dict(key=case.key, scenario_id=sc.id, solve_time_s=w * b.slow, solve_cpu_s=c * b.slow,
                              cores=(0, 1), started_at="2026-11-22T05:00:00+00:00",
                              finished_at="2026-11-22T05:00:01+00:00", environment=e)
                fail = b.fail if (b.fail and n % b.fail_every == 0) else None
                if fail:
                    res = CaseResult(reason=fail, error=f"{fail} in the fixture", **common)
                else:
                    k = max(0, int(round(len(plan.actions) * b.keep)))
                    mine = Plan(plan.actions[:k]) if b.keep < 1 else plan
                    if b.teleport:
                        mine = Plan(tuple(_shifted(a, b.teleport) for a in mine.actions))
                    text = mine.to_json()
                    verdict, metrics = score(sc, text, suite.success_threshold)
                    metrics.update(solve_time_s=common["solve_time_s"], solve_cpu_s=common["solve_cpu_s"])
                    res = CaseResult(reason="ok" if verdict.valid else "invalid", metrics=metrics,
                                     violations=tuple(v.to_dict() for v in verdict.violations), plan_json=text, **common)
                store.record(case, res)
    return db


def _shifted(action: Any, dx: float) -> Any:
    """The truck's moves ``dx`` further east: it jumps off its start, and the dumps may miss it."""
    if getattr(action, "kind", "") == "move" and action.machine == "truck":
        return dataclasses.replace(action, path=tuple((t, x + dx, y, yaw) for t, x, y, yaw in action.path))
    return action


def standard_behaviours() -> list[Behaviour]:
    return [
        Behaviour(ref("greedy", "1.0")),
        Behaviour(ref("half"), keep=0.5, slow=0.5),
        Behaviour(ref(EVIL, "6.6"), keep=0.8, slow=2.0),
        Behaviour(ref("flaky"), fail="timeout", slow=3.0, fail_every=2),
    ]


__all__ = ["EVIL", "Behaviour", "fill_store", "load_suite", "ref", "standard_behaviours", "suite_of"]
