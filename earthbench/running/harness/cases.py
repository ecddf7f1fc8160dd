"""The harness's record of a planner's preparation, and the old home of the run's records.

:class:`Case`, :class:`CaseResult`, :class:`PlannerRef`, ``REASONS`` and ``utc_now`` live in
:mod:`earthbench.results.records`, below both the harness and the store; they are exported here too, the
same objects, for code that imports them from here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ...results.records import REASONS, Case, CaseResult, PlannerRef, utc_now

__all__ = ["REASONS", "Case", "CaseResult", "PlannerRef", "Prepared", "utc_now"]


@dataclass(frozen=True)
class Prepared:
    """A finished preparation of a planner on this machine (:mod:`.prepare`): its folder and
    what it cost (the harness's measurements)."""

    key: str
    path: str
    wall_s: float
    cpu_s: float
    peak_rss_mb: float | None = None
    #: True when this process ran it just now (not found on disk).
    ran: bool = False
    summary: Any = field(default=None, compare=False)

