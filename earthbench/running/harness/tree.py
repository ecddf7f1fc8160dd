"""The process tree of one fenced job, as its supervisor sees it: the warden, the planner's
process and their descendants; their CPU seconds and memory, sampled (or read from the cgroup,
where the kernel counts them); how the tree is ended; the warden's last report.

:class:`ProcessTree` is the part of :class:`.supervisor.Supervisor` that deals with processes
(docs/DESIGN.md §6); the supervisor's own part is the protocol and the clock.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time

import psutil

from .cgroups import CaseCgroup
from .outcome import Outcome

#: Seconds the warden gets to end the case tree after SIGTERM before the harness kills it all.
TERM_GRACE_S = 2.0
#: Seconds between samples of the whole tree (descendants of the planner too).
TREE_SAMPLE_S = 1.0
#: The environment variable that tags every process of a case (for the last-resort sweep).
CASE_TAG = "EARTHBENCH_CASE"


class ProcessTree:
    """The process side of a supervisor: what it knows of the job's processes and how it ends them."""

    proc: subprocess.Popen
    warden: psutil.Process | None
    planner: psutil.Process | None
    sandboxed: bool
    cgroup: CaseCgroup | None
    tag: str
    report_fd: int
    report_buf: bytearray
    next_tree_sample: float
    o: Outcome

    def _tree(self) -> list[psutil.Process]:
        try:
            return self.warden.children(recursive=True) if self.warden is not None else []
        except psutil.Error:
            return []

    def _planner(self) -> psutil.Process | None:
        """The planner's process, by the pid its warden reported (no scan of the process table);
        None in a sandbox of its own (that pid is its PID namespace's, not ours)."""
        if self.sandboxed:
            return None
        if self.planner is None:
            self._read_report_pipe()
            first = self.report_buf.split(b"\n", 1)[0]
            try:
                self.planner = psutil.Process(int(json.loads(first)["planner"]))
            except (ValueError, KeyError, TypeError, psutil.Error):
                return None
        return self.planner

    def _tree_cpu(self) -> float:
        """CPU seconds the case's processes have used so far (the warden's own excluded, as in its report).

        The planner's process (with its reaped children) is read directly; only if its pid is
        not known is the whole tree scanned.
        """
        if self.cgroup is not None:
            return self.cgroup.cpu_s()
        planner = self._planner()
        total = 0.0
        for p in [planner] if planner is not None else self._tree():
            try:
                t = p.cpu_times()
            except psutil.Error:
                continue
            total += t.user + t.system + t.children_user + t.children_system
        return total

    def _sample(self, now: float) -> None:
        """Address space (what RLIMIT_AS caps) and resident memory, as we wait: the planner's process
        every :data:`SAMPLE_S`, the whole tree every :data:`TREE_SAMPLE_S` (a scan of the process table).
        With a cgroup the kernel keeps the peak itself; the process count is sampled."""
        if self.cgroup is not None:
            self.cgroup.sample_pids()
            return
        if now >= self.next_tree_sample:
            procs = self._tree()
            self.next_tree_sample = now + TREE_SAMPLE_S
        else:
            planner = self._planner()
            procs = [planner] if planner is not None else []
        rss = 0.0
        for p in procs:
            try:
                m = p.memory_info()
            except psutil.Error:
                continue
            self.o.peak_vms_mb = max(self.o.peak_vms_mb, m.vms / 2**20)
            rss += m.rss / 2**20
        self.o.peak_rss_mb = max(self.o.peak_rss_mb, rss)

    def _reaped(self, block: bool = False) -> bool:
        try:
            pid, status, _ = os.wait4(self.proc.pid, 0 if block else os.WNOHANG)
        except ChildProcessError:
            pid, status = self.proc.pid, 0
        if not pid:
            return False
        self.o.status = os.waitstatus_to_exitcode(status)
        self.proc.returncode = self.o.status
        return True

    def _end(self) -> None:
        """Ask the warden to end the tree; if it does not within the grace, kill every process we find.
        With a cgroup, the kernel's list of the case's processes is killed at once."""
        if self.cgroup is not None:
            self.cgroup.kill()
            self._reaped(block=True)
            return
        try:
            os.kill(self.proc.pid, signal.SIGTERM)
        except ProcessLookupError:
            pass
        end = time.monotonic() + TERM_GRACE_S
        while time.monotonic() < end:
            if self._reaped():
                return
            time.sleep(0.01)
        for p in self._tree():  # the warden is stopped or gone astray: do its job
            try:
                p.kill()
            except psutil.Error:
                pass
        try:
            os.kill(self.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self._reaped(block=True)

    def _read_report_pipe(self) -> None:
        try:
            os.set_blocking(self.report_fd, False)
            while chunk := os.read(self.report_fd, 1 << 16):
                self.report_buf += chunk
        except OSError:  # nothing more yet (BlockingIOError) or the pipe is gone
            pass

    def _read_report(self) -> None:
        """The warden's final report, if it wrote one; without it, sweep for processes tagged with this case."""
        self._read_report_pipe()
        for line in bytes(self.report_buf).splitlines()[1:2]:
            try:
                rep = json.loads(line)
            except ValueError:
                break
            if isinstance(rep, dict) and all(isinstance(rep.get(k), (int, float)) for k in ("cpu_s", "maxrss_kb")):
                self.o.report = rep
                if isinstance(rep.get("status"), int) and self.o.status == 0:
                    self.o.status = rep["status"]  # the planner process's own exit status
                return
        if self.cgroup is None:  # with a cgroup, the kernel's list of its processes is killed instead
            _sweep(self.tag)


def _sweep(tag: str) -> None:
    """Kill every process of ours that carries the case's tag (the warden died before its job was done)."""
    me = os.getuid()
    for p in psutil.process_iter(["uids"]):
        try:
            if p.info["uids"] and p.info["uids"].real == me and p.environ().get(CASE_TAG) == tag:
                p.kill()
        except psutil.Error:
            continue

