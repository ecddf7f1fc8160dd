"""The inside of one case: a warden process and, under it, the planner's process.

:func:`earthbench.running.harness.run_case` starts ``python -c BOOTSTRAP``, in a sandbox of its own
where the machine allows it (:mod:`.isolation`). The bootstrap is plain Python that imports
nothing of earthbench, numpy or the plugin; it becomes the case's *warden*:

* in a sandbox whose root is the harness's (the harness runs as root), it drops to ``nobody``
  before anything else; it makes itself non-dumpable, so the planner (the same user) cannot
  open its descriptors or memory through ``/proc``;

* it makes itself a child subreaper (``prctl(PR_SET_CHILD_SUBREAPER)``), so every descendant
  of the case, also one that left the session (``setsid``) or was double-forked, is
  re-parented to it rather than to init; with ``PR_SET_PDEATHSIG`` it hears of the
  harness's death;
* it pins the slot's cores and forks the *planner process*, which sets ``RLIMIT_AS`` and then
  runs :func:`main` (the only place plugin code runs);
* it reaps every descendant until the planner process has exited, then kills (SIGKILL) and
  reaps whatever is left; SIGTERM (from the harness at a deadline, or as the harness dies)
  ends the case the same way;
* it writes on a pipe only it holds (the planner process closes it before any plugin code
  runs) the planner process's pid at once, and at the end one report: the planner process's
  exit status, and the kernel's accounting of
  every reaped descendant (``getrusage(RUSAGE_CHILDREN)``: CPU seconds and peak resident
  memory), so CPU and memory figures cover the case's own process tree and nothing else.

The planner process reads the case's specification (planner name, source, overrides) from the
first line of its stdin, then talks to the harness over another inherited pipe, one JSON
object per line: ``{"event": "ready"}`` once the planner's code is imported, then, after it has
read the scenario that the harness writes to its stdin in answer (one line,
``{"nonce": N, "input": SCENARIO}``), ``{"event": "done", "outcome": "plan" | "error" |
"memory", "plan": JSON, "error": text, "detail": {...}, "nonce": N}``: every reply echoes the
nonce of the input it answers. The
harness validates every message and owns every time: it starts the wall budget when it hands
over the scenario and stops it when the result arrives; ``detail`` (the child's own timings) is
kept for information only. The child never judges its own plan.

A preparation job may send ``{"event": "progress", "done": K, "total": N, "what": TEXT, "nonce": N}``
before its result, when the planner calls ``Planner.report_progress`` (at most ten a second).

A closed-loop configuration (docs/DESIGN.md §6) answers instead with ``{"event": "step",
"plan": JSON, "nonce": N}`` per step; the harness executes the step on the truth and writes
the next observation (with a fresh nonce) as the next line of stdin, or closes stdin to end the run. When ``step()``
returns None the child sends ``{"event": "done", "outcome": "steps"}``.
"""

from __future__ import annotations

import importlib
import importlib.util
import json
import os
import resource
import sys
import time
import traceback
from typing import Any


def _cpu() -> float:
    """Process CPU seconds (all threads) plus those of reaped child processes, µs resolution."""
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def load_planner_class(source: str, name: str) -> type:
    """Import exactly the planner's code, without loading every registered plugin.

    ``module:qualname`` is imported; a ``.py`` path is executed as a module and searched for
    the Planner subclass called ``name``. (Loading the whole registry would import every
    installed planner's dependencies into every case, seconds of start-up that have nothing
    to do with the planner under test.)
    """
    if source.endswith(".py"):
        from earthbench.planner import Planner
        from earthbench.registry import PLANNERS, plugin_module

        folder = os.path.dirname(os.path.realpath(source))
        if folder not in sys.path:  # its sibling modules, as for a script (the case sees them: docs/isolation.md)
            sys.path.insert(0, folder)
        module, run = plugin_module(source)
        run()
        mod_name = module.__name__
        for candidate in vars(module).values():
            if isinstance(candidate, type) and issubclass(candidate, Planner) and candidate.__module__ == mod_name \
                    and candidate.name == name:
                return candidate
        return PLANNERS.get(name)  # registered by a decorator under another class name
    module_name, _, qual = source.partition(":")
    obj: Any = importlib.import_module(module_name)
    for part in qual.split("."):
        obj = getattr(obj, part)
    return obj


def read_input(line: bytes) -> tuple[Any, str]:
    """One input the harness wrote: ``{"nonce": N, "input": DOC}`` -> (DOC, N). Every reply
    echoes the nonce of the input it answers, so a reply written before it arrived is refused."""
    if not line:
        raise EOFError("the harness closed the case's input")
    env = json.loads(line)
    return env["input"], env["nonce"]


def main(fd: int) -> None:
    """Read the case's specification from stdin, load the planner, say ``ready``, read the
    scenario from stdin, plan, send the result."""
    out = os.fdopen(fd, "w", buffering=1)
    given = {"nonce": ""}  # of the input being answered

    def send(msg: dict[str, Any]) -> None:
        if given["nonce"]:
            msg["nonce"] = given["nonce"]
        out.write(json.dumps(msg) + "\n")
        out.flush()

    try:
        doc = json.loads(sys.stdin.buffer.readline())
        if doc.get("job") == "probe":  # a planner probe, not a case (earthbench.running.harness.probe)
            _probe(doc, given, send)
            out.close()
            return
        from earthbench.plan import Plan
        from earthbench.world import Scenario

        cls = load_planner_class(doc["source"], doc["name"])
        overrides = doc.get("overrides", {})
        prepared = doc.get("prepared")
        if doc.get("job") == "prepare":  # a preparation, not a case (earthbench.running.harness.prepare)
            del doc
            _prepare(cls, overrides, given, send)
            out.close()
            return
        del doc
    except BaseException as exc:  # noqa: BLE001 - everything the planner's import can do is reported
        outcome = "memory" if isinstance(exc, MemoryError) else "error"
        send({"event": "done", "outcome": outcome, "error": "could not load the planner:\n" + traceback.format_exc()})
        return

    send({"event": "ready"})
    outcome, error, plan = "plan", "", None
    t0, c0 = time.perf_counter(), _cpu()
    try:
        doc, given["nonce"] = read_input(sys.stdin.buffer.readline())
        planner = cls(**overrides)
        if prepared is not None:
            from pathlib import Path

            planner.prepared = Path(prepared)
        if planner.closed_loop:
            if not _steps(planner, doc, given, send):
                out.close()
                return  # the harness ended the run (step cap, broken rules): nothing more to say
            outcome = "steps"
        else:
            plan = planner.plan(Scenario.from_dict(doc))
    except MemoryError:
        plan = None
        outcome, error = "memory", "MemoryError: the planner exceeded the memory budget\n" + _short_tb()
    except BaseException as exc:  # noqa: BLE001 - SystemExit and KeyboardInterrupt too
        plan = None
        outcome, error = "error", _tb(exc)
    finally:
        wall, cpu = time.perf_counter() - t0, _cpu() - c0
    msg: dict[str, Any] = {"event": "done", "detail": {"solve_time_s": wall, "solve_cpu_s": cpu}}
    if outcome == "plan":
        if not isinstance(plan, Plan):
            outcome = "error"
            error = f"plan() returned {type(plan).__module__}.{type(plan).__qualname__}, not an earthbench.Plan"
        else:
            try:
                msg["plan"] = plan.to_json()
            except Exception as exc:  # noqa: BLE001
                outcome, error = "error", "the plan could not be written as JSON:\n" + _tb(exc)
    msg.update(outcome=outcome, error=error)
    try:
        send(msg)
    except (TypeError, ValueError) as exc:  # e.g. a to_json() that returned something JSON cannot write
        send({"event": "done", "outcome": "error", "error": "the plan could not be written as JSON:\n" + _tb(exc)})
    out.close()


def _prepare(cls: type, overrides: dict[str, Any], given: dict[str, str], send: Any) -> None:
    """A preparation job: say ready, read ``{"folder": PATH, "jobs": N}``, call ``prepare``,
    answer ``{"event": "done", "outcome": "prepared", "summary": JSON text}`` (or an error)."""
    from pathlib import Path

    send({"event": "ready"})
    outcome, error, summary = "prepared", "", None
    try:
        job, given["nonce"] = read_input(sys.stdin.buffer.readline())
        planner = cls(**overrides)
        planner.progress_sink = _progress_sender(send)
        summary = planner.prepare(Path(job["folder"]), int(job["jobs"]))
    except MemoryError:
        outcome, error = "memory", "MemoryError: the preparation exceeded its memory budget\n" + _short_tb()
    except BaseException as exc:  # noqa: BLE001 - SystemExit and KeyboardInterrupt too
        outcome, error = "error", _tb(exc)
    msg: dict[str, Any] = {"event": "done", "outcome": outcome, "error": error}
    if outcome == "prepared":
        try:
            msg["summary"] = json.dumps(summary)
        except (TypeError, ValueError) as exc:
            msg.update(outcome="error", error="prepare() returned what JSON cannot write:\n" + _tb(exc))
    send(msg)


#: Seconds between two progress messages a preparation sends (the last step's always goes).
PROGRESS_EVERY_S = 0.1


def _progress_sender(send: Any) -> Any:
    """Where ``Planner.report_progress`` goes in a preparation job: ``{"event": "progress", "done": K,
    "total": N, "what": TEXT}`` on the message pipe, at most one per :data:`PROGRESS_EVERY_S`,
    from any thread, with the planner's slips mended (K within 0..N, TEXT short) so an honest
    planner never breaks the protocol (the harness checks each message all the same)."""
    import threading

    lock, last = threading.Lock(), [-PROGRESS_EVERY_S]

    def sink(p: Any) -> None:
        total = max(0, int(p.total))
        done = min(max(0, int(p.done)), total)
        with lock:
            now = time.monotonic()
            if now - last[0] < PROGRESS_EVERY_S and not 0 < done == total:
                return
            last[0] = now
            send({"event": "progress", "done": done, "total": total, "what": str(p.what)[:200]})

    return sink


def _probe(spec: dict[str, Any], given: dict[str, str], send: Any) -> None:
    """A probe job: say ready, read what to resolve, import the plugin and describe its planners
    (:func:`earthbench.running.harness.describe.answer`), answer ``{"outcome": "probed", "summary": JSON text}``."""
    from earthbench.running.harness.describe import answer

    send({"event": "ready"})
    try:
        payload, given["nonce"] = read_input(sys.stdin.buffer.readline())
        send({"event": "done", "outcome": "probed", "error": "", "summary": json.dumps(answer(spec, payload))})
    except MemoryError:
        send({"event": "done", "outcome": "memory", "error": "MemoryError: the probe exceeded its memory budget"})
    except BaseException as exc:  # noqa: BLE001 - SystemExit and KeyboardInterrupt too
        send({"event": "done", "outcome": "error", "error": _tb(exc)})


def _steps(planner: Any, doc: dict[str, Any], given: dict[str, str], send: Any) -> bool:
    """The closed loop: answer each observation with the next actions, one message per step,
    each echoing the nonce of the observation it answers.

    Returns True when the planner said done (returned None), False when the harness ended
    the run (it closed our stdin instead of sending the next observation).
    """
    from earthbench.plan import Plan
    from earthbench.planner import Observation

    first = None
    while True:
        obs = Observation.from_dict(doc, first)
        first = first or obs.scenario
        actions = planner.step(obs)
        if actions is None:
            return True
        if not isinstance(actions, Plan):
            raise TypeError(f"step() returned {type(actions).__module__}.{type(actions).__qualname__}, not an earthbench.Plan or None")
        send({"event": "step", "plan": actions.to_json()})
        line = sys.stdin.buffer.readline()
        if not line:
            return False
        doc, given["nonce"] = read_input(line)


def _tb(exc: BaseException) -> str:
    return "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))


def _short_tb() -> str:
    try:
        return traceback.format_exc(limit=-3)
    except MemoryError:
        return ""


BOOTSTRAP = r"""
import ctypes, json, os, resource, signal, sys
msg_fd, report_fd, cores, mem, harness = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], int(sys.argv[4]), int(sys.argv[5])
fsize = int(sys.argv[6]) if len(sys.argv) > 6 else 0
try:
    prctl = ctypes.CDLL(None, use_errno=True).prctl
except (OSError, AttributeError):
    prctl = None
if prctl is not None:
    prctl(36, 1)  # PR_SET_CHILD_SUBREAPER: orphans of the case come to the warden, not to init
    prctl(1, int(signal.SIGTERM))  # PR_SET_PDEATHSIG: the harness died -> end the case
if harness and os.getppid() != harness:  # 0: in a PID namespace of its own (bubblewrap's init is the parent)
    os._exit(70)
if not harness and os.getsid(0) != os.getpid():  # in a sandbox: lead a session of its own there too
    try:
        os.setsid()
    except OSError:
        pass
if not harness and os.getuid() == 0:  # the sandbox's root is the harness's: the case runs as nobody
    os.setgroups([])
    os.setgid(65534)
    os.setuid(65534)
if prctl is not None:
    prctl(4, 0)  # PR_SET_DUMPABLE 0: the planner cannot open this process's report pipe through /proc
cpus = [int(c) for c in cores.split(",") if c]
if cpus and hasattr(os, "sched_setaffinity"):  # Linux; elsewhere only the thread caps apply
    os.sched_setaffinity(0, cpus)
warden = os.getpid()
planner = os.fork()
if planner == 0:
    os.close(report_fd)
    if prctl is not None:
        prctl(1, int(signal.SIGKILL))
        prctl(4, 1)  # the planner's own process is an ordinary one
    if os.getppid() != warden:
        os._exit(70)
    if mem > 0:
        resource.setrlimit(resource.RLIMIT_AS, (mem, mem))
    if fsize > 0:  # a preparation: no file it writes may be larger than its disk budget
        resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))
    from earthbench.running.harness.child import main
    main(msg_fd)
    sys.exit(0)
os.close(msg_fd)
os.write(report_fd, (json.dumps({"planner": planner}) + "\n").encode())
devnull = os.open(os.devnull, os.O_RDONLY)
os.dup2(devnull, 0)
ending, orphans, status = False, 0, None

def kill_children():
    me = str(warden)
    for name in os.listdir("/proc"):
        if name.isdigit():
            try:
                with open("/proc/" + name + "/stat", "rb") as f:
                    ppid = f.read().rsplit(b")", 1)[1].split()[1]
            except (OSError, IndexError):
                continue
            if ppid == me.encode():
                try:
                    os.kill(int(name), signal.SIGKILL)
                except OSError:
                    pass

def alive_children():  # any child left? (reaps those already dead; /proc is scanned only if one lives)
    while True:
        try:
            pid, st = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return False
        if not pid:
            return True
        reaped(pid, st)

def reaped(pid, st):
    global status, ending, orphans
    if pid == planner:
        status, ending = st, True
    else:
        orphans += 1

def on_term(signum, frame):
    global ending
    ending = True
    kill_children()

signal.signal(signal.SIGTERM, on_term)
signal.signal(signal.SIGINT, signal.SIG_IGN)
while True:
    try:
        pid, st = os.waitpid(-1, 0)
    except ChildProcessError:
        break
    reaped(pid, st)
    if ending and alive_children():
        kill_children()
ru = resource.getrusage(resource.RUSAGE_CHILDREN)
report = {"status": None if status is None else os.waitstatus_to_exitcode(status),
          "cpu_s": ru.ru_utime + ru.ru_stime, "maxrss_kb": ru.ru_maxrss, "others": orphans}
try:
    os.write(report_fd, (json.dumps(report) + "\n").encode())
except OSError:  # the harness is gone
    pass
os._exit(0)
"""
"""Run as ``python -c BOOTSTRAP MSG_FD REPORT_FD CORES MEMORY_BYTES HARNESS_PID [FILE_BYTES]`` (pid 0:
in a sandbox of its own; ``FILE_BYTES``: a preparation's ``RLIMIT_FSIZE``, 0 none); the first line of
its stdin is the case's specification."""
