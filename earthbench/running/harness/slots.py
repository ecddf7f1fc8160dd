"""Core slots: disjoint groups of CPU cores, one case per slot at a time."""

from __future__ import annotations

import contextlib
import os
import queue
import threading
from collections.abc import Iterable, Iterator, Sequence


def make_slots(cores_per_case: int, jobs: int | None = None, allowed: Iterable[int] | None = None) -> list[tuple[int, ...]]:
    """Disjoint groups of ``cores_per_case`` cores: floor(N / cores) slots, at most ``jobs``.

    With fewer cores than a case asks for, one slot gets all of them.
    """
    if allowed is None:
        allowed = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else range(os.cpu_count() or 1)
    cpus = sorted(allowed)
    n = max(1, len(cpus) // max(1, cores_per_case))
    if jobs is not None:
        n = max(1, min(n, jobs))
    if len(cpus) < cores_per_case:
        return [tuple(cpus)]
    return [tuple(cpus[i * cores_per_case : (i + 1) * cores_per_case]) for i in range(n)]


class SlotPool:
    """Disjoint core slots handed out to concurrent cases of one process."""

    _shared: dict[int, SlotPool] = {}
    _lock = threading.Lock()

    def __init__(self, slots: Sequence[tuple[int, ...]]):
        self.slots = list(slots)
        self._free: queue.Queue[tuple[int, ...]] = queue.Queue()
        for s in self.slots:
            self._free.put(s)

    @classmethod
    def shared(cls, cores_per_case: int) -> SlotPool:
        with cls._lock:
            if cores_per_case not in cls._shared:
                cls._shared[cores_per_case] = cls(make_slots(cores_per_case))
            return cls._shared[cores_per_case]

    @contextlib.contextmanager
    def slot(self) -> Iterator[tuple[int, ...]]:
        s = self._free.get()
        try:
            yield s
        finally:
            self._free.put(s)
