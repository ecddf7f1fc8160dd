"""How busy the machine was around a case: the 1-minute load average and CPU steal.

A solve time means little without it: the same plan re-timed at load 2 on a 2-core machine took
1.5–1.9× as long (issue 35). Each run records the load average (``os.getloadavg``) before and
after its case and the share of CPU time a hypervisor stole meanwhile (``/proc/stat``'s
``steal`` over all its ticks); boards state the range, ``verify`` puts it beside re-timings.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass


@dataclass(frozen=True)
class Snapshot:
    """The load average and the CPU tick counters at one moment (NaN / 0 where the OS has none)."""

    load: float
    steal: int
    total: int


def snapshot() -> Snapshot:
    try:
        load = os.getloadavg()[0]
    except OSError:
        load = math.nan
    steal = total = 0
    try:
        with open("/proc/stat") as f:
            fields = f.readline().split()
        if fields and fields[0] == "cpu":
            ticks = [int(v) for v in fields[1:]]
            # user nice system idle iowait irq softirq steal [guest guest_nice: already in user/nice]
            total, steal = sum(ticks[:8]), (ticks[7] if len(ticks) > 7 else 0)
    except (OSError, ValueError):
        pass
    return Snapshot(load, steal, total)


def around(before: Snapshot, after: Snapshot) -> dict[str, float | None]:
    """The stored columns: ``load_before``, ``load_after`` and ``steal_share`` (None where unknown)."""
    def known(v: float) -> float | None:
        return None if math.isnan(v) else round(v, 3)

    ticks = after.total - before.total
    share = (after.steal - before.steal) / ticks if ticks > 0 else math.nan
    return {"load_before": known(before.load), "load_after": known(after.load), "steal_share": known(share)}
