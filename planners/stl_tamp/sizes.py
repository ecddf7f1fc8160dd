"""The configuration's sizes for a scenario's machines: one rule, from the excavator's spec alone.

``stl-tamp``'s and ``separate``'s settings in metres and m³ (the areas' V_max, where the base and
the truck stand, the terrain fits' lattices, the global window, the dig depth…) are the STL-TAMP
paper's, for the compact class's excavator. On another excavator they scale (docs/machine-classes.md,
"stl-tamp and separate on every class"):

- a length by the reach: ``reach_max`` ÷ the compact excavator's (6.1 m);
- a volume by the bucket: ``bucket_capacity`` ÷ the compact excavator's (0.28 m³);
- a phase's bound on its work time by the stroke and the dump: ``min_stroke_time + min_dump_time``
  ÷ the compact excavator's (5 s).

A configuration names its settings of each kind (``LENGTHS``, ``VOLUMES``); a lattice's spacing
and its extent scale alike, so its number of points, hence the NLP's size, stays the paper's.
On the compact excavator every factor is exactly 1 and the configuration is the given one, so
its plans are those of the versions before the rule.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass
from typing import Any, TypeVar

from earthbench.world import ExcavatorSpec

#: The excavator the configurations' defaults are for: the compact class's, the paper's machine.
REFERENCE = ExcavatorSpec()

C = TypeVar("C")
P = TypeVar("P", bound="Sized")


@dataclass(frozen=True)
class Factors:
    """How much larger an excavator is than :data:`REFERENCE`: in length, volume and work time."""

    length: float
    volume: float
    work_time: float

    @property
    def unit(self) -> bool:
        """The reference machine (no setting changes)."""
        return self.length == 1.0 and self.volume == 1.0 and self.work_time == 1.0


def factors(exc: ExcavatorSpec) -> Factors:
    """The rule's three factors for ``exc`` (the module's docstring)."""
    ref = REFERENCE
    return Factors(length=exc.reach_max / ref.reach_max, volume=exc.bucket_capacity / ref.bucket_capacity,
                   work_time=(exc.min_stroke_time + exc.min_dump_time) / (ref.min_stroke_time + ref.min_dump_time))


def _scaled(value: Any, k: float) -> Any:
    return tuple(v * k for v in value) if isinstance(value, tuple) else value * k


def sized(config: C, exc: ExcavatorSpec) -> C:
    """``config`` with its ``LENGTHS`` and ``VOLUMES`` scaled for ``exc``; ``config`` itself on
    the reference machine."""
    f = factors(exc)
    if f.unit:
        return config
    changes = {name: _scaled(getattr(config, name), f.length) for name in getattr(config, "LENGTHS", ())}
    changes.update({name: _scaled(getattr(config, name), f.volume) for name in getattr(config, "VOLUMES", ())})
    return dataclasses.replace(config, **changes)  # type: ignore[type-var]


class Sized:
    """A planner whose configuration is given in the compact excavator's sizes and planned with
    those of the scenario's excavator (mixed in before :class:`earthbench.planner.Planner`)."""

    config: Any

    def __init__(self, config: Any = None, **overrides: Any):
        super().__init__(config, **overrides)  # type: ignore[call-arg]
        self.given = self.config  # the compact excavator's sizes; ``config`` may be another's

    def sized_for(self: P, exc: ExcavatorSpec) -> P:
        """This planner with its sizes for ``exc``: itself on the compact excavator."""
        config = sized(self.given, exc)
        if config == self.config:
            return self
        out = copy.copy(self)
        out.config = config
        return out
