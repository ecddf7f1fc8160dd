"""Planners for the Dask executor tests (loaded as a plugin file, like a user's one-file plugin)."""

from __future__ import annotations

import os
import signal
import time

from earthbench import Plan, Planner


class KillsItsWorker(Planner):
    """Kills the process that supervises it (on a Dask worker: the worker itself), every time."""

    name = "t-kill-worker"

    def plan(self, scenario):
        import psutil

        os.kill(psutil.Process(os.getppid()).ppid(), signal.SIGKILL)  # the case's warden's parent: the worker
        time.sleep(30)
        return Plan()
