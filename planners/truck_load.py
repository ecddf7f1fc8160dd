"""What the truck surely takes from an open-loop plan on the realistic track (:class:`LoadBound`).

A plan made on a scan with the soil's class only cannot see the truck fill: the site's bucket
fill and swell are drawn within the class's ranges (docs/realistic.md), and a dump into a full
truck leaves the rest in the bucket, so the next dig or charge starts with soil in it
(``bucket_not_empty``). The loaders (``loader_cycle``) and ``separate`` therefore bound what
their digs may really deliver by the class's fullest bucket, and the truck's room by its loose
capacity at the class's largest swell, and plan no dig after one that may have filled it. The
exact track has no bound: its cut model is the referee's.
"""

from __future__ import annotations

from dataclasses import dataclass

from earthbench.soil import MATERIALS, fill_range
from earthbench.world import Scenario

#: The share of a bucket's capacity a path may really hold beyond what the planner's ground says.
SCAN_ALLOWANCE = 0.1


@dataclass(frozen=True)
class LoadBound:
    """``fill_most``: the bank m³ a bucket of the class holds at most per m³ of capacity
    (:func:`earthbench.soil.fill_range`); ``room``: the bank m³ the truck surely holds (its
    loose capacity over the class's largest swell)."""

    fill_most: float
    room: float

    @classmethod
    def of(cls, scenario: Scenario) -> LoadBound | None:
        """The bound of a planner's view (its soil is the class's nominal one); None on the
        exact track."""
        soil = scenario.soil
        if soil is None:
            return None
        known = MATERIALS.get(soil.material)
        fill_most = fill_range(soil.material, scenario.machines.machine_class)[1] if known else soil.fill_factor
        swell = known.swell[1] if known else soil.swell
        return cls(fill_most, scenario.machines.truck.capacity / swell)

    def most(self, path_volume: float, capacity: float) -> float:
        """The most a dig or charge can really deliver when its path holds ``path_volume`` on
        the planner's ground (the public cut model): a bucket of ``capacity`` at the class's
        fullest, and no more than the path with a tenth of the capacity for what the scan missed."""
        return min(self.fill_most * capacity, path_volume + SCAN_ALLOWANCE * capacity)

    def took_all(self, most: float, loaded: float = 0.0) -> bool:
        """Whether the truck, holding ``loaded`` bank m³ when the plan began, surely took all of
        digs that delivered at most ``most``: only then may another dig follow."""
        return loaded + most <= self.room + 1e-9
