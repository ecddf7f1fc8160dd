"""Planners that misbehave on purpose, one per fault the harness must survive.

Loaded as a plugin file (``--plugin`` / ``build_cases(plugins=...)``), so a case subprocess
imports them exactly as a user's one-file plugin.
"""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
import time

from earthbench import Dig, Plan, Planner, Prediction


class Fast(Planner):
    """Returns an empty plan at once: valid, loads nothing (harness overhead probe)."""

    name = "t-fast"

    def plan(self, scenario):
        return Plan(predicted=Prediction(volume=0.0, makespan=0.0))


class Raises(Planner):
    name = "t-raise"

    def plan(self, scenario):
        raise ValueError("planner bug: boom")


class NonPlan(Planner):
    name = "t-nonplan"

    def plan(self, scenario):
        return {"not": "a plan"}


class Invalid(Planner):
    """Digs far out of reach and too deep: the referee must flag it."""

    name = "t-invalid"

    def plan(self, scenario):
        return Plan((Dig("excavator", 0.0, 0.5, (0.5, 0.5), 0.0, 5.0, 3.0),))


class Sleeps(Planner):
    name = "t-sleep"

    def plan(self, scenario):
        time.sleep(120)
        return Plan()


class SleepsWithChild(Planner):
    """Starts a grandchild (in its own session, so a group kill alone would miss it), then hangs."""

    name = "t-spawn"

    def plan(self, scenario):
        p = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"], start_new_session=True)
        try:  # out of reach in a sandbox: the zoo then finds the case's processes by their tag
            with open(os.environ["EARTHBENCH_TEST_PIDFILE"], "w") as f:
                f.write(str(p.pid))
        except OSError:
            pass
        time.sleep(120)
        return Plan()


class Hog(Planner):
    """Grows by 128 MB blocks until the address-space limit stops it (untouched pages: fast)."""

    name = "t-memory"

    def plan(self, scenario):
        import numpy as np

        hoard = []
        while True:
            hoard.append(np.empty(128 * 1024 * 1024, dtype=np.uint8))


class Suicide(Planner):
    name = "t-kill"

    def plan(self, scenario):
        os.kill(os.getpid(), signal.SIGKILL)


class Exits(Planner):
    name = "t-exit"

    def plan(self, scenario):
        sys.exit(3)


class Probe(Planner):
    """Reports the fences it runs inside: affinity, thread caps, allocator settings, memory limit,
    process group."""

    name = "t-probe"

    def plan(self, scenario):
        return Plan(info={
            "affinity": sorted(os.sched_getaffinity(0)),
            "omp": os.environ.get("OMP_NUM_THREADS"),
            "openblas": os.environ.get("OPENBLAS_NUM_THREADS"),
            "allocator": sorted(k for k in os.environ if k.startswith(("MALLOC_", "GLIBC_TUNABLES"))),
            "rlimit_as": resource.getrlimit(resource.RLIMIT_AS)[0],
            "own_group": os.getpgid(0) == os.getppid() == os.getsid(0),  # the warden leads its own session
        })


class Nap(Planner):
    """Sleeps a little, then returns an empty plan: for interrupt and resume tests."""

    name = "t-nap"

    def plan(self, scenario):
        time.sleep(float(os.environ.get("EARTHBENCH_TEST_NAP", "0.3")))
        return Plan()


class NativeOOM(Planner):
    """Like a C++ solver whose allocation fails: prints bad_alloc and aborts."""

    name = "t-abort-oom"

    def plan(self, scenario):
        sys.stderr.write("terminate called after throwing an instance of 'std::bad_alloc'\n  what():  std::bad_alloc\n")
        sys.stderr.flush()
        os.abort()
