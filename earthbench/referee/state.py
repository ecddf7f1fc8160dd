"""The judge's state as it replays a plan (:class:`Replay`: its heightmap, truck load, machine
poses and violations so far), plain data that the rule modules read and only the replay loop
(:mod:`earthbench.referee.loop`) advances; the values a judgement produces (:class:`Violation`,
:class:`DigRecord`, :class:`Stroke`, :class:`Verdict`); and the rules' names and version
(docs/DESIGN.md §5).
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
import shapely

from .. import compat, motion
from ..motion import ABS_TOL
from ..plan import Charge, Move, Plan
from ..rules import Spec
from ..soil import hard_top
from ..world import Pose, Scenario

#: The chord (m) below which the heading rule's lateral slack shrinks in proportion: a sample
#: may leave its arc by ``chord_tolerance`` over a chord this long or longer, and by that share
#: of it over a shorter one, so no chain of short steps slides a machine sideways (rules 2).
SLIP_LENGTH = 1.0


#: The version of the rules below. Bumped whenever a rule is added or changes what it refuses,
#: so a stored verdict says which rules judged it (docs/referee.md, "Rules versions"): 1 until
#: 0.x (no row recorded it), 2 adds the machines near a dig and the truck's ground.
RULES_VERSION = 2

#: Called after each action, in the referee's time order, with the action's index, the heightmap
#: as it then stands (read-only, current only during the call) and the m³ in the truck.
Observer = Callable[[int, np.ndarray, float], None]

#: Every rule the referee checks, with the sentence a report shows for it.
RULES: dict[str, str] = {
    "malformed": "the plan document could not be read",
    "unknown_machine": "the action names a machine that is not on site",
    "wrong_machine": "the machine cannot perform this action",
    "overlap": "the action starts before the same machine's previous action ended",
    "discontinuous": "a move does not start where the machine is",
    "speed": "travel speed along the arc between two samples above the machine's limit",
    "yaw_rate": "yaw rate above the machine's limit",
    "heading": "no arc along both samples' headings (forward or reverse) joins the two samples",
    "keep_out": "a machine's footprint or bucket enters a keep-out zone anywhere along its path",
    "off_map": "a machine's footprint leaves the map, whose outside is not open ground",
    "bucket_not_empty": "a dig starts with material still in the bucket",
    "cut_depth": "cut depth above the machine's limit",
    "drag_length": "drag length above the machine's limit",
    "reach": "the stroke leaves the reach annulus around the base",
    "outside_dig_area": "the bucket footprint leaves the dig area",
    "below_floor": "the cut level lies below the floor (design grade)",
    "undermining": "the excavator cuts under or too close to its own tracks",
    "tilt": "the excavator works standing on ground steeper than its limit",
    "duration": "the action is shorter than the swing plus its minimum time",
    "truck_moving": "the truck moves during a dump",
    "dump_reach": "the truck is out of the bucket's reach",
    "collision": "machines closer than the clearance, or their footprints touch, anywhere along their paths",
    "entry_pose": "a charge does not start at the loader's pose",
    "penetration_speed": "a charge drives faster than the loader's penetration speed",
    "overfill": "the cutting edge pushes on through material after the bucket is full",
    "turning_radius": "a loader move turns tighter than its minimum turning radius",
    "step": "a loader's wheels cross a cell higher than its traversable step above the floor",
    "arm_over_machine": "during a dig's stroke another machine's body stands in the arm's ground shadow (base to bucket)",
    "dig_under_machine": "a dig's or charge's bucket footprint reaches under a machine's footprint (the digger's own included)",
    "truck_tilt": "the truck drives or stands on ground steeper than its grade or cross-slope limit",
    "truck_step": "the ground under the truck departs from its plane by more than its step (a bank, a hole, a cut's face)",
    "truck_undercut": "a dig lowers ground the truck stands on",
}


@dataclass(frozen=True)
class Violation:
    """One broken rule: the action's index in the plan (None: the plan as a whole)."""

    action: int | None
    rule: str
    magnitude: float
    message: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"action": self.action, "rule": self.rule, "magnitude": self.magnitude, "message": self.message}


@dataclass(frozen=True)
class DigRecord:
    """One dig or charge: the bank volume it really removed, that ÷ the bucket's capacity, and
    (only on a scenario with soil) ``nominal``: what the public cut model
    (:mod:`earthbench.cut`) removes on the same ground, the planner's best prediction."""

    action: int
    volume: float
    fill: float
    nominal: float | None = None

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"action": self.action, "volume": self.volume, "fill": self.fill}
        if self.nominal is not None:
            d["nominal"] = self.nominal
        return d


@dataclass(frozen=True)
class Verdict:
    """What the referee measured. ``valid`` is True only when ``violations`` is empty."""

    violations: tuple[Violation, ...]
    final_terrain: Any
    loaded_volume: float
    removed_volume: float
    makespan: float
    digs: tuple[DigRecord, ...] = ()
    dumps: int = 0
    travel: dict[str, float] = field(default_factory=dict)
    #: (end time, cumulative loaded volume) after each dump, in replay order: when the truck got what.
    load_curve: tuple[tuple[float, float], ...] = ()
    #: Where each machine stands when the plan ends (what a closed-loop step continues from).
    final_poses: dict[str, Pose] = field(default_factory=dict)
    #: The excavator's upper body relative to its base yaw when the plan ends (rad).
    final_turn: float = 0.0
    #: Bank m³ left in the bucket when the plan ends (a dump into a full truck leaves some).
    final_bucket: float = 0.0

    @property
    def valid(self) -> bool:
        return not self.violations

    def to_dict(self) -> dict[str, Any]:
        """The verdict as plain JSON values; the final terrain as the sha256 of its heights
        (little-endian float64), so two verdicts compare byte for byte."""
        z = np.ascontiguousarray(self.final_terrain.z, dtype="<f8")
        return {
            "valid": self.valid,
            "violations": [v.to_dict() for v in self.violations],
            "loaded_volume": self.loaded_volume,
            "removed_volume": self.removed_volume,
            "makespan": self.makespan,
            "digs": [d.to_dict() for d in self.digs],
            "dumps": self.dumps,
            "travel": dict(self.travel),
            "load_curve": [list(p) for p in self.load_curve],
            "final_terrain_sha256": hashlib.sha256(z.tobytes()).hexdigest(),
        }

    def summary(self) -> str:
        if self.valid:
            return "valid"
        rules = sorted({v.rule for v in self.violations})
        return f"invalid ({len(self.violations)} violations: {', '.join(rules)})"


class Stroke(NamedTuple):
    """A dig's or charge's cut as its track's rules found it, for the replay loop to make: the
    bucket's path (``width`` × ``length`` from ``contact`` along ``heading``, its ``cells``
    and their heights ``before``), the cut level, the bucket's capacity, the stroke's depth
    (None: the loader's charge), the excavator's base (None: the loader), and the truck's cells
    and heights before the cut (``stands``, for ``truck_undercut``)."""

    machine: str
    contact: tuple[float, float]
    heading: float
    width: float
    length: float
    level: float
    capacity: float
    depth: float | None
    cells: tuple[np.ndarray, np.ndarray, np.ndarray]
    before: np.ndarray
    base: Pose | None
    stands: tuple[tuple[np.ndarray, np.ndarray], np.ndarray]


def timelines(scenario: Scenario, plan: Plan) -> dict[str, motion.Timeline]:
    """Each machine's samples over the whole plan: its moves, and its charges (which move it too)."""
    m = scenario.machines
    moves: dict[str, list[Move]] = {mid: [] for mid in m.ids}
    for a in plan.actions:
        if isinstance(a, Move) and a.machine in moves:
            moves[a.machine].append(a)
        elif isinstance(a, Charge) and a.machine in moves:  # a charge moves the loader too
            (x, y, yaw), (ex, ey, _) = a.entry, a.end
            if a.t_end > a.t_start:
                moves[a.machine].append(Move(a.machine, ((a.t_start, x, y, yaw), (a.t_end, ex, ey, yaw))))
    return {mid: motion.Timeline(m.pose(mid), moves[mid]) for mid in m.ids}


class Replay:
    """State of one judgement: the grid being cut, the machines' poses, bucket and truck loads,
    the violations found so far. Plain data: the rules read it and append what they find to
    ``violations``; the loop (:mod:`earthbench.referee.loop`) makes every other change."""

    def __init__(self, scenario: Scenario, plan: Plan):
        self.sc, self.plan = scenario, plan
        self.terrain = scenario.terrain
        self.z = np.array(scenario.terrain.z, dtype=np.float64)
        self.violations: list[Violation] = []
        self.dig_area = shapely.Polygon(scenario.site.dig_area)
        shapely.prepare(self.dig_area)
        self.dig_area_tol = self.dig_area.buffer(ABS_TOL)
        shapely.prepare(self.dig_area_tol)
        self.keep_outs = [shapely.Polygon(k) for k in scenario.site.keep_outs]
        for k in self.keep_outs:
            shapely.prepare(k)
        self.spacing = scenario.terrain.resolution / 2
        m = scenario.machines
        self.specs: dict[str, Spec] = {"truck": m.truck}
        if m.excavator is not None:
            self.specs["excavator"] = m.excavator
        if m.loader is not None:
            self.specs["loader"] = m.loader
        self.timelines = timelines(scenario, plan)
        self.busy_until = {mid: 0.0 for mid in m.ids}
        self.pose = {mid: m.pose(mid) for mid in m.ids}
        self.turn = 0.0  # excavator's upper body angle relative to its base yaw
        self.bucket = 0.0
        self.loaded = 0.0
        self.removed = 0.0
        self.digs: list[DigRecord] = []
        self.dumps = 0
        self.load_curve: list[tuple[float, float]] = []
        self.travel = {mid: 0.0 for mid in m.ids}
        self.station: tuple[Pose, float, float] | None = None  # excavator: pose, track level, tilt
        self.memo: dict[Any, Any] = {}  # what a rule computes once per judgement (e.g. the cells under a parked truck)
        self.soil = scenario.soil
        self.truck_capacity = scenario.truck_holds  # bank m³
        #: the last cut's slump window, the cells it lowered and the most it lowered one, until it settles
        self.unsettled: tuple[tuple[int, int, int, int], np.ndarray, np.ndarray, float] | None = None
        #: with soil and a loader, the firm ground: the heights less the loose material slumping left on
        #: top (what a wheel stands on); otherwise the heights themselves
        self.firm: np.ndarray | None = None if self.soil is None or m.loader is None else self.z.copy()
        #: with soil, the top of its harder layer under every cell (None: no such layer)
        self.hard_top = None if self.soil is None else hard_top(self.soil, self.sc.terrain.z)


__getattr__ = compat.forward(__name__)  # Timeline: moved to earthbench.motion (earthbench.compat)
