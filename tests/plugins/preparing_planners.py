"""Planners with a preparation (docs/DESIGN.md §6 "Preparation"), for tests/test_prepare.py."""

from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import dataclass

from earthbench.plan import Plan, Prediction
from earthbench.planner import Planner


@dataclass(frozen=True)
class Config:
    token: str = "a"


class Prepares(Planner):
    """Writes a token and the process's view (jobs, pid, affinity) into its folder (the one place
    it may write: in a sandbox, nothing else is writable);
    its plan reports what it finds there and whether it can write there."""

    name = "t-prepares"
    Config = Config

    def prepare(self, folder, jobs=1):
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "token.txt").write_text(self.config.token)
        (folder / "seen.json").write_text(json.dumps({"jobs": jobs, "affinity": sorted(os.sched_getaffinity(0)),
                                                      "pid": os.getpid(), "argv": sys.argv}))
        return {"wrote": ["token.txt", "seen.json"]}

    def plan(self, scenario):
        folder = self.prepared
        token = (folder / "token.txt").read_text() if folder is not None else None
        try:
            with open(folder / "token.txt", "a"):
                writable = True
        except OSError:
            writable = False
        return Plan(predicted=Prediction(volume=0.0, makespan=0.0),
                    info={"prepared": str(folder), "token": token, "writable": writable,
                          "mode": oct(os.stat(folder / "token.txt").st_mode & 0o777)})


class PrepareFails(Planner):
    name = "t-prepare-fails"

    def prepare(self, folder, jobs=1):
        raise RuntimeError("no compiler here")

    def plan(self, scenario):
        return Plan(predicted=Prediction(volume=0.0, makespan=0.0))


class PrepareSleeps(Planner):
    name = "t-prepare-sleeps"

    def prepare(self, folder, jobs=1):
        time.sleep(30)

    def plan(self, scenario):
        return Plan(predicted=Prediction(volume=0.0, makespan=0.0))


class PrepareSlow(Planner):
    """A preparation that takes a while (two processes that prepare it at once must not both run it)."""

    name = "t-prepare-slow"

    def prepare(self, folder, jobs=1):
        time.sleep(3.0)
        (folder / "done.txt").write_text(str(time.time()))
        return {"slept": 3.0}

    def plan(self, scenario):
        return Plan(predicted=Prediction(volume=0.0, makespan=0.0))


# -- hostile preparations: the folder a job leaves is data the harness must not trust ------------
def _victim() -> str:
    """A file of the host the test made (0600); only its path reaches the job, through the environment."""
    return os.environ.get("EARTHBENCH_TEST_VICTIM", "/nonexistent")


class _Hostile(Planner):
    def plan(self, scenario):
        return Plan(predicted=Prediction(volume=0.0, makespan=0.0))


class PrepareLinks(_Hostile):
    """Plants the manifest's name as a link to a host file (the harness would write through it) and a
    link to the victim key (a chmod through it would make it world-readable); and a dangling one."""

    name = "t-prep-links"

    def prepare(self, folder, jobs=1):
        (folder / "key").symlink_to(_victim())
        (folder / "prepare.json").symlink_to(_victim())
        (folder / "gone").symlink_to("/nonexistent/at/all")
        return {}


class PrepareFifo(_Hostile):
    """Leaves a FIFO: a harness that opened it would wait forever."""

    name = "t-prep-fifo"

    def prepare(self, folder, jobs=1):
        os.mkfifo(folder / "pipe")
        return {}


class PrepareHardLink(_Hostile):
    """Leaves a second name of one of its files (outside the sandbox it could be a host file)."""

    name = "t-prep-hardlink"

    def prepare(self, folder, jobs=1):
        (folder / "a").write_text("a")
        os.link(folder / "a", folder / "b")
        return {}


class PrepareFloods(_Hostile):
    """Many files, each under the disk budget, more than it together; then waits to be caught."""

    name = "t-prep-flood"

    def prepare(self, folder, jobs=1):
        for i in range(6):
            (folder / f"part{i}").write_bytes(b"x" * 3 * 2**20)
        time.sleep(5)
        return {}


class PrepareBigFile(_Hostile):
    """One file larger than the disk budget (fallocate'd: no data written)."""

    name = "t-prep-bigfile"

    def prepare(self, folder, jobs=1):
        with open(folder / "big", "wb") as f:
            os.posix_fallocate(f.fileno(), 0, 64 * 2**20)
        return {}


# -- preparations that say how far they are (Planner.report_progress) -----------------------------
class PrepareReports(Planner):
    """Reports three steps, 0.3 s apart, with a name that tries to move the terminal's cursor, and
    a slip an honest planner can make (more done than in all), which the bootstrap mends."""

    name = "t-prepare-reports"

    def prepare(self, folder, jobs=1):
        for k in range(3):
            self.report_progress(k, 3, f"\x1b[2Jstep {k}\nof three")
            time.sleep(0.3)
        self.report_progress(4, 3, "done")
        return {"steps": 3}

    def plan(self, scenario):
        return Plan(predicted=Prediction(volume=0.0, makespan=0.0))


def _nonce() -> str | None:
    """The nonce of the job's input, dug out of the bootstrap's frames (as any code in the process can)."""
    frame = sys._getframe()
    while frame is not None:
        given = frame.f_locals.get("given")
        if isinstance(given, dict) and given.get("nonce"):
            return given["nonce"]
        frame = frame.f_back
    return None


def _raw(msg: dict) -> None:
    """A message written straight on the harness's pipe, past the bootstrap's checks."""
    os.write(int(sys.argv[1]), (json.dumps({**msg, "nonce": _nonce()}) + "\n").encode())


class PrepareFloodsProgress(Planner):
    """Writes 5,000 well-formed progress messages at once: the harness keeps ten a second."""

    name = "t-prepare-floods"

    def prepare(self, folder, jobs=1):
        for k in range(5000):
            _raw({"event": "progress", "done": k, "total": 5000, "what": "flood"})
        time.sleep(0.5)
        return {}

    def plan(self, scenario):
        return Plan(predicted=Prediction(volume=0.0, makespan=0.0))


class PrepareBadProgress(Planner):
    """Writes the progress message its configuration names, past the bootstrap's checks."""

    name = "t-prepare-bad-progress"

    @dataclass(frozen=True)
    class Config:
        kind: str = "types"

    def prepare(self, folder, jobs=1):
        msg = {"types": {"done": "1", "total": 3}, "order": {"done": 4, "total": 3},
               "huge": {"done": 1, "total": 3, "what": "x" * 5000}, "nonce": {"done": 1, "total": 3}}[self.config.kind]
        if self.config.kind == "nonce":
            os.write(int(sys.argv[1]), (json.dumps({"event": "progress", **msg, "nonce": "0" * 32}) + "\n").encode())
        else:
            _raw({"event": "progress", **msg})
        time.sleep(2.0)
        return {}

    def plan(self, scenario):
        return Plan(predicted=Prediction(volume=0.0, makespan=0.0))


class PlanReportsProgress(Planner):
    """A case (not a preparation) that sends a progress message: a protocol fault."""

    name = "t-plan-progress"

    def plan(self, scenario):
        _raw({"event": "progress", "done": 1, "total": 2, "what": "planning"})
        time.sleep(2.0)
        return Plan(predicted=Prediction(volume=0.0, makespan=0.0))
