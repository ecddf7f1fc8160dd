"""Planners that attack the harness on purpose: forged messages, escapes, bloated results.

Loaded as a plugin file, like :mod:`faulty_planners`. A planner that starts processes writes
their pids, one per line, to ``$EARTHBENCH_TEST_PIDDIR/<name>.pids`` where it can (without
isolation) so the zoo can check that none outlives its case.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

from earthbench import Plan, Planner


def _harness_pipe() -> int:
    """The descriptor a case reports on: anyone in the process can find it (here: the argv)."""
    return int(sys.argv[1])


def _note(name: str, *pids: int) -> None:
    """Without isolation the zoo checks these pids; in a sandbox the folder is out of reach (and
    the pids are its PID namespace's), so the zoo looks for the case's processes by their tag."""
    try:
        with open(os.path.join(os.environ["EARTHBENCH_TEST_PIDDIR"], f"{name}.pids"), "a") as f:
            f.write("".join(f"{p}\n" for p in pids))
    except OSError:
        pass


def _sleeper(**kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", "import time; time.sleep(300)"], **kw)


class ForgesReady(Planner):
    """Says 'ready' again mid-plan, hoping to restart the budget, then overruns it."""

    name = "h-forge-ready"

    def plan(self, scenario):
        os.write(_harness_pipe(), b'{"event": "ready"}\n')
        time.sleep(12)
        return Plan()


class ForgesStarted(Planner):
    """The old protocol's trick: a 'started' mark with a far-future time."""

    name = "h-forge-started"

    def plan(self, scenario):
        os.write(_harness_pipe(), b'{"event": "started", "t": 1e12, "cpu": 0}\n')
        time.sleep(12)
        return Plan()


class ForgesDone(Planner):
    """Works 1 s, then sends its own result claiming 1 ms of solve time, and exits."""

    name = "h-forge-done"

    def plan(self, scenario):
        import json

        time.sleep(1.0)
        msg = {"event": "done", "outcome": "plan", "plan": Plan().to_json(), "detail": {"solve_time_s": 0.001, "solve_cpu_s": 0.0}}
        os.write(_harness_pipe(), (json.dumps(msg) + "\n").encode())
        os._exit(0)


class PlanFortyTwo(Planner):
    name = "h-plan-42"

    def plan(self, scenario):
        os.write(_harness_pipe(), b'{"event": "done", "outcome": "plan", "plan": 42}\n')
        os._exit(0)


class DictPlan(Plan):
    def to_json(self):  # a dict where a JSON text belongs
        return {"actions": []}


class ReturnsDictPlan(Planner):
    name = "h-dict-plan"

    def plan(self, scenario):
        return DictPlan()


class Garbage(Planner):
    name = "h-garbage"

    def plan(self, scenario):
        os.write(_harness_pipe(), b"\x00\xff not json at all\n")
        time.sleep(12)
        return Plan()


class Bloated(Planner):
    """Sends a result line over the plan-size limit (and keeps writing)."""

    name = "h-bloated"

    def plan(self, scenario):
        fd = _harness_pipe()
        os.write(fd, b'{"event": "done", "outcome": "plan", "plan": "')
        block = b"x" * (1 << 20)
        for _ in range(200):
            os.write(fd, block)
        return Plan()


class Escapes(Planner):
    """Leaves a process in a new session and a double-forked one behind, and returns at once."""

    name = "h-escape"

    def plan(self, scenario):
        a = _sleeper(start_new_session=True)
        r, w = os.pipe()
        if os.fork() == 0:  # double fork: the grandchild is orphaned at once
            os.setsid()
            b = _sleeper()
            os.write(w, f"{b.pid}\n".encode())
            os._exit(0)
        os.close(w)
        b_pid = int(os.read(r, 64))
        _note(self.name, a.pid, b_pid)
        return Plan()


class KillsWarden(Planner):
    """Leaves a process in a new session, then kills the case's warden (its parent)."""

    name = "h-kill-warden"

    def plan(self, scenario):
        a = _sleeper(start_new_session=True)
        _note(self.name, a.pid)
        os.kill(os.getppid(), signal.SIGKILL)
        time.sleep(12)
        return Plan()


class BurnsInOrphan(Planner):
    """Has a process it does not wait for burn 0.5 s of CPU, and returns once it has."""

    name = "h-orphan-burn"

    def plan(self, scenario):
        burn = "import sys, time\nt = time.process_time()\nwhile time.process_time() - t < 0.5: pass\nprint(flush=True)\ntime.sleep(300)"
        p = subprocess.Popen([sys.executable, "-c", burn], start_new_session=True, stdout=subprocess.PIPE)
        _note(self.name, p.pid)
        p.stdout.readline()
        return Plan()


class Segfaults(Planner):
    name = "h-segv"

    def plan(self, scenario):
        os.kill(os.getpid(), signal.SIGSEGV)


class BigResult(Planner):
    """Sends a result of ``$EARTHBENCH_TEST_RESULT_MB`` MB (a JSON string plan) at once: the read-time probe."""

    name = "h-big-result"

    def plan(self, scenario):
        import json

        mb = float(os.environ.get("EARTHBENCH_TEST_RESULT_MB", "12"))
        text = Plan(info={"pad": "x" * int(mb * 2**20)}).to_json()
        os.write(_harness_pipe(), (json.dumps({"event": "done", "outcome": "plan", "plan": text}) + "\n").encode())
        os._exit(0)
