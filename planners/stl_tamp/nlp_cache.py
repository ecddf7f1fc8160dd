"""A disk cache of built NLPs: one file per NLP content, shared by every case process.

Each case runs in a fresh process, and building the CasADi graphs and derivatives of one NLP
costs seconds (planners/stl_tamp/NOTES.md). The build depends only on the NLP's content, so its result
(CasADi's serialization of the built functions, written and read as a file stream, which keeps
the memory low) is stored once per machine under a key that hashes everything it depends on,
and loaded by every later process.

Files are written to a temporary name and renamed into place, so two workers building the same
NLP at once each leave a complete file and a reader never sees a partial one; a file ends in the
sha256 of what precedes it, and one that fails it is a miss (the caller rebuilds and overwrites it). Any
error of the cache itself (no home, a read-only or full disk) makes it a miss, never a failed
plan. The directory is ``$EARTHBENCH_NLP_CACHE`` (``off`` disables the cache), else
``$XDG_CACHE_HOME/earthbench/nlp`` (default ``~/.cache/earthbench/nlp``).
"""

from __future__ import annotations

import hashlib
import os
import platform
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

ENV = "EARTHBENCH_NLP_CACHE"
_TRAILER = b"\nearthbench-nlp/1 sha256 "


def directory() -> Path | None:
    """Where the cache lives, or None when ``$EARTHBENCH_NLP_CACHE`` is ``off``."""
    env = os.environ.get(ENV)
    if env is not None and env.strip():
        return None if env.strip().lower() == "off" else Path(env).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "earthbench" / "nlp"


def key(*parts: object) -> str:
    """The hash of ``parts`` (their ``repr``) and of what else a built NLP depends on: the CasADi
    version, the Python version and machine type, and the source of the modules that build it."""
    import casadi

    h = hashlib.sha256()
    for part in (*parts, casadi.__version__, sys.version_info[:2], platform.machine(), sys.byteorder):
        h.update(repr(part).encode())
        h.update(b"\0")
    here = Path(__file__).resolve().parent
    for name in ("model.py", "graph.py", "staged.py", "stl.py", "problem.py", "nlp_cache.py"):
        h.update((here / name).read_bytes())
    return h.hexdigest()[:32]


def _digest(f, size: int) -> str:
    h = hashlib.sha256()
    while size > 0:
        chunk = f.read(min(1 << 20, size))
        if not chunk:
            break
        h.update(chunk)
        size -= len(chunk)
    return h.hexdigest()


def load(name: str) -> Path | None:
    """The stored file of ``name``, checked whole, or None (no cache, no file, a damaged one)."""
    d = directory()
    if d is None:
        return None
    path = d / f"{name}.nlp"
    tail = len(_TRAILER) + 64
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size - tail
            if size < 0 or _TRAILER + _digest(f, size).encode() != f.read():
                return None
    except OSError:
        return None
    return path


def save(name: str, write: Callable[[str], None]) -> bool:
    """Store what ``write(path)`` writes to ``path`` under ``name``, atomically; False when the
    cache is off or unwritable (``write`` may raise OSError or RuntimeError for a full disk)."""
    d = directory()
    if d is None:
        return False
    tmp = None
    try:
        d.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=d, prefix=f".{name}.", suffix=".tmp")
        os.close(fd)
        write(tmp)
        with open(tmp, "r+b") as f:
            digest = _digest(f, os.fstat(f.fileno()).st_size)
            f.seek(0, os.SEEK_END)
            f.write(_TRAILER + digest.encode())
        os.chmod(tmp, 0o644)  # readable by a sandboxed case, which runs as another user (docs/isolation.md)
        os.replace(tmp, d / f"{name}.nlp")
        return True
    except (OSError, RuntimeError):
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass
        return False
