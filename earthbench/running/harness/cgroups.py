"""A case's own cgroup: one interface, :class:`CaseCgroup`, and a subclass per kernel hierarchy.

The harness creates one cgroup per case under its own (docs/DESIGN.md §6 "Isolation"): the
memory limit of the whole process tree (no swap), the slot's cores as a cpuset, a process cap;
it reads the CPU seconds, peak memory, OOM kills and process count the kernel counts, freezes
the case between closed-loop steps, and at the end kills what is left and removes the folders.
:class:`CgroupV1` works on the v1 controllers (memory, cpuset, cpuacct, freezer, pids, each a
folder of its own), :class:`CgroupV2` on the unified hierarchy (one folder, ``cgroup.freeze``
and ``cgroup.kill``); :meth:`CaseCgroup.create` picks one by its version, ``v1`` or ``v2``.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import itertools
import os
import signal
import time
from abc import ABC, abstractmethod
from collections.abc import Sequence

#: The v1 controllers a case's cgroup needs.
V1_CONTROLLERS = ("memory", "cpuset", "cpuacct", "freezer", "pids")
#: The v2 controllers a case's cgroup needs (the freezer is built into v2).
V2_CONTROLLERS = ("memory", "cpuset", "cpu", "pids")
#: Processes a case may hold at once (a fork bomb ends there, not at the machine's limit).
PIDS_MAX = 1024
_counter = itertools.count()


def _write(path: str, value: str) -> None:
    with open(path, "w") as f:
        f.write(value)


def _read(path: str) -> str:
    with open(path) as f:
        return f.read()


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


def probe() -> tuple[str | None, str]:
    """The cgroup version this process can create and fill a case cgroup in, or None and why not."""
    tried = []
    for version, cls in (("v1", CgroupV1), ("v2", CgroupV2)):
        if cls.bases() is None:
            continue
        try:
            CaseCgroup.create(version, cores=(), memory_bytes=64 * 2**20).remove()
            return version, ""
        except OSError as exc:
            tried.append(f"{version}: {exc.strerror} ({exc.filename})")
    if not tried:
        return None, ("no cgroup with the memory, cpuset, CPU and pids controllers for this process "
                      "(v1 controllers, or a delegated v2 subtree)")
    return None, "cannot create a case cgroup (" + "; ".join(tried) + ")"


class CaseCgroup(ABC):
    """One case's cgroup: its limits, the figures the kernel counts, freeze, kill, remove.

    The interface the sandbox uses; :class:`CgroupV1` and :class:`CgroupV2` say how each
    hierarchy does it."""

    version = ""

    def __init__(self, dirs: dict[str, str]):
        self.dirs = dirs  # controller (or "" for v2) -> folder
        self.pids_peak = 0

    @staticmethod
    def create(version: str, cores: Sequence[int], memory_bytes: int, pids_max: int = PIDS_MAX) -> CaseCgroup:
        """A new case cgroup of ``version`` (``v1``, ``v2``) under this process's own, with its limits set."""
        cls: type[CaseCgroup] = CgroupV1 if version == "v1" else CgroupV2
        bases = cls.bases()
        assert bases is not None
        cls.prepare_bases(bases)
        _clear_stale(tuple(bases.values()))
        name = f"earthbench-{os.getpid()}-{next(_counter)}"
        cg = cls({})
        try:
            for c, b in bases.items():
                os.mkdir(os.path.join(b, name))
                cg.dirs[c] = os.path.join(b, name)
            cg.limit(",".join(map(str, cores)), memory_bytes, pids_max)
        except BaseException:
            cg.remove()
            raise
        return cg

    # -- what each hierarchy says its own way ------------------------------------------------
    @classmethod
    @abstractmethod
    def bases(cls) -> dict[str, str] | None:
        """This process's own cgroup folder per controller, or None when the hierarchy lacks one."""

    @classmethod
    def prepare_bases(cls, bases: dict[str, str]) -> None:
        """Make the folders under ``bases`` able to hold a case's controllers (nothing to do by default)."""
        return None

    @abstractmethod
    def limit(self, cpus: str, memory_bytes: int, pids_max: int) -> None:
        """Pin the case to ``cpus`` and cap its memory and its number of processes."""

    @abstractmethod
    def control(self, ctrl: str, name: str) -> str:
        """The path of the control file ``name`` of controller ``ctrl``."""

    @abstractmethod
    def cpu_s(self) -> float:
        """CPU seconds (user + system) of every process the case ever had, counted by the kernel."""

    @abstractmethod
    def freeze(self, frozen: bool = True, timeout: float = 2.0, wait: bool = True) -> bool:
        """Stop (or restart) every process of the case; True once the kernel says it is done.

        ``wait=False`` asks and returns: a process stops at its next return to user space
        whether or not anyone waits for it (the closed loop does not wait, so a step costs no
        polling)."""

    @abstractmethod
    def kill_all(self) -> None:
        """Ask the kernel to SIGKILL every process of the case (it may take a moment)."""

    peak_file = ""
    oom_file = ""
    procs_ctrl = ""

    # -- the same for both ---------------------------------------------------------------------
    def join(self, pid: int) -> None:
        """Move ``pid`` into the case's cgroup (every controller); its later children are born there."""
        for d in self.dirs.values():
            _write(os.path.join(d, "cgroup.procs"), str(pid))

    def procs(self) -> list[int]:
        try:
            return [int(x) for x in _read(os.path.join(self.dirs[self.procs_ctrl], "cgroup.procs")).split()]
        except (OSError, ValueError):
            return []

    def peak_bytes(self) -> int:
        """The case tree's peak memory (resident, its tmpfs, the page cache it brought in)."""
        try:
            return int(_read(self.control("memory", self.peak_file)))
        except (OSError, ValueError):
            return 0

    def oom_kills(self) -> int:
        """Processes the kernel killed for the case's memory limit."""
        try:
            for line in _read(self.control("memory", self.oom_file)).splitlines():
                if line.startswith("oom_kill "):
                    return int(line.split()[1])
        except (OSError, ValueError):
            pass
        return 0

    def sample_pids(self) -> int:
        """The process count now (the peak is the largest sample, or the kernel's where it keeps one)."""
        try:
            now = int(_read(self.control("pids", "pids.current")))
        except (OSError, ValueError):
            return 0
        self.pids_peak = max(self.pids_peak, now)
        return now

    def kill(self, timeout: float = 5.0) -> bool:
        """SIGKILL every process of the case (frozen first, so none forks away); True when empty."""
        end = time.monotonic() + timeout
        self.kill_all()
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


class CgroupV1(CaseCgroup):
    """A case cgroup on the v1 controllers: one folder per controller."""

    version = "v1"
    peak_file, oom_file, procs_ctrl = "memory.max_usage_in_bytes", "memory.oom_control", "pids"

    @classmethod
    def bases(cls) -> dict[str, str] | None:
        own = _own_cgroups()
        bases = {}
        for ctrl in V1_CONTROLLERS:
            mount = next((m for m, kind, opts in _mounts() if kind == "cgroup" and ctrl in opts), None)
            if mount is None or ctrl not in own:
                return None
            bases[ctrl] = os.path.join(mount, own[ctrl].lstrip("/"))
        return bases

    def control(self, ctrl: str, name: str) -> str:
        return os.path.join(self.dirs[ctrl], name)

    def limit(self, cpus: str, memory_bytes: int, pids_max: int) -> None:
        parent = os.path.dirname(self.dirs["cpuset"])
        _write(self.control("cpuset", "cpuset.cpus"), cpus or _read(os.path.join(parent, "cpuset.cpus")).strip())
        _write(self.control("cpuset", "cpuset.mems"), _read(os.path.join(parent, "cpuset.mems")).strip())
        if memory_bytes > 0:
            _write(self.control("memory", "memory.limit_in_bytes"), str(memory_bytes))
            with contextlib.suppress(OSError):  # without swap accounting there is no memsw file
                _write(self.control("memory", "memory.memsw.limit_in_bytes"), str(memory_bytes))
        _write(self.control("pids", "pids.max"), str(pids_max))

    def cpu_s(self) -> float:
        try:
            return int(_read(self.control("cpuacct", "cpuacct.usage"))) / 1e9
        except (OSError, ValueError):
            return 0.0

    def freeze(self, frozen: bool = True, timeout: float = 2.0, wait: bool = True) -> bool:
        path, want = self.control("freezer", "freezer.state"), "FROZEN" if frozen else "THAWED"
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

    def kill_all(self) -> None:
        self.freeze(True, timeout=1.0)
        for pid in self.procs():
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)
        self.freeze(False, timeout=1.0)


class CgroupV2(CaseCgroup):
    """A case cgroup on the unified (v2) hierarchy: one folder, its freezer and kill switch built in."""

    version = "v2"
    peak_file, oom_file, procs_ctrl = "memory.peak", "memory.events", ""

    @classmethod
    def bases(cls) -> dict[str, str] | None:
        own = _own_cgroups()
        mount = next((m for m, kind, _ in _mounts() if kind == "cgroup2"), None)
        if mount is None or "" not in own:
            return None
        base = os.path.join(mount, own[""].lstrip("/"))
        try:
            have = set(_read(os.path.join(base, "cgroup.controllers")).split())
        except OSError:
            return None
        return {"": base} if set(V2_CONTROLLERS) <= have else None

    @classmethod
    def prepare_bases(cls, bases: dict[str, str]) -> None:
        """Let the children of the base have the controllers a case needs (v2's no-internal-process
        rule: if the base holds processes, they move to a leaf ``earthbench-harness-PID`` first)."""
        base = bases[""]
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

    def control(self, ctrl: str, name: str) -> str:
        return os.path.join(self.dirs[""], name)

    def limit(self, cpus: str, memory_bytes: int, pids_max: int) -> None:
        if cpus:
            _write(self.control("cpuset", "cpuset.cpus"), cpus)
        if memory_bytes > 0:
            _write(self.control("memory", "memory.max"), str(memory_bytes))
            with contextlib.suppress(OSError):
                _write(self.control("memory", "memory.swap.max"), "0")
        _write(self.control("pids", "pids.max"), str(pids_max))

    def cpu_s(self) -> float:
        try:
            for line in _read(self.control("cpu", "cpu.stat")).splitlines():
                if line.startswith("usage_usec "):
                    return int(line.split()[1]) / 1e6
        except (OSError, ValueError):
            pass
        return 0.0

    def sample_pids(self) -> int:
        now = super().sample_pids()
        with contextlib.suppress(OSError, ValueError):
            self.pids_peak = max(self.pids_peak, int(_read(self.control("pids", "pids.peak"))))
        return now

    def freeze(self, frozen: bool = True, timeout: float = 2.0, wait: bool = True) -> bool:
        try:
            _write(self.control("", "cgroup.freeze"), "1" if frozen else "0")
            if not wait:
                return True
            end = time.monotonic() + timeout
            while f"frozen {int(frozen)}" not in _read(self.control("", "cgroup.events")):
                if time.monotonic() > end:
                    return False
                time.sleep(0.0005)
        except OSError:
            return False
        return True

    def kill_all(self) -> None:
        if os.path.exists(self.control("", "cgroup.kill")):
            with contextlib.suppress(OSError):
                _write(self.control("", "cgroup.kill"), "1")
        else:  # kernels before 5.14: as v1 does
            self.freeze(True, timeout=1.0)
            for pid in self.procs():
                with contextlib.suppress(OSError):
                    os.kill(pid, signal.SIGKILL)
            self.freeze(False, timeout=1.0)


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


def descendants(pid: int) -> list[int]:
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
