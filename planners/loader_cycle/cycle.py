"""The loader's cycle (:class:`CycleBuilder`): charge, reverse out, two arcs to the truck, dump,
return; the first candidate whose charge, route to the truck and approach are all feasible wins."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from earthbench.plan import Charge, Dump, Move, Plan, Prediction
from earthbench.planner import Observation, closed_loop_setting
from earthbench.rules import loader_base_level
from earthbench.world import LoaderSpec, Pose, Scenario

from ..truck_load import SCAN_ALLOWANCE, LoadBound
from .charge import ChargeResult, charge_model, entry_for, simulate_charge
from .contours import zero_contour
from .routes import MARGIN, Route, RouteOptions, dump_rays, search_dubins, search_routes
from .scan import read_scan
from .soil_model import SoilModel


@dataclass(frozen=True)
class LoaderPlanConfig:
    """Settings the loader planners share."""

    contour_level: float = 0.02
    """Height (m) above the floor of the pile's zero contour on exact ground; on a scan, at
    least 5 smoothed σ of its estimated noise (:func:`read_scan`)."""
    contour_spacing: float = 0.1
    max_penetration: float = 4.0
    max_tries: int = 80
    """Candidates tried per bucket (those within 0.25 m of a failed one are skipped)."""
    max_cycles: int = 60
    dump_sector: float = math.radians(160.0)
    """Dump poses lie within this sector around the bearing from the truck to the charge's end."""
    charge_share: float = 0.85
    """With soil, a charge's path holds at most this share of the bucket's capacity on the
    planner's ground, so the scan's error cannot make the edge push on after the bucket is full
    (the ``overfill`` rule is judged on the true ground); a charge aims at 1.1 × the nominal fill.
    Each further cycle planned without a new scan lowers it (:meth:`CycleBuilder.drift`)."""
    closed_loop: bool = closed_loop_setting()
    """Replan every bucket from the observed terrain and truck load (docs/DESIGN.md §6)."""


@dataclass
class Cycle:
    approach: Route
    charge: Charge
    charge_result: ChargeResult
    to_truck: Route
    dump: Dump
    candidate: dict = field(default_factory=dict)


class CycleBuilder:
    """State of one loader plan: terrain copy, time, pose, actions; tries candidates in order.

    The ground is :func:`read_scan` of the scenario's grid; ``z0`` (default: the same) is the
    first ground the planner saw, under which the soil's harder layer lies; ``yield_factor``
    scales what a charge is expected to deliver (a closed loop learns it from the truck)."""

    def __init__(self, scenario: Scenario, cfg: LoaderPlanConfig, opts: RouteOptions | None = None,
                 z0: np.ndarray | None = None, yield_factor: float = 1.0):
        self.sc, self.cfg = scenario, cfg
        self.opts = opts or RouteOptions()
        self.spec: LoaderSpec = scenario.machines.loader
        self.base = loader_base_level(scenario)
        self.level = scenario.site.floor if scenario.site.floor is not None else self.base
        self.ground = read_scan(scenario.terrain, self.level, cfg.contour_level)
        self.z = self.ground.z
        self.firm = self.z
        self.step_base = self.base - self.ground.margin
        self.soil = SoilModel.of(scenario.soil, self.z if z0 is None else z0)
        self.load = LoadBound.of(scenario)
        self.yield_factor = yield_factor
        self.share = cfg.charge_share
        self.t = 0.0
        self.pose = scenario.machines.loader_pose
        self.actions: list = []
        self.loaded = self.loaded0 = 0.0
        self.most = 0.0
        self.path_cap = math.inf
        self.rays, self.d_lo, self.d_hi, self.d_target = dump_rays(scenario)
        self.cycles: list[Cycle] = []
        self.tried = 0

    def contours(self) -> list[np.ndarray]:
        return zero_contour(self.sc.terrain, self.z, self.level + self.ground.level, self.cfg.contour_spacing, self.spec.bucket_width)

    @property
    def take(self) -> float:
        """The most a charge's path holds on the planner's ground: the capacity on exact ground;
        with soil, 1.1 × the nominal fill, at most :attr:`share` of the capacity."""
        if self.soil is None:
            return self.spec.bucket_capacity
        return min(self.share, 1.1 * self.soil.fill) * self.spec.bucket_capacity

    def drift(self) -> None:
        """One more cycle planned on ground the planner has not seen since (open loop, with
        soil): its model of the cut, the slump and the harder layer drifts from the truth, so
        the overfill share shrinks by 2.5 % of the capacity (to 60 %) and the step margin grows
        by 1 cm (to 5 cm) per such cycle."""
        if self.soil is None:
            return
        self.share = max(self.share - 0.025, 0.6)
        self.step_base = max(self.step_base - 0.01, self.base - self.ground.margin - 0.05)

    @property
    def room(self) -> float:
        """The least bank m³ the truck can take from this plan's charges: its loose capacity at
        the class's largest swell, less what it held when the plan began (exact ground: no
        bound, the cut model is the referee's)."""
        return math.inf if self.load is None else self.load.room - self.loaded0

    def truck_took_all(self, most: float) -> bool:
        """Whether the truck surely took all of charges that delivered at most ``most``: only
        then does a further charge start with an empty bucket (the ``bucket_not_empty`` rule;
        a dump into a full truck leaves the rest in the bucket). An open-loop plan cannot see
        the truck fill, so it bounds what its charges may really deliver
        (:attr:`ChargeResult.most`) by the class's fullest bucket and its largest swell
        (:class:`LoadBound`)."""
        return self.load is None or self.load.took_all(most, self.loaded0)

    def public_cap(self, most: float, capacity: float, need: float, share: float) -> float:
        """The most the next charge's path may hold on the public cut model (the overfill rule's
        ``share`` of the capacity) after charges that delivered at most ``most``, when it is
        sized ``capacity`` and the truck still needs ``need``: a charge that is not the last
        (it cannot deliver ``need``) leaves what the truck surely takes for the next one
        (:meth:`truck_took_all`), unless that is under a quarter of a bucket: then it is a full
        charge, and the last."""
        cap = share * self.spec.bucket_capacity
        if self.load is None or capacity * self.yield_factor >= need:
            return cap
        left = self.room - most - SCAN_ALLOWANCE * self.spec.bucket_capacity
        return cap if left < 0.25 * self.spec.bucket_capacity else min(cap, left)

    def charge_capacity(self, need: float) -> float:
        """What a charge's path should hold on the planner's ground when the truck still needs
        ``need`` m³: enough to deliver it (at the nominal fill and the learnt yield), at most
        :attr:`take`."""
        return min(self.take, need / self.yield_factor + 0.02)

    def _simulate(self, entry: tuple[float, float, float], capacity: float) -> ChargeResult | None:
        return simulate_charge(self.sc.terrain, self.z, self.spec, entry, capacity, self.cfg.max_penetration, self.level,
                               self.base, self.firm, self.soil, self.step_base,
                               min(self.share * self.spec.bucket_capacity, self.path_cap), self.load)

    def try_candidate(self, M: np.ndarray, h: np.ndarray, capacity: float) -> Cycle | None:
        """Approach, charge and route to the truck for the bucket edge centred at ``M`` heading
        ``h`` into the pile; None if any part is infeasible."""
        self.tried += 1
        entry = entry_for(self.sc.terrain, self.z, self.spec, M, h, self.base)
        if entry is None:
            return None
        ex, ey, eyaw = entry
        # cheapest checks first: the charge, then the two arcs to the truck, then the approach
        ch = self._simulate(entry, capacity)
        if ch is None:
            return None
        dur = max(self.spec.min_charge_time, ch.penetration / (self.spec.penetration_speed * MARGIN)) + 1e-6
        # dump poses on the side of the truck the loader comes from leave room to back out again
        bearing = math.atan2(ch.end[1] - self.sc.machines.truck_pose.y, ch.end[0] - self.sc.machines.truck_pose.x)
        side = np.abs(np.angle(np.exp(1j * (np.arctan2(self.rays[:, 3], self.rays[:, 2]) - bearing)))) <= self.cfg.dump_sector / 2
        to_truck = search_routes(
            self.sc, ch.firm, Pose(*ch.end), 0.0, self.rays[side], self.d_lo, 14.0, self.d_hi, self.d_target, self.opts, self.step_base
        )
        if to_truck is None:
            return None
        ray = np.array([[ex, ey, -math.cos(eyaw), -math.sin(eyaw)]])
        routes = [
            search_routes(self.sc, self.firm, self.pose, self.t, ray, 0.0, 12.0, 0.0, 0.0, self.opts, self.step_base),
            search_dubins(self.sc, self.firm, self.pose, self.t, entry, self.opts, self.step_base),
        ]
        routes = [r for r in routes if r is not None]
        if not routes:
            return None
        approach = min(routes, key=lambda r: r.duration)  # the two-arc return, or a faster Dubins one
        t1 = float(approach.t[-1])
        yaw = float(approach.p[-1, 2])
        if (math.cos(yaw), math.sin(yaw)) != (math.cos(eyaw), math.sin(eyaw)):
            # the route's yaw differs from the simulated one by rounding (or 2π): cut again with
            # exactly the charge the referee will replay, so the prediction stays exact
            vol, zz, firm = charge_model(self.sc.terrain, self.z, self.firm, self.spec, (ex, ey, yaw), ch.penetration, self.level,
                                         capacity, self.soil)
            delivered = vol if self.soil is None else min(vol, self.soil.fill * self.spec.bucket_capacity)
            ch = ChargeResult(ch.penetration, vol, zz, ch.end, firm, delivered, ch.most)
        entry = (ex, ey, yaw)
        charge = Charge("loader", t1, t1 + dur, entry, ch.penetration)
        to_truck = to_truck.shifted(t1 + dur)
        t2 = float(to_truck.t[-1])
        dump = Dump("loader", t2, t2 + self.spec.min_dump_time + 1e-6)
        return Cycle(approach, charge, ch, to_truck, dump)

    def first_feasible(self, M: np.ndarray, h: np.ndarray, order: np.ndarray, capacity: float, failed: list[np.ndarray],
                       max_tries: int) -> tuple[Cycle | None, int]:
        """The first candidate of ``order`` whose cycle is feasible, and its index (-1 if none).

        At most ``max_tries`` are tried; a candidate within 0.25 m of one that already failed
        (``failed``, which grows) is passed over untried, as it would fail the same way."""
        tries = 0
        for k in order:
            if tries >= max_tries:
                break
            if failed and np.min(np.hypot(*(np.array(failed) - M[k]).T)) < 0.25:
                continue
            tries += 1
            cycle = self.try_candidate(M[k], h[k], capacity)
            if cycle is not None:
                return cycle, int(k)
            failed.append(M[k])
        return None, -1

    def commit(self, c: Cycle) -> None:
        if len(c.approach.t) > 1:
            self.actions.append(Move("loader", tuple(c.approach.samples)))
        self.actions.append(c.charge)
        self.actions.append(Move("loader", tuple(c.to_truck.samples)))
        self.actions.append(c.dump)
        self.z = c.charge_result.z
        self.firm = c.charge_result.firm
        self.loaded += c.charge_result.delivered * self.yield_factor
        self.most += c.charge_result.most
        self.t = c.dump.t_end
        self.pose = c.to_truck.end
        self.cycles.append(c)
        self.drift()

    def load_until_target(self, max_cycles: int, choose: Callable[[list[np.ndarray], float], Cycle | str],
                          max_dumps: int | None = None) -> str:
        """The loop both loader planners share: while the truck lacks its target, ask ``choose``
        for the next cycle given the pile's contours and the bucket's capacity for this cycle
        (never much more than the target still needs), and commit it. ``choose`` returns a
        feasible :class:`Cycle`, or the reason to stop. ``max_dumps`` ends a closed-loop step
        after that many cycles; no cycle follows one after which the truck may be full
        (:meth:`truck_took_all`). Returns why loading stopped."""
        target = self.sc.task.target_volume
        while self.loaded < target - 1e-9:
            if len(self.cycles) >= max_cycles:
                return "max_cycles"
            if self.cycles and not self.truck_took_all(self.most):
                return "truck may be full"
            if max_dumps is not None and len(self.cycles) >= max_dumps:
                return "step done"
            lines = self.contours()
            if not lines:
                return "no contour left"
            capacity = self.charge_capacity(target - self.loaded)
            if max_dumps is None or len(self.cycles) + 1 < max_dumps:  # a cycle of this plan may follow
                self.path_cap = self.public_cap(self.most, capacity, target - self.loaded, self.share)
            chosen = choose(lines, capacity)
            if isinstance(chosen, str) and capacity > 0.5 * self.spec.bucket_capacity:
                # a smaller charge is a shorter one: its wheels stay off the bank a full one would climb
                chosen = choose(lines, capacity / 2)
            self.path_cap = math.inf
            if isinstance(chosen, str):
                return chosen
            self.commit(chosen)
        return "target loaded"

    def plan(self, info: dict) -> Plan:
        info = dict(info, cycles=len(self.cycles), candidates_tried=self.tried)
        return Plan(tuple(self.actions), Prediction(volume=self.loaded - self.loaded0, makespan=self.t), info)

    @classmethod
    def observed(cls, observation: Observation, cfg: LoaderPlanConfig, z0: np.ndarray | None = None,
                 yield_factor: float = 1.0) -> CycleBuilder:
        """A closed-loop step's builder: from the observed terrain and pose, at the plan time
        and truck load the harness reports."""
        b = cls(observation.scenario, cfg, z0=z0, yield_factor=yield_factor)
        b.t, b.loaded, b.loaded0 = observation.t, observation.loaded, observation.loaded
        return b
