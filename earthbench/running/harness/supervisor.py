"""Run and measure: the supervisor of one fenced job, and the raw outcome it measures.

:class:`Supervisor` hands a job its input, reads and validates its messages (:mod:`.protocol`),
keeps its deadlines on this process's monotonic clock, samples its memory and CPU (the
cgroup's figures where it has one, else the process tree's: :class:`.tree.ProcessTree`),
drives a closed loop's steps through the loop that owns them (:class:`.protocol.ClosedLoop`,
with this class as the hooks around each step), passes a preparation's progress on, and ends
the process tree. What it returns, :class:`.outcome.Outcome`, is raw: the
exit status, the result message, the fault, which deadline passed, the times and figures. It
judges nothing: :mod:`.judge` turns an outcome into a stored result (docs/DESIGN.md §6).
"""

from __future__ import annotations

import json
import os
import queue
import secrets
import selectors
import subprocess
import threading
import time
from collections.abc import Callable
from typing import Any

import psutil

from ...planner import PrepareProgress
from ...world import Budget
from .cgroups import CaseCgroup
from .outcome import Outcome
from .tree import TREE_SAMPLE_S, ProcessTree
from .protocol import (MAX_PROGRESS_MESSAGES, MAX_RESULT_BYTES, PROGRESS_BURST, PROGRESS_RATE, ClosedLoop, check_done,
                       clip, read_progress, too_large)

#: Seconds a case may take to exit after it has sent its result.
EXIT_GRACE_S = 5.0
#: Bytes of the case's stdout/stderr kept with the result.
LOG_TAIL = 4000
#: Bytes a case may write to its stdout and stderr in all: past them it ends as ``error`` (the
#: harness reads them from a pipe and keeps only :data:`LOG_TAIL`; nothing goes to a disk).
LOG_LIMIT = 64 * 2**20
#: Seconds between samples of the case tree's memory while it runs.
SAMPLE_S = 0.25


class Supervisor(ProcessTree):
    """Hands the job its input, reads and validates its messages, enforces the deadlines."""

    def __init__(self, proc: subprocess.Popen, msg_fd: int, report_fd: int, scenario: bytes, tag: str,
                 budget: Budget, startup_s: float, stop: threading.Event | None, t_spawn: float, loop: ClosedLoop | None = None,
                 cgroup: CaseCgroup | None = None, sandboxed: bool = False, log_fd: int = -1, *, job: bool | str = False,
                 watch: Callable[[], str] | None = None, on_progress: Callable[[PrepareProgress], None] | None = None):
        self.proc, self.msg_fd, self.report_fd, self.scenario, self.tag = proc, msg_fd, report_fd, scenario, tag
        self.prepare = job  # a non-case job (run_job): its name, ``prepare`` or ``probe``
        self.watch = watch
        self.on_progress = on_progress
        self.progress_n, self.progress_tokens, self.progress_at = 0, float(PROGRESS_BURST), t_spawn
        self.next_watch = t_spawn + TREE_SAMPLE_S
        self.log_fd, self.log, self.logged = log_fd, bytearray(), 0
        self.budget, self.stop = budget, stop
        self.o = Outcome(t_spawn=t_spawn, startup_s=startup_s, loop=loop)
        self.outbox: queue.SimpleQueue[bytes | None] = queue.SimpleQueue()
        self.deadline = t_spawn + startup_s
        self.buf = bytearray()
        self.scanned = 0
        self.writer: threading.Thread | None = None
        self.next_sample = 0.0
        self.next_tree_sample = t_spawn + TREE_SAMPLE_S
        self.planner: psutil.Process | None = None
        self.report_buf = bytearray()
        self.cgroup = cgroup
        self.sandboxed = sandboxed
        self.next_cpu_check = 0.0
        #: The nonce of the input the case is answering (None: no answer is due).
        self.nonce: str | None = None
        try:
            self.warden: psutil.Process | None = psutil.Process(proc.pid)
        except psutil.Error:
            self.warden = None

    def run(self) -> Outcome:
        o = self.o
        sel = selectors.DefaultSelector()
        sel.register(self.msg_fd, selectors.EVENT_READ)
        os.set_blocking(self.msg_fd, False)
        if self.log_fd >= 0:
            sel.register(self.log_fd, selectors.EVENT_READ)
            os.set_blocking(self.log_fd, False)
        eof = False
        try:
            while not o.fault:
                now = time.monotonic()
                if self.stop is not None and self.stop.is_set():
                    o.cancelled = True
                    break
                if now >= self.deadline:
                    o.timed_out = o.done is None
                    break
                if now >= self.next_sample:
                    self._sample(now)
                    self.next_sample = now + SAMPLE_S
                if self.watch is not None and now >= self.next_watch:
                    o.fault = self.watch()
                    self.next_watch = time.monotonic() + TREE_SAMPLE_S
                if o.fault or self._over_cpu():
                    break
                if sel.get_map():
                    eof = self._pump(sel, min(self.deadline - now, 0.005 if eof else 0.25)) or eof
                else:
                    time.sleep(0.005)
                if self._reaped():
                    while not eof and not o.fault:  # what is still in the pipe
                        got = self._pump(sel, 0.05, drain=True)
                        if got is None:
                            break
                        eof = got
                    break
        finally:
            sel.close()
            o.t_end = time.monotonic()
            if o.loop is not None and o.t_given is not None:  # the call a deadline or a fault cut short
                o.loop.no_actions(o.t_end - o.t_given)
            if o.done is None:
                self._cpu_at_end()
            if o.status is None:  # still running: past a deadline, a fault, or cancelled
                self._end()
            self._read_report()
            if self.cgroup is not None:
                self.cgroup.kill()  # what the warden left (none, unless it was killed)
                o.cgroup_peak_mb = self.cgroup.peak_bytes() / 2**20
                o.oom_kills = self.cgroup.oom_kills()
                o.processes = self.cgroup.pids_peak
            if self.log_fd >= 0:
                self._read_log()  # what its processes wrote before they ended (they all have)
            if self.writer is not None:
                self.outbox.put(None)
                self.writer.join(timeout=1.0)
        return o

    def _pump(self, sel: selectors.BaseSelector, timeout: float, drain: bool = False) -> bool | None:
        """Wait up to ``timeout`` for the message pipe or the log; read what came. Returns whether
        the message pipe reached its end (None: nothing came while ``drain``ing the messages)."""
        events = sel.select(timeout=max(0.0, timeout))
        eof, got = False, False
        for key, _ in events:
            if key.fd == self.log_fd:
                if not self._read_log():
                    sel.unregister(self.log_fd)
            else:
                got = True
                eof = self._read()
                if eof:
                    sel.unregister(self.msg_fd)
        return None if drain and not got else eof

    def _read_log(self) -> bool:
        """Keep the last :data:`LOG_TAIL` bytes of what the case wrote to its stdout and stderr
        (nothing reaches a disk); past :data:`LOG_LIMIT` bytes it is a fault. False at its end."""
        while True:
            try:
                part = os.read(self.log_fd, 1 << 20)
            except BlockingIOError:
                return True
            except OSError:
                return False
            if not part:
                return False
            self.logged += len(part)
            self.log += part[-LOG_TAIL:]
            del self.log[:-LOG_TAIL]
            if self.logged > LOG_LIMIT and not self.o.fault:
                self.o.fault = (f"the case wrote more than {LOG_LIMIT // 2**20} MB to its stdout and stderr "
                                f"(only the last {LOG_TAIL:,} bytes are kept)")
                return True

    # -- messages ------------------------------------------------------------------------------
    def _read(self) -> bool:
        """Read what the pipe holds; scan only the new bytes for line ends (linear in the size).
        After the result nothing more may come: any byte is a protocol fault, read no further."""
        chunk, eof = bytearray(), False
        while len(chunk) < 1 << 24:  # drain what is there (up to 16 MB) before scanning it
            try:
                part = os.read(self.msg_fd, 1 << 20)
            except BlockingIOError:
                break
            if not part:
                eof = True
                break
            chunk += part
            if self.o.done is not None:
                break
        if self.o.done is not None and chunk and not self.o.fault:
            self.o.fault = f"the case wrote on its message pipe after its result: {bytes(chunk[:40])!r}"
            return eof
        self.buf += chunk
        start = 0
        while not self.o.fault:
            nl = self.buf.find(b"\n", self.scanned)
            if nl < 0:
                self.scanned = len(self.buf)
                if len(self.buf) - start > MAX_RESULT_BYTES:
                    self.o.fault = too_large(len(self.buf) - start)
                break
            line = bytes(self.buf[start:nl])
            start = self.scanned = nl + 1
            if len(line) > MAX_RESULT_BYTES:
                self.o.fault = too_large(len(line))
            elif not line.strip():
                self.o.fault = "the case sent an empty line on its message pipe (every message is one JSON object)"
            else:
                self._handle(line)
                if self.o.done is not None and len(self.buf) > start and not self.o.fault:
                    self.o.fault = f"the case wrote on its message pipe after its result: {bytes(self.buf[start:start + 40])!r}"
        del self.buf[:start]
        self.scanned = max(0, self.scanned - start)
        if eof and self.buf.strip() and not self.o.fault:
            self.o.fault = "the case's last message is not terminated by a newline"
        return eof

    def _handle(self, line: bytes) -> None:
        o = self.o
        try:
            msg = json.loads(line)
        except ValueError as exc:
            o.fault = f"the case sent a message that is not JSON ({exc})"
            return
        event = msg.get("event") if isinstance(msg, dict) else None
        if o.done is not None:
            o.fault = "the case sent a message after its result"
        elif event == "ready" and o.t_ready is None:
            self._hand_over()
        elif event == "ready":
            o.fault = "the case said 'ready' twice"
        elif event == "done":
            problem = check_done(msg, o.t_ready is not None, o.loop is not None, self.prepare) or (
                self._unechoed(msg) if o.t_ready is not None else "")
            if problem:
                o.fault = problem
            else:
                self._finish(msg)
                if o.loop is not None and msg["outcome"] == "steps":
                    o.loop.no_actions(o.calls[-1])
        elif event == "step":
            self._step(msg)
        elif event == "progress":
            self._progress(msg, len(line))
        else:
            o.fault = f"the case sent a message that is not an earthbench message: {clip(line)}"

    def _progress(self, msg: dict[str, Any], size: int) -> None:
        """A preparation says how far it is: checked as hostile data (:func:`.protocol.read_progress`),
        kept at most :data:`.protocol.PROGRESS_RATE` a second (more are dropped) and handed on."""
        o = self.o
        got = read_progress(msg, size, self.prepare)
        if isinstance(got, str):
            o.fault = got
            return
        if o.t_given is None:
            o.fault = "the preparation sent progress before it was given its job"
            return
        if problem := self._unechoed(msg):
            o.fault = problem
            return
        self.progress_n += 1
        if self.progress_n > MAX_PROGRESS_MESSAGES:
            o.fault = f"the preparation sent more than {MAX_PROGRESS_MESSAGES:,} progress messages"
            return
        now = time.monotonic()
        self.progress_tokens = min(float(PROGRESS_BURST), self.progress_tokens + (now - self.progress_at) * PROGRESS_RATE)
        self.progress_at = now
        if self.progress_tokens >= 1.0:
            self.progress_tokens -= 1.0
            if self.on_progress is not None:
                self.on_progress(got)

    def _finish(self, msg: dict[str, Any]) -> None:
        """The run's result is in: stop the clock, close the case's stdin, give it time to exit."""
        o = self.o
        o.t_done = time.monotonic()
        o.replied(o.t_done)
        o.done = msg
        self.nonce = None
        self._cpu_at_end()
        self.deadline = o.t_done + EXIT_GRACE_S
        self.outbox.put(None)

    def _give(self, data: bytes, now: float) -> None:
        """Hand the planner its next input and start its call's clock: the wall budget left over
        all calls, and for a closed-loop run at most the per-step limit."""
        o = self.o
        o.t_given = now
        left = self.budget.wall_s - sum(o.calls)
        o.limit = "step" if o.loop is not None and self.budget.step_s < left else "wall"
        self.deadline = now + (min(self.budget.step_s, left) if o.loop is not None else left)
        self.nonce = secrets.token_hex(16)
        self.outbox.put(b'{"nonce": "%s", "input": ' % self.nonce.encode() + data.rstrip(b"\n") + b"}\n")

    def _hand_over(self) -> None:
        """The planner's code is loaded: start the clock and give the case its scenario."""
        o = self.o
        o.t_ready = time.monotonic()
        o.cpu_ready = self._tree_cpu()
        stdin, outbox = self.proc.stdin, self.outbox
        assert stdin is not None  # the case is started with stdin=PIPE

        def write() -> None:  # one writer, so a case that stops reading never blocks the supervisor
            try:
                while (data := outbox.get()) is not None:
                    stdin.write(data)
                    stdin.flush()
            except OSError:  # the case ended (or closed its stdin) before reading it all
                pass
            try:
                stdin.close()
            except OSError:
                pass

        self.writer = threading.Thread(target=write, name="earthbench-stdin", daemon=True)
        self.writer.start()
        self._give(self.scenario, o.t_ready)

    def _step(self, msg: dict[str, Any]) -> None:
        """One closed-loop step: time it, execute it on the truth, hand over the next observation."""
        o, loop = self.o, self.o.loop
        now = time.monotonic()
        if loop is None:
            o.fault = "the case sent a step, but its configuration does not run closed loop"
        elif o.t_given is None:
            o.fault = (
                "the case sent a step before it was given an observation"
                if o.t_ready is None
                else "the case sent a step it was not asked for"
            )
        elif not isinstance(msg.get("plan"), str):
            o.fault = f"the case's step has a plan of type {type(msg.get('plan')).__name__}, not a JSON text"
        elif problem := self._unechoed(msg):
            o.fault = problem
        else:
            self.nonce = None
            self.step_at = now
            problem = loop.step(msg["plan"], o.replied(now), self)
            if problem:
                o.fault = problem

    # -- the hooks around a closed-loop step (:class:`.protocol.StepHooks`): the loop owns the step
    def pause(self) -> None:
        if self.cgroup is not None:  # no compute between steps: the case stands still while the harness works
            self.cgroup.freeze(True, wait=False)

    def resume(self) -> None:
        if self.cgroup is not None:
            self.cgroup.freeze(False, wait=False)

    def observe(self, data: bytes) -> None:
        self._give(data, time.monotonic())

    def end(self) -> None:
        o = self.o
        o.done = {"event": "done", "outcome": "steps"}
        o.t_done = self.step_at
        self._cpu_at_end()
        self.deadline = self.step_at + EXIT_GRACE_S
        self.outbox.put(None)

    def _cpu_at_end(self) -> None:
        """The cgroup's CPU seconds when the planner's last call ended (what its processes burn
        while the case exits is not the planner's compute)."""
        if self.cgroup is not None and self.o.cgroup_cpu_s is None:
            self.o.cgroup_cpu_s = self.cgroup.cpu_s()

    def _unechoed(self, msg: dict[str, Any]) -> str:
        """Why a reply is not an answer to the input the case was last given ('' when it is)."""
        if self.nonce is None or msg.get("nonce") != self.nonce:
            return ("the case's reply does not echo the nonce of the input it answers "
                    "(a reply written before its input arrived, or not by the case's bootstrap)")
        return ""

    def _over_cpu(self) -> bool:
        """The planner's calls have used more CPU seconds than the budget's ``cpu_s``."""
        cap, o = self.budget.cpu_s, self.o
        if cap is None or o.t_ready is None or o.done is not None:
            return False
        if self.cgroup is None and time.monotonic() < self.next_cpu_check:
            return False  # without a cgroup, reading the tree's CPU is a scan: every SAMPLE_S
        self.next_cpu_check = time.monotonic() + SAMPLE_S
        if self._tree_cpu() - o.cpu_ready > cap:
            o.cpu_out = True
            return True
        return False
