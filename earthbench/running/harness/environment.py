"""The environment stamp of a run: machine, software, and the builds of earthbench and the plugin.

Computed where the case ran (on a Dask worker: there) and cached per process. Which code ran
comes from :mod:`earthbench.results.provenance` (the commit written into the package at build time, the
plugin's distribution), never from the git of a directory at run time.
"""

from __future__ import annotations

import functools
import os
import platform
import socket
from importlib import metadata
from pathlib import Path
from typing import Any

from ...results import provenance


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
    build = provenance.build()
    return {
        "hostname": socket.gethostname(),
        "cpu_model": cpu,
        "cores": os.cpu_count(),
        "os": platform.platform(),
        "python": platform.python_version(),
        "packages": packages,
        "project_commit": provenance.commit_text(build),
        "earthbench_version": build["version"],
    }


@functools.lru_cache(maxsize=64)
def environment(planner_source: str = "") -> dict[str, Any]:
    """Machine, software and commits of where a case ran (computed there, cached per process)."""
    env = dict(_machine())
    env["packages"] = dict(env["packages"])
    plugin = provenance.plugin(planner_source) if planner_source else None
    if plugin and plugin.get("name") and plugin.get("version"):
        env["packages"][plugin["name"]] = plugin["version"]
    env["plugin"] = plugin
    env["plugin_commit"] = plugin.get("commit") if plugin else None
    return env


def cache_folder(env: str, leaf: str) -> Path:
    """Where this machine keeps one of earthbench's caches: ``$env`` when set, else
    ``$XDG_CACHE_HOME/earthbench/leaf`` (``~/.cache`` without it)."""
    chosen = os.environ.get(env, "").strip()
    if chosen:
        return Path(chosen).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "earthbench" / leaf
