"""``strip-loader``: a strip along the pile, the truck beside it on the open floor.

The built-in loaders cycle as Singh and Cannon's did: charge, reverse out, two arcs to a truck
that never moves, dump, and back. This planner plans the cycle the loader bound leaves open
(docs/metrics.md, "What the geometry forces"): the loader drives once to the end of a straight
strip along the pile's zero contour, then charges along it, each charge up to a full bucket,
and dumps where the charge ends into the truck, which drove once to a line beside the strip and
moves on along it during each charge (:mod:`.strip`). Every cycle after the first costs the
fastest charge and dump and a back-off of two cells. Where no strip loads the target (no place
where the pile ends across a strip, no room for the truck beside it, wheels that would climb
what a harder layer leaves), the planner falls back to ``greedy-loader``'s cycles, so it loads
wherever that one does. In closed loop it runs greedy cycles (a strip step, continued from
where the loader stands, is written in :mod:`.strip` but not yet planned step by step).

Status: experimental and not registered as an entry point (see README.md: on ``pile`` it finds a
strip that keeps clear of the truck on 1 of 20 scenarios).
"""

from __future__ import annotations

from dataclasses import dataclass

from earthbench.plan import Plan, Prediction

from ..greedy.loader import GreedyLoader, GreedyLoaderConfig
from ..loader_cycle import CycleBuilder
from .schedule import timed
from .strip import Strip, StripSettings, candidates, layout


@dataclass(frozen=True)
class StripLoaderConfig(GreedyLoaderConfig):
    """``greedy-loader``'s settings (for the fallback) and the strip's (:class:`StripSettings`)."""

    back_off: float = 0.2
    """Metres the loader backs off before each further charge (two cells: the row where the last
    bucket filled is left partly cut)."""


class StripLoader(GreedyLoader):
    """A strip along the pile with the truck beside it; greedy cycles where no strip fits."""

    name = "strip-loader"
    version = "1.1"
    Config = StripLoaderConfig

    def _run(self, b: CycleBuilder, max_dumps: int | None = None) -> Plan:
        strip = self._strip(b) if max_dumps is None else None
        if strip is None:
            return super()._run(b, max_dumps)
        actions = tuple(sorted(strip.loader + strip.truck, key=lambda a: a.t_start))
        info = {"stop": "target loaded", "strip": True, "cycles": len(strip.charges)}
        return Plan(actions, Prediction(volume=strip.loaded - b.loaded0, makespan=strip.t_end), info)

    def _strip(self, b: CycleBuilder) -> Strip | None:
        """The fastest strip that keeps clear of the truck, of the few whose layouts promise most."""
        s = StripSettings(back_off=self.config.back_off)
        layouts = [lay for lay in (layout(b, e, s) for e in candidates(b, s)) if lay is not None]
        best: Strip | None = None
        for lay in sorted(layouts, key=lambda lay: lay.estimate)[: s.timed]:
            if best is not None and lay.estimate >= best.t_end:
                break
            strip = timed(b, lay)
            if strip is not None and (best is None or strip.t_end < best.t_end):
                best = strip
        return best
