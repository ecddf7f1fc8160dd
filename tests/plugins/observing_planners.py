"""A planner that reports what it was shown: the scenario object it received, in its plan's info.

Loaded as a plugin file by the realistic-track tests, which check that the case process gets
the observation (:func:`earthbench.sensing.observe`) and nothing of the truth.
"""

from __future__ import annotations

import hashlib

import numpy as np

from earthbench import Plan, Planner


class Snoop(Planner):
    """Returns no actions; ``info`` holds the digest, terrain, soil and meta it was given."""

    name = "t-snoop"

    def plan(self, scenario):
        z = np.ascontiguousarray(scenario.terrain.z, dtype="<f8")
        return Plan(info={
            "digest": scenario.digest,
            "terrain_sha256": hashlib.sha256(z.tobytes()).hexdigest(),
            "resolution": scenario.terrain.resolution,
            "soil": scenario.to_dict().get("soil"),
            "sensing": scenario.to_dict().get("sensing"),
            "meta": scenario.meta,
        })
