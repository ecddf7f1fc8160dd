"""What a loader planner assumes of the soil from its class (:class:`SoilModel`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from earthbench.world import Soil


@dataclass(frozen=True)
class SoilModel:
    """What a loader planner assumes of the soil from its class (the observation's nominal
    soil): the bucket's bank fill factor, the angle the faces slump to, and a harder layer
    ``shallower`` m above the nominal depth (every class's documented range of depths is 0.4 m
    wide: 0.2 m is its shallow end) under the initial ground ``z0``, the first grid the planner
    saw: ``top``, the layer's top per cell, and ``penetration``, how far one charge cuts into it."""

    fill: float
    repose_deg: float
    top: np.ndarray | None
    penetration: float

    @classmethod
    def of(cls, soil: Soil | None, z0: np.ndarray, shallower: float = 0.2) -> SoilModel | None:
        if soil is None:
            return None
        top = None if soil.hard_depth is None else np.asarray(z0) - max(soil.hard_depth - shallower, 0.0)
        return cls(soil.fill_factor, soil.repose_deg, top, soil.hard_penetration)

    def levels(self, jj: np.ndarray, ii: np.ndarray, heights: np.ndarray, level: float) -> float | np.ndarray:
        """The level each path cell is cut to: ``level``, but no deeper than ``penetration``
        into the harder layer (the rule of docs/realistic.md, as the referee applies it)."""
        if self.top is None:
            return level
        return np.maximum(level, np.minimum(heights, self.top[jj, ii]) - self.penetration)
