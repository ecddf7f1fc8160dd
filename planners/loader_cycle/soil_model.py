"""What a loader planner assumes of the soil from its class (:class:`SoilModel`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from earthbench.soil import MATERIALS, fill_range
from earthbench.world import Soil


@dataclass(frozen=True)
class SoilModel:
    """What a loader planner assumes of the soil from its class (the observation's nominal
    soil): the bucket's bank fill factor, the angle the faces slump to, and a harder layer
    ``shallower`` m above the nominal depth (every class's documented range of depths is 0.4 m
    wide: 0.2 m is its shallow end) under the initial ground ``z0``, the first grid the planner
    saw: ``top``, the layer's top per cell, and ``penetration``, how far one charge cuts into it.
    And the ends of the class's ranges a load is bounded by: ``fill_most``, the bank fill factor
    of the fullest bucket the machine class's buckets carry (:func:`earthbench.soil.fill_range`),
    and ``truck_least``, the bank m³ a loose m³ of the truck holds at the class's largest swell."""

    fill: float
    repose_deg: float
    top: np.ndarray | None
    penetration: float
    fill_most: float
    truck_least: float

    @classmethod
    def of(cls, soil: Soil | None, z0: np.ndarray, shallower: float = 0.2, machines: str = "compact") -> SoilModel | None:
        if soil is None:
            return None
        top = None if soil.hard_depth is None else np.asarray(z0) - max(soil.hard_depth - shallower, 0.0)
        known = soil.material in MATERIALS
        fill_most = fill_range(soil.material, machines)[1] if known else soil.fill_factor
        truck_least = 1.0 / (MATERIALS[soil.material].swell[1] if known else soil.swell)
        return cls(soil.fill_factor, soil.repose_deg, top, soil.hard_penetration, fill_most, truck_least)

    def levels(self, jj: np.ndarray, ii: np.ndarray, heights: np.ndarray, level: float) -> float | np.ndarray:
        """The level each path cell is cut to: ``level``, but no deeper than ``penetration``
        into the harder layer (the rule of docs/realistic.md, as the referee applies it)."""
        if self.top is None:
            return level
        return np.maximum(level, np.minimum(heights, self.top[jj, ii]) - self.penetration)

    def most_delivered(self, path_volume: float, capacity: float) -> float:
        """The most a charge can really deliver when its path holds ``path_volume`` on the
        planner's ground (the public cut model, to the floor): a bucket at the class's fullest,
        and no more than the path with a tenth of the capacity for what the scan missed."""
        return min(self.fill_most * capacity, path_volume + 0.1 * capacity)
