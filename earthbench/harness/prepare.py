"""A planner's preparation: scenario-blind work run once per machine before its first case.

The rule and its trust argument are docs/DESIGN.md §6 "Preparation". In short: a planner that
overrides :meth:`earthbench.planner.Planner.prepare` gets one call per planner, version,
configuration, earthbench version and machine (CPU model, instruction set, C compiler), in a
fenced process of its own (the case's warden and supervisor, :mod:`.sandbox`), under the
budget's ``prepare_s`` and ``prepare_memory_mb``, with no scenario and no store. It writes a
folder; the folder is named by the hash of everything it depends on (:func:`prepare_key`), made
read-only, and every later case of that planner configuration on this machine is told where it
is (``Planner.prepared``). Its wall and CPU time are the harness's measurements, stored with each
run that used it (``prepare_s``, ``prepare_cpu_s``) and shown beside the solve times, never in
them.

Where folders live: ``$EARTHBENCH_PREPARED`` (a directory), else
``$XDG_CACHE_HOME/earthbench/prepared`` (default ``~/.cache/earthbench/prepared``). A folder is
complete when its ``prepare.json`` is there: it is written last, and the folder is renamed into
place only after it, so a killed preparation leaves nothing a case would use.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import platform
import shutil
import stat
import subprocess
import threading
from collections.abc import Callable, Sequence
from importlib import metadata
from pathlib import Path

from ..errors import EarthbenchError
from ..registry import OWN_DISTRIBUTION
from ..world import Budget
from ..records import Case, CaseResult, PlannerRef, utc_now
from .cases import Prepared

ENV = "EARTHBENCH_PREPARED"
#: ``EARTHBENCH_PREPARE=off``: no preparation is run or used; cases run without their planner's
#: folder (a planner must work without it: stl-tamp then loads its NLPs uncompiled, with the
#: same plans) and their runs store no preparation time.
SWITCH = "EARTHBENCH_PREPARE"
MANIFEST = "prepare.json"


class PrepareError(EarthbenchError):
    """A planner's preparation failed (its error, a timeout, a crash): its cases are not run."""


def root() -> Path:
    """Where preparations are kept (see the module's docstring)."""
    env = os.environ.get(ENV, "").strip()
    if env:
        return Path(env).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "earthbench" / "prepared"


@functools.lru_cache(maxsize=1)
def machine_stamp() -> dict[str, str]:
    """What compiled or tuned output depends on: CPU model and instruction set, the C compiler,
    the interpreter, and earthbench's version."""
    cpu, flags = platform.processor() or platform.machine(), ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name") and cpu == (platform.processor() or platform.machine()):
                    cpu = line.split(":", 1)[1].strip()
                elif line.startswith("flags") and not flags:
                    flags = hashlib.sha256(" ".join(sorted(line.split(":", 1)[1].split())).encode()).hexdigest()[:16]
    except OSError:
        pass
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc") or ""
    compiler = "none"
    if cc:
        try:
            out = subprocess.run([cc, "--version"], capture_output=True, text=True, timeout=30)
            compiler = (out.stdout.splitlines() or ["unknown"])[0]
        except (OSError, subprocess.SubprocessError):
            compiler = "unknown"
    try:
        version = metadata.version("earthbench")
    except metadata.PackageNotFoundError:
        version = "unknown"
    return {"cpu_model": cpu, "isa": f"{platform.machine()} {flags}", "compiler": compiler,
            "python": platform.python_version(), "earthbench": version}


def prepare_key(ref: PlannerRef) -> str:
    """The folder's name: a hash of planner, version, configuration, the digest of its code and
    :func:`machine_stamp`. The configuration's ``closed_loop`` setting is left out: it is how the
    harness calls the planner (docs/DESIGN.md §6), so open and closed loop share one preparation.
    A plugin's code digest is in it (two plugins of one name and version never share a folder); the
    built-in planners' is earthbench's version, already in the machine stamp, so their keys stay."""
    config = {k: v for k, v in ref.config.items() if k != "closed_loop"}
    doc = {"planner": ref.name, "version": ref.version, "config": config, "machine": machine_stamp()}
    if ref.code_digest and ref.code_digest != OWN_DISTRIBUTION:
        doc["code"] = ref.code_digest
    return f"{ref.name}-{hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:24]}"


def find(ref: PlannerRef) -> Prepared | None:
    """The finished preparation of ``ref`` on this machine, or None."""
    path = root() / prepare_key(ref)
    try:
        doc = json.loads((path / MANIFEST).read_text())
        return Prepared(doc["key"], str(path), float(doc["wall_s"]), float(doc["cpu_s"]), doc.get("peak_rss_mb"),
                        summary=doc.get("summary"))
    except (OSError, ValueError, KeyError, TypeError):
        return None


_LOCKS: dict[str, threading.Lock] = {}
_FAILED: dict[str, str] = {}
_LOCKS_LOCK = threading.Lock()


def ensure(ref: PlannerRef, budget: Budget, cores: Sequence[int] | None = None, *,
           stop: threading.Event | None = None, log: Callable[[str], None] | None = None) -> Prepared | None:
    """The preparation of ``ref`` on this machine: found on disk, or run now (once per process
    and key; concurrent callers wait for it). None when the planner declares none or
    ``$EARTHBENCH_PREPARE`` is ``off``. Raises
    :class:`PrepareError` when it fails."""
    if not ref.prepares or os.environ.get(SWITCH, "").strip().lower() == "off":
        return None
    key = prepare_key(ref)
    with _LOCKS_LOCK:
        lock = _LOCKS.setdefault(key, threading.Lock())
    with lock:
        found = find(ref)
        if found is not None:
            return found
        if key in _FAILED:  # one attempt per process: the next cases fail at once with its error
            raise PrepareError(_FAILED[key])
        if log is not None:
            log(f"preparing {ref.name} {ref.version} (config {ref.config_hash}) on this machine: "
                f"up to {budget.prepare_s:g} s and {budget.prepare_memory_mb} MB")
        try:
            done = run(ref, budget, cores, stop=stop)
        except PrepareError as exc:
            if "interrupted" not in str(exc):
                _FAILED[key] = str(exc)
            raise
        if log is not None:
            log(f"prepared {ref.name} in {done.wall_s:.1f} s ({done.cpu_s:.1f} s CPU): {done.path}")
        return done


def run_prepared_case(case: Case, cores: Sequence[int], *, stop: threading.Event | None = None,
                      startup_s: float | None = None) -> CaseResult:
    """:func:`.sandbox.run_case` after the case's planner is prepared on this machine (what every
    executor calls): a failed preparation is this case's ``error``, with its message."""
    from .sandbox import STARTUP_S, run_case

    try:
        prepared = ensure(case.planner, case.scenario.budget, cores, stop=stop) if case.prepare else None
    except PrepareError as exc:
        return CaseResult.failure(case, "error", str(exc))
    return run_case(case, cores, stop=stop, startup_s=STARTUP_S if startup_s is None else startup_s, prepared=prepared)


def run(ref: PlannerRef, budget: Budget, cores: Sequence[int] | None = None, *,
        stop: threading.Event | None = None) -> Prepared:
    """Run the preparation of ``ref`` now, in a fenced process (replacing a finished one)."""
    from .sandbox import run_job

    key = prepare_key(ref)
    final = root() / key
    cores = tuple(cores) if cores is not None else tuple(sorted(os.sched_getaffinity(0)))[:budget.cores]
    try:
        root().mkdir(parents=True, exist_ok=True)
        out = Path(_tmp_dir(root(), key))
    except OSError as exc:
        raise PrepareError(f"cannot create the preparation folder in {root()}: {exc.strerror}; set ${ENV}") from None
    # the job may run as another user inside its namespaces (docs/isolation.md): it must be able
    # to write its fresh, private output folder; _read_only takes every write bit off afterwards
    out.chmod(0o777)
    started = utc_now()
    job_budget = Budget(wall_s=budget.prepare_s, cores=len(cores), memory_mb=budget.prepare_memory_mb)
    job = {"name": ref.name, "source": ref.source, "overrides": ref.overrides, "job": "prepare"}
    payload = json.dumps({"folder": str(out), "jobs": len(cores)}).encode() + b"\n"
    try:
        o = run_job(job, payload, cores, job_budget, writable=str(out), stop=stop)
    except BaseException:
        _writable(out)
        shutil.rmtree(out, ignore_errors=True)
        raise
    tail = o.log_tail
    try:
        if o.cancelled:
            raise PrepareError(f"the preparation of {ref.name} was interrupted")
        if o.done is None or o.done.get("outcome") != "prepared":
            why = (o.fault or (o.done or {}).get("error") or
                   (f"it ran past its budget of {budget.prepare_s:g} s" if o.timed_out else f"its process exited with status {o.status}"))
            last = why.strip().splitlines()[-1] if why.strip() else ""
            raise PrepareError(f"the preparation of {ref.name} {ref.version} failed: {last}"
                               + (f"\n{tail}" if tail and not o.done else ""))
        doc = {"key": key, "planner": ref.name, "version": ref.version, "config_hash": ref.config_hash,
               "machine": machine_stamp(), "started_at": started, "wall_s": o.wall_s or 0.0,
               "cpu_s": o.cpu_s or 0.0, "peak_rss_mb": o.peak_rss_mb, "summary": json.loads(o.done["summary"])}
        (out / MANIFEST).write_text(json.dumps(doc, indent=1, sort_keys=True))
        _read_only(out)
        if final.exists():  # a preparation of the same key finished meanwhile (another process): replace it
            old = Path(_tmp_dir(root(), key + ".old"))
            os.rename(final, old / "prev")
            os.rename(out, final)
            _writable(old)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.rename(out, final)
    finally:
        if out.exists():
            _writable(out)
            shutil.rmtree(out, ignore_errors=True)
    return Prepared(key, str(final), doc["wall_s"], doc["cpu_s"], doc["peak_rss_mb"], ran=True, summary=doc["summary"])


def _tmp_dir(parent: Path, key: str) -> str:
    import tempfile

    return tempfile.mkdtemp(prefix=f".{key}.", suffix=".tmp", dir=parent)


def _read_only(folder: Path) -> None:
    """Readable by everyone, writable by no one (a case, whichever user the sandbox runs it as,
    sees the folder read only; for root the sandbox's mounts must enforce it: docs/DESIGN.md §6)."""
    for p in [*folder.rglob("*"), folder]:
        mode = stat.S_IMODE(p.stat().st_mode)
        try:  # a file the job wrote as another user (its namespace's) may refuse a chmod by ours
            p.chmod(0o555 if p.is_dir() or mode & stat.S_IXUSR else 0o444)
        except PermissionError:
            pass


def _writable(folder: Path) -> None:
    for p in [folder, *folder.rglob("*")]:
        try:
            p.chmod(stat.S_IMODE(p.stat().st_mode) | stat.S_IWUSR)
        except OSError:
            pass


def forget(ref: PlannerRef) -> bool:
    """Remove the finished preparation of ``ref`` on this machine (``earthbench prepare --again``)."""
    path = root() / prepare_key(ref)
    if not path.exists():
        return False
    _writable(path)
    shutil.rmtree(path, ignore_errors=True)
    return True

