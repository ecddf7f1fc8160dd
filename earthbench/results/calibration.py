"""Calibration: each machine class's cycles and bucket fills, as the referee judges them, against
the handbook's bands (docs/machine-classes.md; ``earthbench calibration``).

Every figure here is the referee's: a dig–swing–dump–return plan (a wheel loader's charge,
reverse turn, drive, dump and return) is built at each machine's fastest valid durations with
the public motion functions, a planner's tools, and judged with :func:`earthbench.referee.judge`,
the same timing and soil model that scores planners; a cycle is the time between two dumps' ends
of the judged plan (its ``load_curve``), a fill the bank volume of a judged full stroke ÷ the
bucket's capacity × the soil's swell (loose ÷ heaped, the handbook's measure). A plan the referee
refuses is an error, never a figure; so is a cycle plan that stays valid 1 % faster, which would
mean its durations are not the referee's fastest.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from ..classes import MachineClass, machine_classes
from ..errors import EarthbenchError
from ..motion import min_dig_time, min_dump_time
from ..plan import Charge, Dig, Dump, Move, Plan
from ..referee import Verdict, judge
from ..soil import nominal
from ..world import Heightmap, LoaderSpec, Machines, Pose, Scenario, Site, Soil, Task, TruckSpec

EPS = 1e-6
#: The angles a band of swing angles is judged at: its ends and its middle.
_MATERIALS = ("sand", "loam", "clay")
_SWINGS = (45.0, 67.5, 90.0, 135.0, 180.0)


@dataclass(frozen=True)
class Row:
    """One condition of one class: earthbench's figure, the handbook's band and whether it is inside."""

    machine_class: str
    what: str
    machine: str
    condition: str
    figure: float
    unit: str
    band: tuple[float, float] | None
    source: str

    @property
    def inside(self) -> bool | None:
        """Whether the figure lies in the band (to the printed precision); None without a band."""
        if self.band is None:
            return None
        return self.band[0] - 5e-4 <= self.figure <= self.band[1] + 5e-4


def _judged(sc: Scenario, actions: list) -> Verdict:
    v = judge(sc, Plan(tuple(actions)))
    if not v.valid:
        raise EarthbenchError(f"calibration plan on {sc.id!r} is invalid: {v.violations[0].message}")
    return v


def _fastest(sc: Scenario, faster: list) -> None:
    """Refuse a calibration whose plan stays valid 1 % faster: its durations would not be the
    referee's fastest, and its cycle not the machine's."""
    if judge(sc, Plan(tuple(faster))).valid:
        raise EarthbenchError(f"calibration plan on {sc.id!r} stays valid 1 % faster: its durations are not the fastest")


def _flat(sc_id: str, size: tuple[float, float, float, float], z: np.ndarray, dig_area: tuple, machines: Machines,
          track: str = "backhoe", soil: Soil | None = None) -> Scenario:
    x0, _, y0, _ = size
    return Scenario(id=sc_id, terrain=Heightmap((x0, y0), 0.1, z), site=Site(dig_area, floor=0.0, open_outside=True),
                    machines=machines, task=Task(1.0), track=track, soil=soil)  # type: ignore[arg-type]


def _backhoe_site(mc: MachineClass, swing_deg: float, soil: Soil | None = None) -> Scenario:
    """Flat ground 2 m above the floor, the excavator at the origin facing +x, the truck broadside
    at ``swing_deg`` from the dig's bearing, as near as its clearance and the bucket's reach allow."""
    e, t = mc.excavator, mc.truck
    d = max(e.clearance + 0.3, min(e.reach_max + t.loading_radius - 0.3, e.reach_max))
    a = math.radians(swing_deg)
    truck = Pose(d * math.cos(a), d * math.sin(a), a + math.pi / 2)
    nx, ny = 400, 400
    z = np.full((ny, nx), 2.0)
    area = ((e.reach_min, -1.5), (e.reach_max + 0.5, -1.5), (e.reach_max + 0.5, 1.5), (e.reach_min, 1.5))
    machines = Machines(truck=t, truck_pose=truck, excavator=e, excavator_pose=Pose(0.0, 0.0, 0.0),
                        machine_class=mc.name)
    return _flat(f"calibration/{mc.name}/swing{swing_deg:g}", (-20.0, 20.0, -20.0, 20.0), z, area, machines, soil=soil)


def _backhoe_plan(sc: Scenario, cycles: int, depth: float, stretch: float = 1.0) -> list:
    """``cycles`` digs (each a full stroke at ``depth`` on fresh ground along +x) and dumps at the
    fastest durations the public motion functions give (× ``stretch``)."""
    e = sc.machines.excavator
    assert e is not None
    base, truck = Pose(0.0, 0.0, 0.0), sc.machines.truck_pose
    out: list = []
    t, turn = 0.0, 0.0
    for k in range(cycles):
        contact = (e.reach_max - 0.3 - k * (e.max_drag_length + 0.1), 0.0)
        dur = min_dig_time(base, turn, contact, e) * stretch + EPS
        out.append(Dig("excavator", t, t + dur, contact, math.pi, depth, e.max_drag_length))
        t, turn = t + dur, 0.0
        dur = min_dump_time(base, turn, (truck.x, truck.y), e) * stretch + EPS
        out.append(Dump("excavator", t, t + dur))
        t, turn = t + dur, math.atan2(truck.y, truck.x)
    return out


def backhoe_cycle(mc: MachineClass, swing_deg: float) -> float:
    """The referee's excavator cycle (s) at ``swing_deg`` between the dig and the truck: the time
    from one dump's end to the next's, digging a full stroke each time."""
    sc = _backhoe_site(mc, swing_deg)
    v = _judged(sc, _backhoe_plan(sc, 2, mc.excavator.max_cut_depth))
    _fastest(sc, _backhoe_plan(sc, 2, mc.excavator.max_cut_depth, 0.99))
    return v.load_curve[1][0] - v.load_curve[0][0]


def backhoe_fill(mc: MachineClass, material: str) -> float:
    """The referee's fill (loose ÷ heaped) of one full-depth stroke in ``material``'s nominal soil."""
    soil = nominal(material, mc.name)
    sc = _backhoe_site(mc, 90.0, soil)
    v = _judged(sc, _backhoe_plan(sc, 1, mc.excavator.max_cut_depth))
    return v.digs[0].fill * soil.swell


def _arc(start: tuple[float, float, float], curvature: float, length: float, t0: float, speed: float, n: int = 32) -> Move:
    """A loader move along an arc of signed ``length`` (negative: in reverse) at ``speed``."""
    x0, y0, th0 = start
    s = np.linspace(0.0, length, n + 1)
    if curvature == 0.0:
        x, y, th = x0 + s * math.cos(th0), y0 + s * math.sin(th0), np.full_like(s, th0)
    else:
        th = th0 + curvature * s
        x = x0 + (np.sin(th) - math.sin(th0)) / curvature
        y = y0 - (np.cos(th) - math.cos(th0)) / curvature
    t = t0 + np.abs(s) / speed + EPS
    t[0] = t0
    return Move("loader", tuple((float(a), float(b), float(c), float(d)) for a, b, c, d in zip(t, x, y, th)))


def _loader_site(mc: MachineClass, soil: Soil | None = None) -> tuple[Scenario, float]:
    """A block of material 1.5 m high east of x = 0 on a level floor, the loader's bucket at its
    face; the truck where a reverse quarter turn and a short drive north bring the bucket to it.
    Returns the scenario and the penetration of one charge."""
    ld, t = mc.loader, mc.truck
    r = ld.min_turning_radius + 0.5
    z = np.zeros((400, 500))
    z[:, 300:] = 1.5
    need = ld.bucket_capacity * (1.0 if soil is None else soil.fill_factor)
    depth = 1.5 if soil is None or soil.hard_depth is None else min(1.5, soil.hard_depth + soil.hard_penetration)
    pen = math.ceil(need / (ld.bucket_width * depth) / 0.1 - 1e-9) * 0.1  # fills the bucket within the last cell
    x1 = -ld.bucket_offset + pen
    gap = max(ld.clearance, ld.bucket_offset + t.loading_radius) + 0.05
    truck = Pose(x1 - r, -r + _drive(ld, t) + gap, 0.0)
    machines = Machines(truck=t, truck_pose=truck, excavator=None, excavator_pose=None, loader=ld,
                        loader_pose=Pose(-ld.bucket_offset, 0.0, 0.0), machine_class=mc.name)
    area = ((0.0, -19.9), (19.9, -19.9), (19.9, 19.9), (0.0, 19.9))
    return _flat(f"calibration/{mc.name}/loader", (-30.0, 20.0, -20.0, 20.0), z, area, machines, "wheel_loader", soil), pen


def _drive(ld: LoaderSpec, t: TruckSpec) -> float:
    """The drive north to the truck: at least 2 m, and enough that the truck, broadside beyond it,
    stands clear of the loader's body as it backs out of the pile."""
    r = ld.min_turning_radius + 0.5
    gap = max(ld.clearance, ld.bucket_offset + t.loading_radius) + 0.05
    return max(2.0, ld.wheel_width / 2 + t.width / 2 + 0.3 - gap + r)


def _loader_plan(sc: Scenario, pen: float, cycles: int, stretch: float = 1.0) -> list:
    """Charge, reverse a quarter turn, drive north (:func:`_drive`), dump, reverse, turn forward back to
    the new face; ``cycles`` times, at the fastest durations the loader's limits allow (× ``stretch``)."""
    ld = sc.machines.loader
    assert ld is not None
    r = ld.min_turning_radius + 0.5
    v_arc, v = min(ld.travel_speed, ld.yaw_rate * r) / stretch, ld.travel_speed / stretch
    drive = _drive(ld, sc.machines.truck)
    out: list = []
    t, x = 0.0, -ld.bucket_offset
    for _ in range(cycles):
        dur = max(ld.min_charge_time, pen / ld.penetration_speed) * stretch + EPS
        out.append(Charge("loader", t, t + dur, (x, 0.0, 0.0), pen))
        x, t = x + pen, t + dur
        out_turn = _arc((x, 0.0, 0.0), -1.0 / r, -r * math.pi / 2, t, v_arc)
        fwd = _arc(out_turn.path[-1][1:], 0.0, drive, out_turn.t_end, v)
        dump_end = fwd.t_end + ld.min_dump_time * stretch + EPS
        back = _arc(fwd.path[-1][1:], 0.0, -drive, dump_end, v)
        turn = _arc(back.path[-1][1:], -1.0 / r, r * math.pi / 2, back.t_end, v_arc)
        out += [out_turn, fwd, Dump("loader", fwd.t_end, dump_end), back, turn]
        t = turn.t_end
    return out


def loader_cycle(mc: MachineClass) -> float:
    """The referee's wheel-loader cycle (s): one dump's end to the next's."""
    sc, pen = _loader_site(mc)
    v = _judged(sc, _loader_plan(sc, pen, 2))
    _fastest(sc, _loader_plan(sc, pen, 2, 0.99))
    return v.load_curve[1][0] - v.load_curve[0][0]


def loader_fill(mc: MachineClass, material: str) -> float:
    """The referee's fill (loose ÷ heaped) of one full charge into a pile of ``material``'s nominal
    soil (loose, so without the harder layer): the longest charge the referee accepts (it refuses
    a bucket pushed on through what it cannot take), from the cut model's estimate down, cell by cell."""
    soil = dataclasses.replace(nominal(material, mc.name), hard_depth=None)
    sc, pen = _loader_site(mc, soil)
    while pen > 0.05:
        v = judge(sc, Plan(tuple(_loader_plan(sc, pen, 1))))
        if v.valid:
            return v.digs[0].fill * soil.swell
        pen = round(pen - 0.1, 9)
    raise EarthbenchError(f"no charge on {sc.id!r} is valid")


def rows(mc: MachineClass) -> Iterator[Row]:
    """Every row of class ``mc``: its bands judged (each swing band at its ends and middle), or,
    for an uncalibrated class, the same conditions without a band."""
    bands = [b for b in mc.bands if b.what in ("cycle", "fill")] if mc.calibrated else []
    if not bands:
        for a in _SWINGS:
            yield Row(mc.name, "cycle", "excavator", f"swing {a:g}°", backhoe_cycle(mc, a), "s", None, mc.compared_with)
        yield Row(mc.name, "cycle", "loader", "V-pattern, 90° reverse turn", loader_cycle(mc), "s", None, mc.compared_with)
        for m in _MATERIALS:
            yield Row(mc.name, "fill", "excavator", f"{m} full stroke", backhoe_fill(mc, m), "", None, mc.compared_with)
        return
    for b in bands:
        if b.what == "cycle" and b.machine == "excavator" and b.swing_deg is not None:
            lo, hi = b.swing_deg
            for a in (lo, (lo + hi) / 2, hi):
                yield Row(mc.name, "cycle", "excavator", f"swing {a:g}° (band {lo:g}–{hi:g}°)", backhoe_cycle(mc, a), "s",
                          b.band, b.source)
        elif b.what == "cycle":
            yield Row(mc.name, "cycle", b.machine, "V-pattern, 90° reverse turn", loader_cycle(mc), "s", b.band, b.source)
        elif b.what == "fill" and b.material is not None:
            fill = backhoe_fill if b.machine == "excavator" else loader_fill
            how = f"{mc.excavator.max_cut_depth:g} m deep stroke" if b.machine == "excavator" else "pile, full charge"
            yield Row(mc.name, "fill", b.machine, f"{b.material} {how}", fill(mc, b.material), "", b.band, b.source)


def calibration(names: list[str] | None = None) -> list[Row]:
    """The rows of the named machine classes (every class when None)."""
    known = machine_classes()
    return [row for name, mc in known.items() if names is None or name in names for row in rows(mc)]
