"""How the greedy backhoe's machines change places: the truck's stands for a new base (nearest
the material's bearing first), which machine drives first so neither path passes the other, and
the moves in the plan."""

from __future__ import annotations

import math
from collections.abc import Iterator

from shapely.geometry import LineString, Point

import numpy as np

from earthbench.motion import poses_at, wrap
from earthbench.plan import Move
from earthbench.world import Pose

from ..truck_stands import Sample, arc_times, drive


class Moves:
    """The machines' moves of the greedy backhoe's session (``GreedySession`` in
    :mod:`earthbench_planners.greedy.backhoe`), which holds the state they read and change."""

    def _truck_spots(self, base: Pose, toward: tuple[float, float] | None = None) -> Iterator[Pose]:
        """Stands for the truck serving ``base``, nearest the bearing of its material (or of
        ``toward``) first (:meth:`..truck_stands.TruckStands.parking`)."""
        bearing = (math.atan2(toward[1] - base.y, toward[0] - base.x) if toward is not None
                   else self.material_bearing(base))
        buckets = (self.sc.task.target_volume - self.loaded) / self.exc.bucket_capacity
        return self.stands.parking(base, self.truck, bearing, max(buckets, 1.0), arcs=True)

    def exc_drive_times(self, xy: np.ndarray) -> np.ndarray:
        """The excavator's least time (s) from its base to each of ``xy[k, 2]``: turning in place
        (either way round: it drives forward or back) then straight, or on an arc at full speed
        and yaw rate then straight (``truck_stands.arc_times``); its slow turn counts."""
        e, b = self.exc, self.base
        dx, dy = xy[:, 0] - b.x, xy[:, 1] - b.y
        turn = np.abs((np.arctan2(dy, dx) - b.yaw + math.pi) % (2 * math.pi) - math.pi)
        turn = np.where(np.hypot(dx, dy) > 1e-6, np.minimum(turn, math.pi - turn), 0.0)
        time = turn / e.yaw_rate + np.hypot(dx, dy) / e.travel_speed
        for side in (1, -1):
            time = np.minimum(time, arc_times(b, xy[:, 0], xy[:, 1], e.travel_speed, e.yaw_rate, side)[0])
        return time

    def _clear(self, path: list[Sample], static: Pose) -> bool:
        """Whether a move's ``path`` keeps out of keep-outs and the clearance from a machine standing at ``static``."""
        seg = _line(path)
        if any(seg.intersects(ko) for ko in self.keep_outs):
            return False
        return seg.distance(Point(static.x, static.y)) >= self.exc.clearance + 0.05

    def _truck_move(self, new_base: Pose, toward: tuple[float, float] | None = None,
                    spots: list[Pose] | None = None) -> tuple[str, Pose] | None:
        """Where the truck stands for a base at ``new_base`` and which machine drives first so
        neither path passes the other machine — or ``both`` at once, when they keep the
        clearance apart at every instant, starting together (None: no spot works). ``spots``: only these stands."""
        dest = (new_base.x, new_base.y)
        exc_path = self._exc_path(dest, 0.0)
        tried = 0
        for tpose in spots if spots is not None else self._truck_spots(new_base, toward):
            truck_path = self._truck_path(tpose, 0.0)
            if not self._clear(truck_path, self.base if len(exc_path) == 1 else Pose(*dest, 0.0)):
                continue
            if len(exc_path) == 1 or self._apart(exc_path, truck_path):
                first = "both"
            elif self._clear(exc_path, self.truck) and self._clear(truck_path, Pose(*dest, 0.0)):
                first = "excavator"
            elif self._clear(truck_path, self.base) and self._clear(exc_path, tpose):
                first = "truck"
            else:
                continue
            tried += 1
            if self.stands.path_ok(truck_path):
                return first, tpose  # the truck's way keeps its ground limits
            if tried >= 40:
                break
        return None

    def _apart(self, a: list[Sample], b: list[Sample]) -> bool:
        """Whether two moves starting at the same time keep the machines' centres the clearance
        (and 0.1 m: the footprints' corners) apart at every instant, each waiting at its end."""
        end = max(a[-1][0], b[-1][0])
        times = np.append(np.arange(0.0, end, 0.05), end)
        pa, pb = poses_at(np.asarray(a), times), poses_at(np.asarray(b), times)
        return bool(np.hypot(pa[:, 0] - pb[:, 0], pa[:, 1] - pb[:, 1]).min() >= self.exc.clearance + 0.1)

    def _truck_path(self, spot: Pose, t0: float) -> list[Sample]:
        return drive(self.truck, (spot.x, spot.y), t0, self.truck_spec.travel_speed, self.truck_spec.yaw_rate, final_yaw=spot.yaw)

    def _exc_path(self, dest: tuple[float, float], t0: float) -> list[Sample]:
        return drive(self.base, dest, t0, self.exc.travel_speed, self.exc.yaw_rate)

    def _go(self, new_base: Pose, toward: tuple[float, float] | None = None) -> bool:
        """Bring the truck (and the excavator) for a base at ``new_base``; False if no spot works."""
        move = self._truck_move(new_base, toward)
        if move is not None:
            self._drive_in_turn((new_base.x, new_base.y), *move)
        return move is not None

    def _drive_in_turn(self, dest: tuple[float, float], first: str, spot: Pose) -> None:
        if first == "both":
            t0 = max(self.t, self.truck_ready)
            self._drive("excavator", dest, t0=t0)
            self._drive("truck", (spot.x, spot.y), spot.yaw, t0=t0)
        elif first == "excavator":
            self._drive("excavator", dest)
            self._drive("truck", (spot.x, spot.y), spot.yaw)
        else:
            self._drive("truck", (spot.x, spot.y), spot.yaw)
            self._drive("excavator", dest)

    def _drive(self, machine: str, goal: tuple[float, float], yaw: float | None = None, t0: float | None = None) -> None:
        pose = self.base if machine == "excavator" else self.truck
        spec = self.exc if machine == "excavator" else self.truck_spec
        if math.hypot(goal[0] - pose.x, goal[1] - pose.y) < 1e-9 and (yaw is None or abs(wrap(yaw - pose.yaw)) < 1e-9):
            return
        start = max(self.t, self.truck_ready) if t0 is None else t0
        path = drive(pose, goal, start, spec.travel_speed, spec.yaw_rate, final_yaw=yaw)
        self.actions.append(Move(machine, tuple(path)))
        end = Pose(path[-1][1], path[-1][2], path[-1][3])
        if machine == "excavator":
            self.t = path[-1][0]
            self.base = end  # the upper body turns with the base: ``turn`` is relative
        else:
            # the excavator digs on while the truck drives (a dig checks where it still drives:
            # ``still_driving``); a drive of the excavator after it waits (``truck_ready``)
            self.truck, self.truck_path = end, path
            self.truck_ready = path[-1][0]


def _line(path: list[Sample]) -> LineString | Point:
    """The ground track of a move's samples (arcs are sampled finely enough: ``truck_stands.ARC_PIECE``)."""
    pts = list(dict.fromkeys((p[1], p[2]) for p in path))
    return LineString(pts) if len(pts) > 1 else Point(pts[0])
