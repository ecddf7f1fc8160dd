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


# -- channels that only isolation closes (docs/isolation.md); each raises once it got through,
# so a case that ends ``ok`` found the channel shut

def _other_pids() -> list[int]:
    """Every process this one can see that is not of its own case's tree (warden and below)."""
    mine = {os.getpid(), os.getppid()}
    out = []
    for name in os.listdir("/proc"):
        if name.isdigit() and int(name) not in mine:
            try:
                with open(f"/proc/{name}/stat", "rb") as f:
                    ppid = int(f.read().rsplit(b")", 1)[1].split()[1])
            except (OSError, ValueError, IndexError):
                continue
            if ppid not in mine:
                out.append(int(name))
    return out


class ReadsStore(Planner):
    """Looks through /proc/*/fd for an open SQLite store (the harness's), reads it, rewrites its runs."""

    name = "h-read-store"

    def plan(self, scenario):
        import sqlite3

        for pid in _other_pids():
            try:
                fds = os.listdir(f"/proc/{pid}/fd")
            except OSError:
                continue
            for fd in fds:
                try:
                    target = os.readlink(f"/proc/{pid}/fd/{fd}")
                except OSError:
                    continue
                if target.endswith(".db"):
                    try:
                        db = sqlite3.connect(f"/proc/{pid}/fd/{fd}")
                        db.execute("UPDATE runs SET reason='crashed', solve_time_s=0.001")
                        db.commit()
                    except (OSError, sqlite3.Error):
                        pass
                    raise RuntimeError(f"reached the store {target} through /proc/{pid}/fd/{fd}")
        return Plan()


class ReadsHarnessMemory(Planner):
    """Opens /proc/PID/mem of every process it can see outside its case and reads a mapped page."""

    name = "h-read-mem"

    def plan(self, scenario):
        for pid in _other_pids():
            try:
                with open(f"/proc/{pid}/maps") as f:
                    first = f.readline().split()[0]
                lo = int(first.split("-")[0], 16)
                with open(f"/proc/{pid}/mem", "rb") as mem:
                    mem.seek(lo)
                    if mem.read(4096):
                        raise RuntimeError(f"read the memory of process {pid}")
            except (OSError, ValueError, IndexError):
                continue
        return Plan()


class RewritesOtherCases(Planner):
    """Looks for other cases' folders in the machine's temp folder and writes into them."""

    name = "h-rewrite-other"

    def plan(self, scenario):
        import glob
        import tempfile

        for d in glob.glob(os.path.join(tempfile.gettempdir(), "earthbench-case-*")) + glob.glob("/tmp/earthbench-case-*"):
            if os.path.abspath(d) == os.path.abspath(os.getcwd()):
                continue
            try:
                with open(os.path.join(d, "case.json"), "w") as f:
                    f.write('{"name": "t-fast", "source": "forged", "overrides": {}}')
            except OSError:
                continue
            raise RuntimeError(f"wrote into another case's folder {d}")
        return Plan()


def _burn(seconds: float) -> None:
    t = time.process_time()
    while time.process_time() - t < seconds:
        pass


class ForgesReport(Planner):
    """Reopens its warden's report pipe through /proc and writes a report of 0 s CPU and 1 MB
    first, then burns 2 s of CPU holding 300 MB."""

    name = "h-forge-report"

    def plan(self, scenario):
        import json

        forged = {"status": 0, "cpu_s": 0.0, "maxrss_kb": 1024, "others": 0}
        report = json.dumps({"planner": os.getpid()}) + "\n" + json.dumps(forged) + "\n"
        try:
            fd = os.open(f"/proc/{os.getppid()}/fd/{sys.argv[2]}", os.O_WRONLY)
            os.write(fd, report.encode())
            os.close(fd)
        except OSError:
            pass
        hoard = b"\x01" * (300 * 2**20)
        _burn(2.0)
        return Plan(info={"held": len(hoard)})


class TreeOverMemory(Planner):
    """Three child processes of 600 MB each, every page written: 1.8 GB under a 1,024 MB budget
    (each process stays under the per-process limit)."""

    name = "h-tree-memory"

    def plan(self, scenario):
        hold = "import sys, time\nb = b'\\x01' * (600 * 2**20)\nprint(flush=True)\ntime.sleep(3)"
        kids = [subprocess.Popen([sys.executable, "-c", hold], stdout=subprocess.PIPE) for _ in range(3)]
        for k in kids:
            k.stdout.readline()
        for k in kids:
            k.wait()
        return Plan()


class EscapesCores(Planner):
    """Asks for every core of the machine with sched_setaffinity and says which it got."""

    name = "h-affinity"

    def plan(self, scenario):
        try:
            os.sched_setaffinity(0, range(os.cpu_count() or 1))
        except OSError:
            pass
        return Plan(info={"affinity": sorted(os.sched_getaffinity(0))})


class LeaksEnvironment(Planner):
    """Sends the whole environment it was given out again: in its plan's info and in its log."""

    name = "h-env-leak"

    def plan(self, scenario):
        env = dict(os.environ)
        print(env, flush=True)
        return Plan(info={"env": env, "cwd": os.getcwd()})


class FloodsLog(Planner):
    """Writes 100 MB to its stdout (a file on the host would hold them all) and tries to fallocate more."""

    name = "h-log-flood"

    def plan(self, scenario):
        try:
            os.posix_fallocate(1, 0, 2**30)
        except OSError:
            pass
        block = b"spam " * 200_000
        for _ in range(100):
            os.write(1, block)
        return Plan()


class FloodsAfterResult(Planner):
    """Keeps a copy of its message pipe and, once its result is sent, floods it with blank lines."""

    name = "h-after-result"

    def plan(self, scenario):
        import atexit

        fd = os.dup(_harness_pipe())

        def flood():
            end = time.monotonic() + 20
            while time.monotonic() < end:
                try:
                    os.write(fd, b"\n" * 65536)
                except OSError:
                    return

        atexit.register(flood)
        return Plan()


class FloodsBlankLines(Planner):
    """Floods its message pipe with blank lines before any result."""

    name = "h-blank-lines"

    def plan(self, scenario):
        for _ in range(160):
            os.write(_harness_pipe(), b"\n" * 65536)
        time.sleep(12)
        return Plan()


class ForgesProgress(Planner):
    """Digs the job's nonce out of the bootstrap's frames and reports preparation progress from a
    case, a message only a preparation may send (its text a terminal's clear-screen)."""

    name = "h-progress"

    def plan(self, scenario):
        import json

        frame, nonce = sys._getframe(), None
        while frame is not None and nonce is None:
            given = frame.f_locals.get("given")
            nonce = given.get("nonce") if isinstance(given, dict) else None
            frame = frame.f_back
        msg = {"event": "progress", "done": 1, "total": 2, "what": "\x1b[2J", "nonce": nonce}
        os.write(_harness_pipe(), (json.dumps(msg) + "\n").encode())
        time.sleep(12)
        return Plan()
