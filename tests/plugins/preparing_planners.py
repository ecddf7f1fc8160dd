"""Planners with a preparation (docs/DESIGN.md §6 "Preparation"), for tests/test_prepare.py."""

from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import dataclass

from earthbench.plan import Plan, Prediction
from earthbench.planner import Planner


@dataclass(frozen=True)
class Config:
    token: str = "a"


class Prepares(Planner):
    """Writes a token and the process's view (jobs, pid, affinity) into its folder (the one place
    it may write: in a sandbox, nothing else is writable);
    its plan reports what it finds there and whether it can write there."""

    name = "t-prepares"
    Config = Config

    def prepare(self, folder, jobs=1):
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "token.txt").write_text(self.config.token)
        (folder / "seen.json").write_text(json.dumps({"jobs": jobs, "affinity": sorted(os.sched_getaffinity(0)),
                                                      "pid": os.getpid(), "argv": sys.argv}))
        return {"wrote": ["token.txt", "seen.json"]}

    def plan(self, scenario):
        folder = self.prepared
        token = (folder / "token.txt").read_text() if folder is not None else None
        try:
            with open(folder / "token.txt", "a"):
                writable = True
        except OSError:
            writable = False
        return Plan(predicted=Prediction(volume=0.0, makespan=0.0),
                    info={"prepared": str(folder), "token": token, "writable": writable,
                          "mode": oct(os.stat(folder / "token.txt").st_mode & 0o777)})


class PrepareFails(Planner):
    name = "t-prepare-fails"

    def prepare(self, folder, jobs=1):
        raise RuntimeError("no compiler here")

    def plan(self, scenario):
        return Plan(predicted=Prediction(volume=0.0, makespan=0.0))


class PrepareSleeps(Planner):
    name = "t-prepare-sleeps"

    def prepare(self, folder, jobs=1):
        time.sleep(30)

    def plan(self, scenario):
        return Plan(predicted=Prediction(volume=0.0, makespan=0.0))
