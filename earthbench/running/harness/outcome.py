"""The raw outcome of one fenced job: what the sandbox measured, nothing judged.

The exit status, the result message, the fault, which deadline passed, the times (every one
on the harness's monotonic clock) and the figures (CPU seconds, peak memory, OOM kills, the
process count: the cgroup's where the job had one, else the process tree's), the fences it had
and the tail of its log. :mod:`.supervisor` fills it; :mod:`.judge` reads it (docs/DESIGN.md §6).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from .protocol import ClosedLoop


@dataclass
class Outcome:
    """What the supervisor measured of one job, raw (nothing judged); every time here is from the
    harness's monotonic clock."""

    t_spawn: float
    startup_s: float
    t_ready: float | None = None
    t_done: float | None = None
    t_end: float | None = None
    #: When the planner's current call began (the hand-over of the scenario or of an observation).
    t_given: float | None = None
    #: Harness-measured seconds of each finished planner call (one for an open-loop run).
    calls: list[float] = field(default_factory=list)
    #: Which limit the current deadline is: "wall" (the budget over all calls) or "step".
    limit: str = "wall"
    loop: ClosedLoop | None = None
    cpu_ready: float = 0.0
    done: dict[str, Any] | None = None
    fault: str = ""
    timed_out: bool = False
    cancelled: bool = False
    status: int | None = None
    report: dict[str, Any] | None = None
    peak_vms_mb: float = 0.0
    peak_rss_mb: float = 0.0
    #: The kernel's figures of the case's cgroup when it has one (None: per-process fences only).
    cgroup_cpu_s: float | None = None
    cgroup_peak_mb: float | None = None
    oom_kills: int = 0
    processes: int | None = None
    #: The case used more CPU seconds than its budget's ``cpu_s``.
    cpu_out: bool = False
    #: The fences it had (``namespaces+cgroup-v1`` …, ``none``) and the tail of its stdout and stderr.
    isolation: str = "none"
    log_tail: str = ""

    @property
    def solve_time_s(self) -> float | None:
        """The planner's compute: every call from hand-over to reply (the call cut short by a deadline too)."""
        if self.t_ready is None:
            return None
        running = (self.t_end or self.t_given) - self.t_given if self.t_given is not None else 0.0
        return max(0.0, sum(self.calls) + running)

    def replied(self, now: float) -> float:
        """End the planner's current call at ``now``; returns its length."""
        took = now - (self.t_given if self.t_given is not None else now)
        self.calls.append(took)
        self.t_given = None
        return took

    @property
    def solve_cpu_s(self) -> float | None:
        if self.t_ready is None:
            return None
        if self.cgroup_cpu_s is not None:
            return max(0.0, self.cgroup_cpu_s - self.cpu_ready)
        if self.report is None:
            return None
        return max(0.0, float(self.report["cpu_s"]) - self.cpu_ready)  # tick-resolution sample vs µs accounting

    @property
    def maxrss_mb(self) -> float | None:
        if self.cgroup_peak_mb is not None:
            return self.cgroup_peak_mb
        if self.report is not None:
            return float(self.report["maxrss_kb"]) / 1024.0
        return self.peak_rss_mb or None
