"""The machines of a site: the specs of the excavator, the truck and the wheel loader, their
poses and the ``Machines`` set a scenario holds (docs/DESIGN.md §3; field by field: docs/world.md).

The dataclasses' defaults are the ``compact`` machine class, the STL-TAMP paper's setting; other
classes are data (``earthbench/classes/*.toml``, :mod:`earthbench.classes`, docs/machine-classes.md)
parsed into these same dataclasses. Every limit the referee checks lives in a spec.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .errors import ScenarioError

#: Field metadata of world-model fields added after digests were first pinned: such a field is
#: left out of the JSON form and the digest while it holds its default, so every scenario
#: written before it existed keeps its digest.
LATER = {"omit_default": True}


def later(default: Any) -> Any:
    """A field added after digests were pinned: left out of the JSON and the digest at ``default``."""
    return field(default=default, metadata=LATER)


def rectangle(x: np.ndarray, y: np.ndarray, yaw: np.ndarray, back: float, front: float, width: float) -> np.ndarray:
    """Corners ``[k, 4, 2]`` of a rectangle from ``back`` behind to ``front`` ahead of each pose
    (along its yaw), ``width`` across; the one footprint shape of every machine."""
    x, y, yaw = (np.atleast_1d(np.asarray(a, dtype=float)) for a in (x, y, yaw))
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    along = np.array([-back, front, front, -back])[None, :]
    across = np.array([-width / 2, -width / 2, width / 2, width / 2])[None, :]
    return np.stack([x[:, None] + along * c - across * s, y[:, None] + along * s + across * c], axis=-1)


@dataclass(frozen=True)
class Pose:
    """A planar pose: position in metres, yaw in radians counter-clockwise from +x."""

    x: float
    y: float
    yaw: float = 0.0

    @property
    def xy(self) -> np.ndarray:
        return np.array([self.x, self.y])


@dataclass(frozen=True)
class ExcavatorSpec:
    """A backhoe excavator. Defaults: the STL-TAMP paper's 7-tonne machine (section V).

    ``reach_min``/``reach_max`` bound the horizontal distance from the base centre to any point
    of a dig stroke (boom + arm = 6.2 m at full stretch; 6.1 m keeps the bucket controllable).
    A dig lasts at least the swing to its bearing plus ``min_stroke_time``; a dump at least the
    swing to the truck plus ``min_dump_time``. ``clearance`` is the least centre distance to the
    truck. ``chord_tolerance`` is the lateral slack (m) allowed between a unicycle arc and the
    straight chord between two path samples.
    """

    boom_length: float = 3.6
    arm_length: float = 2.6
    reach_min: float = 2.0
    reach_max: float = 6.1
    bucket_width: float = 0.7
    bucket_capacity: float = 0.28
    max_drag_length: float = 1.0
    max_cut_depth: float = 0.4
    travel_speed: float = 0.86
    yaw_rate: float = 0.11
    swing_rate: float = 1.1
    joint_rate: float = 1.1
    min_stroke_time: float = 3.0
    min_dump_time: float = 2.0
    clearance: float = 3.5
    chord_tolerance: float = 0.05
    track_length: float = later(2.6)
    track_width: float = later(2.1)
    undermine_slope: float = later(1.0)
    max_tilt: float = later(0.35)

    def outline(self, x: Any, y: Any, yaw: Any) -> np.ndarray:
        """Corners ``[k, 4, 2]`` of the tracks at each pose."""
        return rectangle(x, y, yaw, self.track_length / 2, self.track_length / 2, self.track_width)

    body = outline


@dataclass(frozen=True)
class TruckSpec:
    """A dump truck: the same travel limits as the excavator, a loading radius and a capacity.

    Footprint: a ``length`` × ``width`` rectangle centred on its pose (a small site dumper).
    Its ground (rules version 2, docs/referee.md): wherever it drives or stands the plane fitted
    to the ground under its body rises at most ``max_grade`` along its heading and
    ``max_cross_slope`` across it (rise over run: a site dumper's manufacturers allow 25 % and
    16 %), and that ground departs from the plane by at most ``max_step`` (m): no wheel over a
    bank, a hole or a cut's face.
    """

    travel_speed: float = 0.86
    yaw_rate: float = 0.11
    loading_radius: float = 1.0
    capacity: float = 10.0
    chord_tolerance: float = 0.05
    length: float = later(3.2)
    width: float = later(1.6)
    max_grade: float = later(0.25)
    max_cross_slope: float = later(0.16)
    max_step: float = later(0.15)

    def outline(self, x: Any, y: Any, yaw: Any) -> np.ndarray:
        """Corners ``[k, 4, 2]`` of the truck at each pose."""
        return rectangle(x, y, yaw, self.length / 2, self.length / 2, self.width)

    body = outline


@dataclass(frozen=True)
class LoaderSpec:
    """A small wheel loader (about 5–6 t, 0.8 m³ bucket) for the ``wheel_loader`` track.

    The loader's pose is the centre of its front axle; the bucket's cutting edge, ``bucket_width``
    wide, lies ``bucket_offset`` ahead of it along the heading. The loader is car-like: it
    drives forward or in reverse along its heading on arcs of radius ≥ ``min_turning_radius``
    (it cannot turn in place) at ≤ ``travel_speed`` and ≤ ``yaw_rate``.

    A charge drives ≤ ``penetration_speed`` into the pile and lasts at least
    ``min_charge_time`` (crowding and racking the bucket back); a dump lasts at least
    ``min_dump_time``, needs the cutting edge within ``dump_reach`` of the truck's loading
    circle and the truck in front (within 45° of the heading). ``clearance`` is the least
    distance between the loader's pose and the truck's centre. The pose may never cross a cell
    more than ``max_step`` above the base level (the floor; see the referee).
    ``chord_tolerance`` is the lateral slack (m) between an arc and the chord of two samples.

    Footprint: the wheels stand on the ``wheelbase`` × ``wheel_width`` rectangle behind the
    front axle (the step rule checks every cell under it); the body reaches ``rear_overhang``
    behind the rear axle and ``front_overhang`` ahead of the front one (clearance to the truck,
    over whose bed the raised bucket may reach); the outline adds the bucket out to its cutting
    edge, ``bucket_width`` wide (keep-out zones and the map's edge).
    """

    bucket_width: float = 1.8
    bucket_capacity: float = 0.8
    bucket_offset: float = 1.2
    min_turning_radius: float = 3.5
    travel_speed: float = 2.0
    penetration_speed: float = 0.5
    yaw_rate: float = 0.6
    min_charge_time: float = 2.0
    min_dump_time: float = 3.0
    dump_reach: float = 1.0
    clearance: float = 2.5
    max_step: float = 0.15
    chord_tolerance: float = 0.05
    wheelbase: float = later(2.0)
    wheel_width: float = later(1.6)
    rear_overhang: float = later(0.9)
    front_overhang: float = later(0.5)

    def wheels(self, x: Any, y: Any, yaw: Any) -> np.ndarray:
        """Corners ``[k, 4, 2]`` of the rectangle the wheels stand on at each pose."""
        return rectangle(x, y, yaw, self.wheelbase, 0.0, self.wheel_width)

    def body(self, x: Any, y: Any, yaw: Any) -> np.ndarray:
        """Corners ``[k, 4, 2]`` of the body without the bucket at each pose."""
        return rectangle(x, y, yaw, self.wheelbase + self.rear_overhang, self.front_overhang, self.wheel_width)

    def outline(self, x: Any, y: Any, yaw: Any) -> np.ndarray:
        """Corners ``[k, 4, 2]`` of body and bucket (a rectangle out to the cutting edge)."""
        return rectangle(x, y, yaw, self.wheelbase + self.rear_overhang, self.bucket_offset, max(self.bucket_width, self.wheel_width))


@dataclass(frozen=True)
class Machines:
    """The machines on site with their initial poses. Machine ids in plans: see ``ids``."""

    truck: TruckSpec = field(default_factory=TruckSpec)
    truck_pose: Pose = Pose(2.0, 13.0, 0.0)
    excavator: ExcavatorSpec | None = field(default_factory=ExcavatorSpec)
    excavator_pose: Pose | None = Pose(13.0, 7.2, math.pi)
    loader: LoaderSpec | None = None
    loader_pose: Pose | None = None
    #: The machine class these specs come from (:mod:`earthbench.classes`); a label, left out of
    #: the JSON and the digest at ``compact`` (the digest covers the specs themselves).
    machine_class: str = later("compact")

    def __post_init__(self) -> None:
        if not isinstance(self.machine_class, str) or not self.machine_class:
            raise ScenarioError(f"machines.machine_class must be a non-empty string, got {self.machine_class!r:.40}")
        for name in ("excavator", "loader"):
            if (getattr(self, name) is None) != (getattr(self, f"{name}_pose") is None):
                raise ScenarioError(f"machines.{name} and machines.{name}_pose must be given together")

    @property
    def ids(self) -> tuple[str, ...]:
        out = ["truck"]
        if self.loader is not None:
            out.insert(0, "loader")
        if self.excavator is not None:
            out.insert(0, "excavator")
        return tuple(out)

    def pose(self, machine: str) -> Pose:
        if machine not in self.ids:
            raise ScenarioError(f"no machine {machine!r} on this site; machines: {', '.join(self.ids)}")
        return getattr(self, f"{machine}_pose")
