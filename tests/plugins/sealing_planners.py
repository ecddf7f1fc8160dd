"""Hostile planners that try to know which scenario they play: the trust model of sealed runs.

Each is honest greedy when its trick fails, so a sealed run shows exactly what the trick gains
(docs/sealed-evaluation.md). ``info["trick"]`` says whether it worked on a case.

* ``t-oracle`` regenerates the hidden world: it loads the public suites named in its config,
  regenerates every scenario with the public generators and :func:`earthbench.soil.draw` (what
  ``load_suite`` does), computes each one's observation, and when one equals what it was handed
  it plans on that scenario's truth (true terrain, true soil).
* ``t-lookup`` ships plans computed offline, keyed by the digest of the observation.
* ``t-witness`` plans nothing; it reports everything a case process can read about itself
  (environment, arguments, working directory, the files there), so a test can look for names.
"""

from __future__ import annotations

import json
import os
import sys
from dataclasses import dataclass

from earthbench import Plan, Planner


def _honest(view) -> Plan:
    from earthbench_planners.greedy.backhoe import GreedyPlanner

    return GreedyPlanner().plan(view)


def _tagged(plan: Plan, trick: str) -> Plan:
    return Plan(plan.actions, plan.predicted, {**plan.info, "trick": trick})


class Oracle(Planner):
    name = "t-oracle"

    @dataclass(frozen=True)
    class Config:
        suites: tuple[str, ...] = ()

    def plan(self, view):
        from earthbench.sensing import observe
        from earthbench.results.suite import load_suite

        for suite in self.config.suites:
            for truth in load_suite(suite).scenarios:
                if observe(truth).digest == view.digest:
                    return _tagged(_honest(truth), "hit")
        return _tagged(_honest(view), "miss")


class Lookup(Planner):
    name = "t-lookup"

    @dataclass(frozen=True)
    class Config:
        table: str = ""

    def plan(self, view):
        with open(self.config.table) as f:
            table = json.load(f)
        if view.digest in table:
            return _tagged(Plan.from_json(table[view.digest]), "hit")
        return _tagged(_honest(view), "miss")


class Witness(Planner):
    name = "t-witness"

    def plan(self, view):
        here = os.getcwd()
        files = {}
        for name in sorted(os.listdir(here)):
            try:
                with open(os.path.join(here, name), errors="replace") as f:
                    files[name] = f.read(100_000)
            except OSError:
                files[name] = "(unreadable)"
        return Plan(info={"environ": dict(os.environ), "argv": sys.argv, "cwd": here, "files": files,
                          "id": view.id, "meta": view.meta})
