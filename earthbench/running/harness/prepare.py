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

The folder a job leaves is hostile data (the job ran plugin code; the harness may be root):
:func:`_seal` follows no link and opens nothing but plain files and folders (a link, FIFO,
socket, device or hard link is refused), counts it against the budget's ``prepare_disk_mb``
and :data:`MAX_FILES` (bounded while it writes, too: ``RLIMIT_FSIZE`` per file and a look every
second), and makes it read-only through the descriptors it opened; the manifest is created
beside it, never through a name the job could have planted. Two processes never prepare one
key at once: a lock file per key makes the second wait and then use the first's folder.
"""

from __future__ import annotations

import errno
import fcntl
import functools
import hashlib
import json
import os
import platform
import shutil
import signal
import stat
import subprocess
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

from ...errors import EarthbenchError
from ...planner import PrepareProgress
from ...registry import OWN_DISTRIBUTION
from ...world import Budget
from ...results.records import Case, CaseResult, PlannerRef, utc_now
from .cases import Prepared
from .environment import cache_folder

ENV = "EARTHBENCH_PREPARED"
#: ``EARTHBENCH_PREPARE=off``: no preparation is run or used; cases run without their planner's
#: folder (a planner must work without it, with the same plans: e.g. by loading uncompiled what it
#: would have compiled) and their runs store no preparation time.
SWITCH = "EARTHBENCH_PREPARE"
MANIFEST = "prepare.json"
#: The most files and folders a preparation may leave (with ``prepare_disk_mb``, its disk budget).
MAX_FILES = 20_000
#: The deepest a preparation's folders may nest.
MAX_DEPTH = 64


class PrepareError(EarthbenchError):
    """A planner's preparation failed (its error, a timeout, a crash): its cases are not run."""


@dataclass(frozen=True)
class PrepareStatus:
    """A running preparation, for a display: the planner, what it last said of its progress
    (``Planner.report_progress``, checked as hostile data; None: nothing yet), the harness's
    seconds since it started, and an estimate of the seconds left (None: no ground for one)."""

    planner: str
    progress: PrepareProgress | None
    elapsed_s: float
    left_s: float | None


def estimate(progress: PrepareProgress | None, elapsed_s: float, last_s: float | None) -> float | None:
    """Seconds a preparation has left: from the last recorded preparation of the planner on this
    machine while it has not been outrun (steps may differ widely in cost, the whole does not),
    else from the share of steps done so far; None without either."""
    if last_s is not None and elapsed_s < last_s:
        return last_s - elapsed_s
    if progress is not None and progress.total > 0 and progress.done > 0:
        return elapsed_s * (progress.total - progress.done) / progress.done
    return None


def last_recorded(name: str) -> float | None:
    """The wall seconds of the latest finished preparation of planner ``name`` on this machine
    (any version or configuration: the harness's own measurement, from its manifest), or None."""
    best: tuple[str, float] | None = None
    try:
        folders = [p for p in root().iterdir() if p.name.startswith(f"{name}-") and not p.name.startswith(".")]
    except OSError:
        return None
    for folder in folders:
        try:
            doc = json.loads((folder / MANIFEST).read_text())
            when, wall = str(doc["started_at"]), float(doc["wall_s"])
        except (OSError, ValueError, KeyError, TypeError):
            continue
        if doc.get("planner") == name and (best is None or when > best[0]):
            best = (when, wall)
    return best[1] if best is not None else None


def root() -> Path:
    """Where preparations are kept (see the module's docstring)."""
    return cache_folder(ENV, "prepared")


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
           stop: threading.Event | None = None, log: Callable[[str], None] | None = None,
           on_progress: Callable[[PrepareStatus], None] | None = None) -> Prepared | None:
    """The preparation of ``ref`` on this machine: found on disk, or run now (once per process
    and key; concurrent callers wait for it). None when the planner declares none or
    ``$EARTHBENCH_PREPARE`` is ``off``. ``log`` hears when it starts and ends, ``on_progress``
    how far it is while it runs (:class:`PrepareStatus`). Raises :class:`PrepareError` when it fails."""
    if not ref.prepares or os.environ.get(SWITCH, "").strip().lower() == "off":
        return None
    key = prepare_key(ref)
    found = find(ref)  # a finished folder appears whole (renamed into place): no lock needed to use it
    if found is not None:
        return found
    with _LOCKS_LOCK:
        lock = _LOCKS.setdefault(key, threading.Lock())
    with lock, _key_lock(key, ref, stop, log):
        found = find(ref)
        if found is not None:
            return found
        if key in _FAILED:  # one attempt per process: the next cases fail at once with its error
            raise PrepareError(_FAILED[key])
        if log is not None:
            last = last_recorded(ref.name)
            log(f"preparing {ref.name} {ref.version} (config {ref.config_hash}) on this machine: "
                f"up to {budget.prepare_s:g} s, {budget.prepare_memory_mb} MB of memory and {budget.prepare_disk_mb} MB of disk"
                + (f" (the last preparation of {ref.name} here took {last:.0f} s)" if last is not None else ""))
        try:
            done = _run(ref, budget, cores, stop=stop, on_progress=on_progress)
        except PrepareError as exc:
            if "interrupted" not in str(exc):
                _FAILED[key] = str(exc)
            raise
        if log is not None:
            log(f"prepared {ref.name} in {done.wall_s:.1f} s ({done.cpu_s:.1f} s CPU): {done.path}")
        return done


@contextmanager
def _key_lock(key: str, ref: PlannerRef, stop: threading.Event | None = None,
              log: Callable[[str], None] | None = None) -> Iterator[None]:
    """Hold the machine-wide lock of ``key`` (a lock file in :func:`root`): a second process that
    prepares the same key waits here, then finds the first one's folder."""
    try:
        root().mkdir(parents=True, exist_ok=True)
        fd = os.open(root() / f".{key}.lock", os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600)
    except OSError as exc:
        raise PrepareError(f"cannot create the preparation lock in {root()}: {exc.strerror}; set ${ENV}") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if log is not None:
                log(f"waiting for another process that is preparing {ref.name} {ref.version} on this machine "
                    f"(lock {root() / f'.{key}.lock'})")
            while True:
                if stop is not None and stop.is_set():
                    raise PrepareError(f"the preparation of {ref.name} was interrupted") from None
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    break
                except BlockingIOError:
                    time.sleep(0.2)
        yield
    finally:
        os.close(fd)  # and with it the lock


def run_prepared_case(case: Case, cores: Sequence[int], *, stop: threading.Event | None = None,
                      startup_s: float | None = None) -> CaseResult:
    """:func:`.run.run_case` after the case's planner is prepared on this machine (what every
    executor calls): a failed preparation is this case's ``error``, with its message."""
    from .run import STARTUP_S, run_case

    try:
        prepared = ensure(case.planner, case.scenario.budget, cores, stop=stop) if case.prepare else None
    except PrepareError as exc:
        return CaseResult.failure(case, "error", str(exc))
    return run_case(case, cores, stop=stop, startup_s=STARTUP_S if startup_s is None else startup_s, prepared=prepared)


def run(ref: PlannerRef, budget: Budget, cores: Sequence[int] | None = None, *,
        stop: threading.Event | None = None, on_progress: Callable[[PrepareStatus], None] | None = None) -> Prepared:
    """Run the preparation of ``ref`` now, in a fenced process (replacing a finished one)."""
    with _key_lock(prepare_key(ref), ref, stop):
        return _run(ref, budget, cores, stop=stop, on_progress=on_progress)


class _Reporter:
    """A running preparation's :class:`PrepareStatus` for ``on_progress``: at each progress message
    (checked by the sandbox) and, so a display keeps time when a planner says nothing, each second."""

    def __init__(self, ref: PlannerRef, on_progress: Callable[[PrepareStatus], None] | None):
        self.name, self.on_progress = ref.name, on_progress
        self.t0, self.last = time.monotonic(), last_recorded(ref.name) if on_progress is not None else None
        self.progress: PrepareProgress | None = None

    def __call__(self, p: PrepareProgress | None = None) -> None:
        if self.on_progress is None:
            return
        self.progress = p or self.progress
        elapsed = time.monotonic() - self.t0
        self.on_progress(PrepareStatus(self.name, self.progress, elapsed, estimate(self.progress, elapsed, self.last)))


def _run(ref: PlannerRef, budget: Budget, cores: Sequence[int] | None = None, *,
         stop: threading.Event | None = None, on_progress: Callable[[PrepareStatus], None] | None = None) -> Prepared:
    """:func:`run` with the key's lock held."""
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
    # to write its fresh, private output folder; _seal takes every write bit off afterwards
    out.chmod(0o777)
    started = utc_now()
    disk = budget.prepare_disk_mb * 2**20
    job_budget = Budget(wall_s=budget.prepare_s, cores=len(cores), memory_mb=budget.prepare_memory_mb,
                        prepare_disk_mb=budget.prepare_disk_mb)
    job = {"name": ref.name, "source": ref.source, "overrides": ref.overrides, "job": "prepare"}
    payload = json.dumps({"folder": str(out), "jobs": len(cores)}).encode() + b"\n"
    what = f"the preparation of {ref.name} {ref.version}"
    try:
        report = _Reporter(ref, on_progress)

        def watch() -> str:  # every second while it runs
            report()
            return _over_budget(out, disk, budget.prepare_disk_mb)

        o = run_job(job, payload, cores, job_budget, writable=str(out), stop=stop, reads=ref.reads,
                    on_progress=report if on_progress is not None else None, watch=watch)
        tail = o.log_tail
        if o.cancelled:
            raise PrepareError(f"the preparation of {ref.name} was interrupted")
        if o.done is None or o.done.get("outcome") != "prepared":
            why = (o.fault or (o.done or {}).get("error") or
                   (f"it ran past its budget of {budget.prepare_s:g} s" if o.timed_out else
                    f"it wrote a file larger than its disk budget of {budget.prepare_disk_mb} MB" if o.status == -signal.SIGXFSZ else
                    f"its process exited with status {o.status}"))
            last = why.strip().splitlines()[-1] if why.strip() else ""
            raise PrepareError(f"{what} failed: {last}" + (f"\n{tail}" if tail and not o.done else ""))
        doc = {"key": key, "planner": ref.name, "version": ref.version, "config_hash": ref.config_hash,
               "machine": machine_stamp(), "started_at": started, "wall_s": o.wall_s or 0.0,
               "cpu_s": o.cpu_s or 0.0, "peak_rss_mb": o.peak_rss_mb, "summary": json.loads(o.done["summary"])}
        try:
            _seal(out, what, disk, budget.prepare_disk_mb, json.dumps(doc, indent=1, sort_keys=True).encode())
        except OSError as exc:  # e.g. a folder it made unreadable: refused like any other
            raise PrepareError(f"{what} left what the harness cannot check ({exc.strerror}: {exc.filename}); "
                               "it was not used") from None
        if final.exists() or final.is_symlink():  # `run` of a key already prepared: replace it
            old = Path(_tmp_dir(root(), key + ".old"))
            os.rename(final, old / "prev")
            os.rename(out, final)
            _remove(old)
        else:
            os.rename(out, final)
    finally:
        if out.exists() or out.is_symlink():
            _remove(out)
    return Prepared(key, str(final), doc["wall_s"], doc["cpu_s"], doc["peak_rss_mb"], ran=True, summary=doc["summary"])


def _tmp_dir(parent: Path, key: str) -> str:
    import tempfile

    return tempfile.mkdtemp(prefix=f".{key}.", suffix=".tmp", dir=parent)


def _over_budget(folder: Path, disk_bytes: int, disk_mb: int) -> str:
    """While the job runs: why its folder is over the disk budget ('' while it is not). The walk
    stops at the budget, so it costs the harness at most :data:`MAX_FILES` entries."""
    used, count, todo = 0, 0, [str(folder)]
    while todo:
        try:
            with os.scandir(todo.pop()) as it:
                for entry in it:
                    count += 1
                    st = entry.stat(follow_symlinks=False)
                    used += max(st.st_size, st.st_blocks * 512)
                    if stat.S_ISDIR(st.st_mode):
                        todo.append(entry.path)
                    if used > disk_bytes or count > MAX_FILES:
                        return (f"the preparation wrote more than its disk budget of {disk_mb} MB and {MAX_FILES:,} files "
                                "(prepare_disk_mb in the suite's [budget])")
        except OSError:  # gone or unreadable meanwhile: the final check (_seal) decides
            continue
    return ""


def _seal(folder: Path, what: str, disk_bytes: int, disk_mb: int, manifest: bytes) -> None:
    """Check the job's output as hostile data and make it read-only, then add the manifest.

    Follows no link: every folder and file is opened with ``O_NOFOLLOW`` relative to its
    parent's descriptor (``O_NONBLOCK``: a FIFO cannot hold the harness), only plain files
    with one link and folders are accepted, their sizes and number are counted against the
    disk budget, and the modes are changed through the descriptors. Raises :class:`PrepareError`
    saying what was refused."""
    top = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW)
    try:
        tally = [0, 0]  # bytes, entries
        _seal_dir(top, "", what, tally, disk_bytes, disk_mb, 0)
        try:
            fd = os.open(MANIFEST, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o444, dir_fd=top)
        except FileExistsError:
            raise PrepareError(f"{what} left a file named {MANIFEST}, the harness's own name; it was not used") from None
        try:
            os.write(fd, manifest)
            os.fchmod(fd, 0o444)
        finally:
            os.close(fd)
        os.fchmod(top, 0o555)
        if not os.path.samestat(os.fstat(top), os.lstat(folder)):
            raise PrepareError(f"{what} replaced its output folder; it was not used")
    finally:
        os.close(top)


_KINDS = {stat.S_IFLNK: "a symbolic link", stat.S_IFIFO: "a FIFO", stat.S_IFSOCK: "a socket",
          stat.S_IFCHR: "a device", stat.S_IFBLK: "a device"}


def _seal_dir(dfd: int, where: str, what: str, tally: list[int], disk_bytes: int, disk_mb: int, depth: int) -> None:
    if depth > MAX_DEPTH:
        raise PrepareError(f"{what} left folders nested deeper than {MAX_DEPTH} ({where}); it was not used")
    for entry in os.scandir(dfd):
        name = f"{where}/{entry.name}" if where else entry.name
        st = entry.stat(follow_symlinks=False)
        tally[0] += max(st.st_size, st.st_blocks * 512)
        tally[1] += 1
        if tally[0] > disk_bytes or tally[1] > MAX_FILES:
            raise PrepareError(f"{what} left more than its disk budget of {disk_mb} MB and {MAX_FILES:,} files "
                               "(prepare_disk_mb in the suite's [budget]); it was not used")
        if name == MANIFEST:
            raise PrepareError(f"{what} left a file named {MANIFEST}, the harness's own name; it was not used")
        kind = stat.S_IFMT(st.st_mode)
        if kind not in (stat.S_IFDIR, stat.S_IFREG):
            raise PrepareError(f"{what} left {_KINDS.get(kind, 'a special file')} ({name}); only plain files and "
                               "folders are accepted, it was not used")
        if kind == stat.S_IFREG and st.st_nlink != 1:
            raise PrepareError(f"{what} left a hard link ({name}, {st.st_nlink} links); only plain files and "
                               "folders are accepted, it was not used")
        flags = os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | (os.O_DIRECTORY if kind == stat.S_IFDIR else 0)
        fd = os.open(entry.name, flags, dir_fd=dfd)
        try:
            now = os.fstat(fd)
            if (now.st_ino, now.st_dev, stat.S_IFMT(now.st_mode)) != (st.st_ino, st.st_dev, kind) or \
                    (kind == stat.S_IFREG and now.st_nlink != 1):
                raise PrepareError(f"{what} left {name}, which changed while it was checked; it was not used")
            if kind == stat.S_IFDIR:
                _seal_dir(fd, name, what, tally, disk_bytes, disk_mb, depth + 1)
            # readable by everyone, writable by no one: whichever user the sandbox runs a case as
            os.fchmod(fd, 0o555 if kind == stat.S_IFDIR or st.st_mode & stat.S_IXUSR else 0o444)
        finally:
            os.close(fd)


def _remove(folder: Path) -> None:
    """Remove a preparation folder (a finished one is read-only; a failed one may hold links):
    its folders are made writable through descriptors opened without following a link."""
    def writable(dfd: int) -> None:
        os.fchmod(dfd, 0o700)
        for entry in os.scandir(dfd):
            if entry.is_dir(follow_symlinks=False):
                try:  # a folder (not a link: no process of the job is left to swap it) the job made 0000
                    os.chmod(entry.name, 0o700, dir_fd=dfd)
                    fd = os.open(entry.name, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW, dir_fd=dfd)
                except OSError:
                    continue
                try:
                    writable(fd)
                finally:
                    os.close(fd)

    try:
        top = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW)
    except OSError as exc:
        if exc.errno in (errno.ELOOP, errno.ENOTDIR):  # a link or a file where the folder was: only the name goes
            os.unlink(folder)
        return
    try:
        writable(top)
    except OSError:
        pass
    finally:
        os.close(top)
    shutil.rmtree(folder, ignore_errors=True)


def forget(ref: PlannerRef) -> bool:
    """Remove the finished preparation of ``ref`` on this machine (``earthbench prepare --again``)."""
    path = root() / prepare_key(ref)
    with _key_lock(prepare_key(ref), ref):
        if not (path.exists() or path.is_symlink()):
            return False
        _remove(path)
    return True
