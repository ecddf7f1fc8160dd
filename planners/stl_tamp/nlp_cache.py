"""A disk cache of built NLPs: one file per NLP content, shared by every case process.

Each case runs in a fresh process, and building the CasADi graphs and derivatives of one NLP
costs seconds (docs/DESIGN.md §11). The build depends only on the NLP's content, so its result
(serialized CasADi functions, zlib-compressed) is stored once per machine under a key that hashes
everything it depends on, and loaded by every later process.

Files are written to a temporary name and renamed into place, so two workers building the same
NLP at once each leave a complete file and a reader never sees a partial one; a file that fails
its checksum or does not decompress is a miss (the caller rebuilds and overwrites it). Any
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
import zlib
from pathlib import Path

ENV = "EARTHBENCH_NLP_CACHE"
_MAGIC = b"earthbench-nlp/1\n"


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
    for name in ("model.py", "stl.py", "problem.py", "nlp_cache.py"):
        h.update((here / name).read_bytes())
    return h.hexdigest()[:32]


def load(name: str) -> str | None:
    """The payload stored under ``name``, or None (no cache, no file, or a damaged one)."""
    d = directory()
    if d is None:
        return None
    try:
        blob = (d / f"{name}.nlp").read_bytes()
    except OSError:
        return None
    head = len(_MAGIC) + 64
    if not blob.startswith(_MAGIC) or len(blob) < head + 1:
        return None
    body = blob[head + 1:]
    if hashlib.sha256(body).hexdigest().encode() != blob[len(_MAGIC):head]:
        return None
    try:
        return zlib.decompress(body).decode()
    except (zlib.error, UnicodeDecodeError):
        return None


def save(name: str, payload: str) -> bool:
    """Store ``payload`` under ``name`` atomically; False when the cache is off or unwritable."""
    d = directory()
    if d is None:
        return False
    body = zlib.compress(payload.encode(), 1)
    tmp = None
    try:
        d.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=d, prefix=f".{name}.", suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            f.write(_MAGIC + hashlib.sha256(body).hexdigest().encode() + b"\n" + body)
        os.replace(tmp, d / f"{name}.nlp")
        return True
    except OSError:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass
        return False
