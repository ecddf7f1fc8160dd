"""Which code ran: the build of the installed earthbench and the distribution of a planner plugin.

The stamp of every run names the code, never a working directory's git (issue 35: a checkout's
HEAD at run time named code that was not installed):

* :func:`build` — earthbench's version and the commit it was built from, written into the package
  at build time (``earthbench/build_info.py``, by ``setup.py``'s build step) with a dirty flag.
  An editable install runs its checkout, so there the checkout's own commit (and whether its
  tracked files differ) is the code's;
* :func:`plugin` — a planner's distribution name, version and, where pip recorded one
  (``direct_url.json``: ``pip install git+…`` or a VCS checkout), its source commit; a plugin
  loaded from a file is named by the file and the SHA-256 of its text.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import json
import subprocess
from importlib import metadata
from pathlib import Path
from typing import Any

from .. import __version__


def _direct_url(dist: str) -> dict[str, Any]:
    try:
        return json.loads(metadata.distribution(dist).read_text("direct_url.json") or "{}")
    except (metadata.PackageNotFoundError, ValueError):
        return {}


def _checkout_commit(directory: Path) -> tuple[str | None, bool | None]:
    """HEAD of the checkout holding ``directory`` and whether its tracked files differ (editable installs only)."""
    try:
        head = subprocess.run(["git", "-C", str(directory), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5)
        if head.returncode != 0:
            return None, None
        status = subprocess.run(["git", "-C", str(directory), "status", "--porcelain", "--untracked-files=no"],
                                capture_output=True, text=True, timeout=10)
        return head.stdout.strip(), bool(status.stdout.strip())
    except (OSError, subprocess.SubprocessError):
        return None, None


@functools.lru_cache(maxsize=1)
def build() -> dict[str, Any]:
    """``version``, ``commit`` (None: unknown), ``dirty`` and ``how`` (``built``, ``editable`` or ``source``)."""
    try:
        from .. import build_info  # type: ignore[attr-defined]  # generated at build time, absent in a checkout
    except ImportError:
        build_info = None
    if build_info is not None:
        return {"version": __version__, "commit": build_info.COMMIT, "dirty": build_info.DIRTY, "how": "built"}
    editable = bool(_direct_url("earthbench").get("dir_info", {}).get("editable"))
    commit, dirty = _checkout_commit(Path(__file__).resolve().parent)
    return {"version": __version__, "commit": commit, "dirty": dirty, "how": "editable" if editable else "source"}


def commit_text(info: dict[str, Any]) -> str | None:
    """``<commit>`` or ``<commit>+dirty`` (the stored ``project_commit``), None when unknown."""
    if not info.get("commit"):
        return None
    return str(info["commit"]) + ("+dirty" if info.get("dirty") else "")


def build_text(version: Any, commit: Any) -> str:
    """How a stamp names one build: ``earthbench 1.2.0 (commit 0123abcd, +dirty)``."""
    c = str(commit) if commit and str(commit) != "nan" else ""
    dirty = c.endswith("+dirty")
    c = c.removesuffix("+dirty")
    where = f"commit {c[:12]}" + (", uncommitted changes" if dirty else "") if c else "commit unknown"
    return f"earthbench {version if version and str(version) != 'nan' else '?'} ({where})"


@functools.lru_cache(maxsize=64)
def plugin(source: str) -> dict[str, Any] | None:
    """The distribution (``name``, ``version``, ``commit``) of a planner's ``module:Class`` source, or
    the ``file`` and ``sha256`` of a plugin file; None when neither can be found."""
    if source.endswith(".py") or ".py:" in source:
        path = Path(source.split(":", 1)[0] if ".py:" in source else source)
        try:
            return {"file": path.name, "sha256": hashlib.sha256(path.read_bytes()).hexdigest()}
        except OSError:
            return {"file": path.name, "sha256": None}
    module = source.split(":", 1)[0]
    if not module:
        return None
    top = module.split(".", 1)[0]
    dists = metadata.packages_distributions().get(top, [])
    if not dists:
        try:
            spec = importlib.util.find_spec(module)
        except (ImportError, ValueError):
            spec = None
        return {"module": module, "file": spec.origin if spec else None} if spec else None
    name = dists[0]
    try:
        version: str | None = metadata.version(name)
    except metadata.PackageNotFoundError:
        version = None
    if name == "earthbench":  # the built-in planners: the build of earthbench itself
        return {"name": name, "version": version, "commit": commit_text(build())}
    vcs = _direct_url(name).get("vcs_info", {})
    return {"name": name, "version": version, "commit": vcs.get("commit_id")}
