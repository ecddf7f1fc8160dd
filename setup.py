"""A build step that writes the commit the package is built from into it (``earthbench/build_info.py``).

Everything else about the build is in pyproject.toml. The stamp of every run reads the module
(:mod:`earthbench.results.provenance`), so a non-editable install names the code it holds, not whatever
a checkout beside it says later (issue 35). Built outside a git checkout (an sdist), the commit is
unknown and the module says so.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent


def _git(*args: str) -> str | None:
    try:
        out = subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True, timeout=20)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


class BuildPyWithCommit(build_py):
    """``build_py`` plus the generated ``build_info.py`` in the build tree (never in the checkout)."""

    def run(self) -> None:
        super().run()
        if getattr(self, "editable_mode", False):
            return  # an editable install runs the checkout itself: provenance reads the checkout then
        commit = _git("rev-parse", "HEAD")
        dirty = bool(_git("status", "--porcelain", "--untracked-files=no")) if commit else None
        target = Path(self.build_lib) / "earthbench" / "build_info.py"
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(
            '"""Generated at build time by setup.py: the commit this copy of earthbench was built from."""\n\n'
            f"COMMIT = {commit!r}\nDIRTY = {dirty!r}\n"
        )


setup(cmdclass={"build_py": BuildPyWithCommit})
