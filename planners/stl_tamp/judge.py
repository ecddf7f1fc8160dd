"""How stl-tamp judges the tilt of a stand (0.13.0): its facing-away tiles' bases stand on the dig
area, among the soil's faces, where a scan errs most (planners/stl_tamp/NOTES.md, "0.13.0")."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from shapely.geometry import Polygon

from earthbench.rules import track_level_and_tilt
from earthbench.world import ExcavatorSpec, Pose, Scenario


def worst_tilt(sc: Scenario, z: np.ndarray, spec: ExcavatorSpec, pose: Pose, blur: float, at_pose: float | None = None) -> float:
    """The tilt (rad) of the excavator's tracks at ``pose`` on the grid ``z``, the worst of it and,
    where the tracks stand on the dig area, of the pose moved by ``blur`` metres every 45°. A scan
    may misplace a face of the soil by that much (:func:`planners.stability.face_blur`): stl-tamp
    0.13.0's stands on the dig area, judged at the pose alone, stood on true ground tilted up to
    26° (limit 20°) where the scan showed 17°. Off the dig area, and with ``blur`` 0, the pose alone.
    ``at_pose``: the tilt at ``pose`` on ``z`` when the caller has it already."""
    tilt = track_level_and_tilt(sc, z, spec, pose)[1] if at_pose is None else at_pose
    if blur <= 0.0 or not Polygon(sc.site.dig_area).intersects(Polygon(spec.body(pose.x, pose.y, pose.yaw)[0])):
        return tilt
    for k in range(8):
        a = k * math.pi / 4
        tilt = max(tilt, track_level_and_tilt(sc, z, spec, Pose(pose.x + blur * math.cos(a), pose.y + blur * math.sin(a), pose.yaw))[1])
    return tilt


@dataclass(frozen=True)
class StandJudge:
    """How the tilt of a stand is judged (stl-tamp 0.13.0, whose stands stand on the dig area): the
    worst of :func:`worst_tilt` with ``blur`` on the grid planned on and on ``others``, earlier scans
    of the site (closed loop: a cab sees a face from one side and fills it flatter from another; a
    run stood, on its second step's scan from the south, on ground that scan showed at 17° and the
    first at 23°; truth 23°). The default judges the pose on the grid alone."""

    blur: float = 0.0
    others: tuple[np.ndarray, ...] = ()

    def tilt(self, sc: Scenario, z: np.ndarray, spec: ExcavatorSpec, pose: Pose, at_pose: float | None = None) -> float:
        """The judged tilt (rad); ``at_pose``: the tilt at ``pose`` on ``z``, when known."""
        return max([worst_tilt(sc, z, spec, pose, self.blur, at_pose)] + [worst_tilt(sc, g, spec, pose, self.blur) for g in self.others])


#: Judged at the stand, on the grid planned on (stl-tamp before 0.13.0).
AT_THE_STAND = StandJudge()
