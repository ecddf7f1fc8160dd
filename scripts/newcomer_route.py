"""The README's route for a newcomer, timed: a fresh environment, the commands of the README's
steps 1–4 exactly as written (the last ranks the new planner beside the published board), then
every command those commands print for the user to run (``see: …``, ``next: …``), each as
printed, until none is left that has not run.

    python scripts/newcomer_route.py                    # a fresh clone and `pip install .` (minutes: the dependencies)
    python scripts/newcomer_route.py --reuse            # this interpreter's installs seen from a fresh venv (seconds)
    python scripts/newcomer_route.py --quick-start      # also the quick start's `earthbench run quick` (every
                                                        # built-in planner: stl-tamp's preparation takes minutes)

Prints one line per command (seconds, exit status, where it came from) and the totals; exit
status 1 when any command failed. ``tests/test_newcomer_route.py`` runs it with ``--reuse``
(a slow test), so a README step or a printed hint that does not run as written fails CI.
"""

from __future__ import annotations

import argparse
import os
import re
import shlex
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import time
import venv
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: A command the CLI prints for the user to run: ``earthbench`` and a command name, then its words up to two
#: spaces (an explanation follows), a semicolon, a backquote, a comma after a word ("…, then") or the line's end.
HINT = re.compile(r"\bearthbench ([a-z][a-z-]*(?: [^\s;(),`]+(?:,[^\s;(),`]+)*)*)")
#: Words of a printed command that stand for something the user fills in: such a command is not run.
PLACEHOLDERS = frozenset({"N", "RUN", "DIR", "PATH", "NAME", "SUITE", "FILE"})


def hints(text: str) -> list[str]:
    """Every command ``text`` tells the user to run (without placeholders), as printed: ``earthbench …``
    anywhere in a line, and every indented line of a block after a line ending ``next:`` (``pip …`` too)."""
    out, block = [], False
    for line in text.splitlines():
        if block and line.startswith("  ") and line.strip():
            command = re.split(r"\s{2,}\(", line.strip())[0]
            if not PLACEHOLDERS & set(shlex.split(command)):
                out.append(command)
            continue
        block = line.rstrip().endswith("next:")
        for m in HINT.finditer(line):
            if not PLACEHOLDERS & set(shlex.split(m.group(1))):
                out.append("earthbench " + m.group(1))
    return out


def readme_commands(readme: str, first: str = "## 1. ", last: str = "## The published boards") -> list[str]:
    """The shell commands of the README's steps (the ``bash`` blocks from ``first`` to ``last``), comments dropped."""
    part = readme[readme.index(first):readme.index(last)]
    out = []
    for block in re.findall(r"```bash\n(.*?)```", part, flags=re.S):
        for line in block.splitlines():
            line = re.split(r"\s{2,}#|^#", line)[0].strip()
            if line:
                out.append(line)
    return out


def quick_start(readme: str) -> list[str]:
    """The quick start's first command without its own environment (the route's environment is made here)."""
    block = re.search(r"## Quick start.*?```bash\n(.*?)```", readme, flags=re.S)
    assert block, "the README has no quick start block"
    first = next(line for line in block.group(1).splitlines() if line and not line.startswith("#"))
    return [c.strip() for c in first.split("&&") if "venv" not in c and "activate" not in c]


@dataclass
class Step:
    command: str
    source: str  # "README" or the command whose output printed it
    seconds: float = 0.0
    status: int = 0
    output: str = ""


@dataclass
class Route:
    workdir: Path  # where the commands ran: the clone, or the scratch folder with --reuse
    steps: list[Step] = field(default_factory=list)

    @property
    def failed(self) -> list[Step]:
        return [s for s in self.steps if s.status != 0]

    @property
    def seconds(self) -> float:
        return sum(s.seconds for s in self.steps)


def make_env(root: Path, reuse: bool) -> tuple[dict[str, str], Path]:
    """A fresh virtual environment (``--reuse``: seeing this interpreter's installs through a ``.pth``)
    and the working folder: a fresh clone of this repository's last commit, or a scratch folder."""
    env_dir = root / "venv"
    venv.EnvBuilder(with_pip=not reuse).create(env_dir)
    python = env_dir / "bin" / "python"
    if reuse:
        site = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                              capture_output=True, text=True, check=True).stdout.strip()
        # addsitedir, so this environment's own .pth files (an editable earthbench) run too
        Path(site, "route-reuse.pth").write_text(f"import site; site.addsitedir({sysconfig.get_paths()['purelib']!r})\n")
        for tool, module in (("pip", "pip"), ("earthbench", "earthbench")):  # the commands the README types, in this venv
            script = env_dir / "bin" / tool
            script.write_text(f'#!/bin/sh\nexec "{python}" -m {module} "$@"\n')
            script.chmod(0o755)
        work = root / "work"
        (work / "leaderboard").mkdir(parents=True)  # what step 4 reads from the clone: the published board's store
        shutil.copyfile(ROOT / "leaderboard" / "standard.db", work / "leaderboard" / "standard.db")
    else:
        work = root / "earthbench"
        subprocess.run(["git", "clone", "--quiet", str(ROOT), str(work)], check=True)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME", "EARTHBENCH_DB")}
    env.update(HOME=str(root), VIRTUAL_ENV=str(env_dir), PATH=f"{env_dir / 'bin'}{os.pathsep}{env['PATH']}")
    return env, work


def run_step(step: Step, env: dict[str, str], cwd: Path, timeout: float) -> Step:
    t0 = time.perf_counter()
    try:
        res = subprocess.run(["bash", "-c", step.command], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
        step.status, step.output = res.returncode, res.stdout + res.stderr
    except subprocess.TimeoutExpired as exc:
        step.status, step.output = 124, f"timed out after {timeout:g} s: {exc}"
    step.seconds = time.perf_counter() - t0
    return step


def walk(root: Path, *, reuse: bool, with_quick_start: bool = False, timeout: float = 900.0,
         say=print) -> Route:
    """Follow the README in a fresh environment under ``root``; every printed command once."""
    readme = (ROOT / "README.md").read_text()
    env, work = make_env(root, reuse)
    todo = [Step(c, "README") for c in (quick_start(readme) if with_quick_start else [] if reuse else ["pip install ."])]
    todo += [Step(c, "README") for c in readme_commands(readme)]
    route, seen = Route(work), set()
    while todo:
        step = todo.pop(0)
        if step.command in seen:
            continue
        seen.add(step.command)
        run_step(step, env, work, timeout)
        route.steps.append(step)
        say(f"{step.seconds:7.1f} s  exit {step.status:<3} {step.command}" + ("" if step.source == "README" else
                                                                           f"   (printed by: {step.source})"))
        if step.status != 0:
            say("    " + step.output.strip()[-1500:].replace("\n", "\n    "))
        if "earthbench " in step.command:  # what earthbench printed for the user to run next, before the README's next step
            todo[0:0] = [Step(h, step.command) for h in dict.fromkeys(hints(step.output)) if h not in seen]
    say(f"{route.seconds:7.1f} s  total, {len(route.steps)} commands ({sum(s.source != 'README' for s in route.steps)} "
        f"printed by earthbench), {len(route.failed)} failed")
    return route


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--reuse", action="store_true", help="see this interpreter's installs instead of installing (seconds)")
    p.add_argument("--quick-start", action="store_true", help="also the quick start's `earthbench run quick`")
    p.add_argument("--workdir", help="where the environment and clone go (default: a temporary folder, removed)")
    p.add_argument("--timeout", type=float, default=900.0, help="seconds one command may take (default 900)")
    args = p.parse_args(argv)
    if args.workdir:
        Path(args.workdir).mkdir(parents=True, exist_ok=True)
        route = walk(Path(args.workdir), reuse=args.reuse, with_quick_start=args.quick_start, timeout=args.timeout)
    else:
        with tempfile.TemporaryDirectory(prefix="earthbench-route-") as tmp:
            route = walk(Path(tmp), reuse=args.reuse, with_quick_start=args.quick_start, timeout=args.timeout)
    return 1 if route.failed else 0


if __name__ == "__main__":
    sys.exit(main())
