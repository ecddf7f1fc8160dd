"""The inside of one case subprocess: load the planner, time its call, send back the plan.

Started by :func:`earthbench.harness.run_case` through a tiny bootstrap that pins the CPU
affinity and sets the memory limit *before* this module (and so numpy) is imported. It talks
to the harness over an inherited pipe, one JSON object per line:

* ``{"event": "started", "t": <CLOCK_MONOTONIC>, "cpu": <process CPU s>}`` just before the
  planner is constructed: the wall budget runs from here, so imports and reading the
  scenario never count against the planner;
* ``{"event": "done", "outcome": "plan" | "error" | "memory", ...}`` with the harness-side
  timings (``solve_time_s`` wall, ``solve_cpu_s`` process CPU incl. reaped children) that are
  measured even when the planner raises.

The child never judges its own plan: the referee runs in the harness process, out of the
planner's reach.
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


def load_planner_class(source: str, name: str, plugins: list[str] | tuple[str, ...] = ()) -> type:
    """Import exactly the planner's code, without loading every registered plugin.

    ``module:qualname`` is imported; a ``.py`` path is executed as a module and searched for
    the Planner subclass called ``name``; ``registry`` loads ``plugins`` and looks ``name`` up.
    (Loading the whole registry would import every installed planner's dependencies into
    every case, seconds of start-up that have nothing to do with the planner under test.)
    """
    from earthbench.planner import Planner
    from earthbench.registry import PLANNERS, load_plugin_file

    if source.endswith(".py"):
        mod_name = f"earthbench_plugin_{os.path.splitext(os.path.basename(source))[0]}"
        spec = importlib.util.spec_from_file_location(mod_name, source)
        if spec is None or spec.loader is None:
            raise ImportError(f"{source} is not an importable Python file")
        module = importlib.util.module_from_spec(spec)
        sys.modules[mod_name] = module
        spec.loader.exec_module(module)
        for obj in vars(module).values():
            if isinstance(obj, type) and issubclass(obj, Planner) and obj.__module__ == mod_name and obj.name == name:
                return obj
        return PLANNERS.get(name)  # registered by a decorator under another class name
    if source == "registry":
        for plugin in plugins:
            load_plugin_file(plugin)
        return PLANNERS.get(name)
    module_name, _, qual = source.partition(":")
    obj: Any = importlib.import_module(module_name)
    for part in qual.split("."):
        obj = getattr(obj, part)
    return obj


def main(case_file: str, fd: int) -> None:
    out = os.fdopen(fd, "w", buffering=1)

    def send(msg: dict[str, Any]) -> None:
        out.write(json.dumps(msg) + "\n")
        out.flush()

    try:
        with open(case_file) as f:
            doc = json.load(f)
        from earthbench.plan import Plan
        from earthbench.world import Scenario

        cls = load_planner_class(doc["source"], doc["name"], doc.get("plugins", ()))
        scenario = Scenario.from_dict(doc["scenario"])
        overrides = doc.get("overrides", {})
        del doc
    except BaseException as exc:  # noqa: BLE001 - everything the planner's import can do is reported
        outcome = "memory" if isinstance(exc, MemoryError) else "error"
        send({"event": "done", "outcome": outcome, "error": "could not load the planner:\n" + traceback.format_exc()})
        return

    send({"event": "started", "t": time.monotonic(), "cpu": _cpu()})
    outcome, error, plan = "plan", "", None
    t0, c0 = time.perf_counter(), _cpu()
    try:
        planner = cls(**overrides)
        plan = planner.plan(scenario)
    except MemoryError:
        plan = None
        outcome, error = "memory", "MemoryError: the planner exceeded the memory budget\n" + _short_tb()
    except BaseException as exc:  # noqa: BLE001 - SystemExit and KeyboardInterrupt too
        plan = None
        outcome, error = "error", _tb(exc)
    finally:
        wall, cpu = time.perf_counter() - t0, _cpu() - c0
    msg: dict[str, Any] = {"event": "done", "solve_time_s": wall, "solve_cpu_s": cpu}
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
    send(msg)
    out.close()


def _tb(exc: BaseException) -> str:
    return "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))


def _short_tb() -> str:
    try:
        return traceback.format_exc(limit=-3)
    except MemoryError:
        return ""


BOOTSTRAP = """
import os, sys, resource
cores = [int(c) for c in sys.argv[3].split(",") if c]
if cores and hasattr(os, "sched_setaffinity"):  # Linux; elsewhere only the thread caps apply
    os.sched_setaffinity(0, cores)
mem = int(sys.argv[4])
if mem > 0:
    resource.setrlimit(resource.RLIMIT_AS, (mem, mem))
try:
    import ctypes
    ctypes.CDLL(None).prctl(1, 9)  # PR_SET_PDEATHSIG = SIGKILL: never outlive the harness
    if os.getppid() != int(sys.argv[5]):
        os._exit(70)
except (OSError, AttributeError):
    pass
from earthbench.harness.child import main
main(sys.argv[1], int(sys.argv[2]))
"""
"""Run as ``python -c BOOTSTRAP CASE_FILE FD CORES MEMORY_BYTES PARENT_PID``."""

if __name__ == "__main__":  # pragma: no cover - for debugging a case file by hand
    main(sys.argv[1], sys.stdout.fileno())
