"""The environment stamp of a run: machine, software, and the commits of the project and plugin.

Computed where the case ran (on a Dask worker: there) and cached per process.
"""

from __future__ import annotations

import functools
import importlib.util
import json
import os
import platform
import socket
import subprocess
from importlib import metadata
from pathlib import Path
from typing import Any


@functools.lru_cache(maxsize=64)
def _git_commit(directory: str) -> str | None:
    try:
        head = subprocess.run(["git", "-C", directory, "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5)
        if head.returncode != 0:
            return None
        dirty = subprocess.run(
            ["git", "-C", directory, "status", "--porcelain", "--untracked-files=no", "--", "."],
            capture_output=True, text=True, timeout=10,
        )
        return head.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return None


@functools.lru_cache(maxsize=1)
def _machine() -> dict[str, Any]:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    packages = {}
    for dist in ("earthbench", "numpy", "scipy", "shapely", "pandas", "casadi", "cvxpy", "psutil"):
        try:
            packages[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            pass
    commit = _git_commit(str(Path(__file__).resolve().parent.parent))
    if commit is None:  # installed with `pip install .`: the checkout it came from, if pip recorded it
        try:
            url = json.loads(metadata.distribution("earthbench").read_text("direct_url.json") or "{}").get("url", "")
            if url.startswith("file://"):
                commit = _git_commit(url[len("file://"):])
        except (metadata.PackageNotFoundError, ValueError):
            pass
    return {
        "hostname": socket.gethostname(),
        "cpu_model": cpu,
        "cores": os.cpu_count(),
        "os": platform.platform(),
        "python": platform.python_version(),
        "packages": packages,
        "project_commit": commit,
    }


@functools.lru_cache(maxsize=64)
def environment(planner_source: str = "") -> dict[str, Any]:
    """Machine, software and commits of where a case ran (computed there, cached per process)."""
    env = dict(_machine())
    env["packages"] = dict(env["packages"])
    where: str | None = None
    if planner_source.endswith(".py"):
        where = planner_source
    elif ":" in planner_source:
        module = planner_source.split(":", 1)[0]
        try:
            spec = importlib.util.find_spec(module)
            where = spec.origin if spec else None
        except (ImportError, ValueError):
            where = None
        top = module.split(".", 1)[0]
        for dist in metadata.packages_distributions().get(top, []):
            try:
                env["packages"][dist] = metadata.version(dist)
            except metadata.PackageNotFoundError:
                pass
    env["plugin_commit"] = _git_commit(str(Path(where).resolve().parent)) if where else None
    return env
