"""Algorithm 1: a global problem over local areas, then one local problem per chosen area.

1. Fit the surface (``earthbench_planners.stl_tamp.surface.fit_rbf``; counted in the solve time).
2. Candidate local areas tile the dig area (side √S_l, S_l = 5 buckets); a greedy tour from the
   excavator's start, by estimated volume per second of travel and digging, seeds the global
   problem (contact at each area's far edge, base ``base_offset`` beyond the area toward the
   truck's side, truck behind the base).
3. Global: the same :class:`~earthbench_planners.stl_tamp.model.PhaseNLP` with the area as the unit
   (V_max = 1 m³ per area, m_g phases); the areas with η ≥ ``eta_on`` in phase order are the
   local areas. If the global solve fails, its seed tour is used (recorded in ``plan.info``).
4. Local: for each area, a fresh window fit of the *current* grid (after the digs already
   planned) becomes the terrain parameter; the local NLP (bucket unit, m_l phases) starts from
   an IK guess at spread-out contacts and the global base/truck poses, with a terminal cost
   toward the next area's base. Its phases become actions (``convert``), checked against the
   referee's rules on the real grid. The local target is what the target still lacks
   (measured with the referee's cut), capped at the area's V_max (at m_l buckets when the dig
   area is a single local area), so model error in one area is made up in the next; when the
   global areas run out, further areas come from the tour.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from shapely.geometry import Polygon

from earthbench.world import Pose, Scenario
from .surface import RbfSurface, fit_rbf

from .convert import TILT_MARGIN, SimState
from .judge import AT_THE_STAND, StandJudge
from .guess import PhaseSeed
from .problem import Shape

if TYPE_CHECKING:  # CasADi loads with the first NLP, not with the planner (problem.py)
    from .model import PhaseNLP

_NLP_CACHE: dict[Any, PhaseNLP] = {}


class StlTampSolveError(RuntimeError):
    """A local solve failed and the configuration allows no fallback (``on_failure="raise"``)."""


def get_nlp(shape: Shape, scenario: Scenario, box: tuple[float, float, float, float]) -> tuple[PhaseNLP, bool]:
    """The process-wide NLP of this shape, machines and site box (built on first use)."""
    from .model import PhaseNLP

    key = (shape, scenario.machines.excavator, scenario.machines.truck, box)
    hit = key in _NLP_CACHE
    if not hit:
        _NLP_CACHE[key] = PhaseNLP(shape, scenario.machines.excavator, scenario.machines.truck, box)
    return _NLP_CACHE[key], hit


@dataclass(frozen=True)
class LocalProblem:
    """One area's local NLP as ``stl-tamp`` and ``separate`` both set it up (step 4 above): the
    process-wide NLP of the local shape, the surface fitted to the current grid around the area
    (``fit_time_s``: the fit's seconds), the site's floor (0 without one), the start state with
    the arm's joints where the last area left them, and the packed parameters."""

    nlp: PhaseNLP
    surf: RbfSurface
    fit_time_s: float
    floor: float
    s0: np.ndarray
    params: np.ndarray


NODE0_TOLERANCE = 1e-3  # m: within this of Eq. (23)'s clearance (IPOPT's tolerance leaves trucks ~0.3 mm in), node 0 stays
NODE0_PUSH = 0.01  # m beyond the clearance that :func:`nlp_start` puts a truck nearer than that


def nlp_start(st: SimState, shape: Shape, exc: Any) -> np.ndarray:
    """The NLP's first node (``st.s0``), with a truck that stands nearer the base than Eq. (23)'s
    clearance plus ``shape.col_margin`` (the referee asks only the clearance) seen a centimetre
    beyond it, pushed out along the base–truck line: node 0 is fixed, so its clearance row alone
    made every problem from there infeasible (stl-tamp 0.12.2, separate 0.5.2; planners/stl_tamp/
    NOTES.md, "0.12.2"). The converter drives the truck from where it is. A truck within
    ``NODE0_TOLERANCE`` of the distance or farther: ``st.s0`` as it is."""
    s0 = st.s0
    lcol = exc.clearance + shape.col_margin
    dx, dy = s0[6] - s0[0], s0[7] - s0[1]
    d = math.hypot(dx, dy)
    if 0.0 < d < lcol - NODE0_TOLERANCE:
        out = (lcol + NODE0_PUSH) / d
        s0[6], s0[7] = s0[0] + dx * out, s0[1] + dy * out
    return s0


def local_problem(scenario: Scenario, st: SimState, area: Area, shape: Shape, box: tuple[float, float, float, float],
                  joints: tuple[float, float], *, fit_spacing: float, fit_half: float, fit_solver: str, vt: float,
                  alpha: tuple[float, float, float, float, float], goal: tuple[float, float]) -> LocalProblem:
    """The local problem of ``area`` on the grid as it now is (``st.z``): a window fit of
    ``±fit_half`` m at ``fit_spacing`` (``fit_solver``: :func:`~.surface.fit_rbf`'s), the
    target ``vt``, the weights ``alpha`` and the terminal ``goal`` (the next area's base)."""
    nlp, _ = get_nlp(shape, scenario, box)
    floor = scenario.site.floor if scenario.site.floor is not None else 0.0
    t0 = time.perf_counter()
    cx, cy = area.centre
    surf = fit_rbf(scenario.terrain.with_z(st.z), spacing=fit_spacing, window=(cx - fit_half, cx + fit_half, cy - fit_half, cy + fit_half),
                   shape=shape.terrain_shape, margin=0, solver=fit_solver)
    fit_time_s = time.perf_counter() - t0
    s0 = nlp_start(st, shape, scenario.machines.excavator)
    s0[4], s0[5] = joints
    params = nlp.pack_p(w=surf.weights.reshape(-1), o=(surf.x0, surf.y0), s0=s0, vt=vt, alpha=alpha, goal=goal, floor=floor)
    return LocalProblem(nlp, surf, fit_time_s, floor, s0, params)


@dataclass
class Area:
    """A local area: its far-edge contact ``(px, py)``, drag heading, base and truck poses."""

    px: float
    py: float
    psi: float
    base: tuple[float, float]
    truck: tuple[float, float]
    estimate: float
    centre: tuple[float, float]
    source: str = "tour"
    toward: Area | None = None  # facing away from the truck: the same tile facing it (the fallback)
    swing: float = 0.0  # the least swing (rad) a dump from it costs, the truck off the dig area (.stand.least_swing)


@dataclass
class Standless:
    """Visits to areas for which the truck has no stand (:func:`.stand.truck_stand`) that dug and
    that dug nothing, and such areas passed over once they proved hopeless on the site (stl-tamp
    0.12.1, separate 0.5.1): on a site larger than the truck's reach nearly all of them lie beyond
    dump reach, each costing a local solve and a drive for nothing; on a small site the NLP's truck
    often serves them. No area passed over: the plan is the one of the versions before."""

    dug: int = 0
    fruitless: int = 0
    passed: int = 0

    def hopeless(self, tries: int) -> bool:
        """At least ``tries`` × (1 + the visits that dug) fruitless visits (``tries`` 0: never)."""
        return tries > 0 and self.fruitless >= tries * (self.dug + 1)

    def visited(self, dug: bool) -> None:
        self.dug += dug
        self.fruitless += not dug

    def record(self) -> dict[str, int]:
        return {"dug": self.dug, "fruitless": self.fruitless, "passed_over": self.passed}


@dataclass
class Trace:
    """What happened, for ``plan.info`` and the report."""

    fit_time_s: float = 0.0
    build_time_s: float = 0.0
    global_: dict[str, Any] = field(default_factory=dict)
    locals_: list[dict[str, Any]] = field(default_factory=list)
    fallbacks: int = 0
    regenerated: int = 0
    standless: Standless = field(default_factory=Standless)  # areas without a truck stand (0.12.1)
    nlp_cache: dict[str, int] = field(default_factory=dict)  # NLPs loaded ("hit") or built ("miss", "off")
    # solves by FATROP and by IPOPT, and FATROP's failures IPOPT solved again ("fallback")
    solvers: dict[str, int] = field(default_factory=lambda: {"fatrop": 0, "ipopt": 0, "fallback": 0})

    def add_build(self, nlp: PhaseNLP) -> None:
        """Count the NLP's construction seconds not yet reported and, once, how it was made."""
        self.build_time_s += nlp.take_build_time()
        for k, v in nlp.take_solver_counts().items():
            self.solvers[k] = self.solvers.get(k, 0) + v
        state = nlp.take_cache_state()
        if state is not None:
            self.nlp_cache[state] = self.nlp_cache.get(state, 0) + 1


def site_box(scenario: Scenario) -> tuple[float, float, float, float]:
    xs, ys = zip(*scenario.site.dig_area)
    return (min(xs), max(xs), min(ys), max(ys))


def global_blocks(box: tuple[float, float, float, float], window: tuple[float, float]) -> list[tuple[float, float, float, float]]:
    """The site box split into equal tiles of at most ``window`` (m): the global layer's groups
    of areas. One tile (the box itself) when the site fits, as the paper's 12 m × 6 m map does."""
    xmin, xmax, ymin, ymax = box
    nx = max(1, math.ceil((xmax - xmin) / window[0] - 1e-9))
    ny = max(1, math.ceil((ymax - ymin) / window[1] - 1e-9))
    wx, wy = (xmax - xmin) / nx, (ymax - ymin) / ny
    return [(xmin + a * wx, xmin + (a + 1) * wx, ymin + b * wy, ymin + (b + 1) * wy) for b in range(ny) for a in range(nx)]


def global_lattice(window: tuple[float, float], spacing: float) -> tuple[int, int]:
    """(ny, nx) of the global surface over one window: the lattice ``fit_rbf`` gives a window
    of that size with its default margin, fixed so that every window shares one NLP."""
    return (math.ceil(round(window[1] / spacing, 9)) + 3, math.ceil(round(window[0] / spacing, 9)) + 3)


def in_box(pt: tuple[float, float], box: tuple[float, float, float, float]) -> bool:
    return box[0] <= pt[0] <= box[1] and box[2] <= pt[1] <= box[3]


def nearest_block(blocks: list[tuple[float, float, float, float]], areas: list[Area],
                  pos: tuple[float, float]) -> tuple[float, float, float, float]:
    """The tile with areas left whose centre is nearest to ``pos`` (ties: the first)."""
    live = [b for b in blocks if any(in_box(a.centre, b) for a in areas)]
    return min(live, key=lambda b: math.hypot(0.5 * (b[0] + b[1]) - pos[0], 0.5 * (b[2] + b[3]) - pos[1]))


def solve_counts(records: list[dict[str, Any]]) -> dict[str, int]:
    """How the local solves ended (the planner's own report, from IPOPT's status): succeeded
    (Solve_Succeeded at the planner's tolerance), acceptable (IPOPT's acceptable level), capped
    (iteration cap, feasible iterate accepted), fallback (the IK guess executed), other (failed
    past the fallback bound: the area was left undug)."""
    out = {"succeeded": 0, "acceptable": 0, "capped": 0, "fallback": 0, "other": 0}
    for r in records:
        st = str(r.get("status", ""))
        if "fallback" in r:
            out["fallback"] += 1
        elif st == "Solve_Succeeded":
            out["succeeded"] += 1
        elif st.startswith("Solved_To_Acceptable"):
            out["acceptable"] += 1
        elif "feasible iterate accepted" in st:
            out["capped"] += 1
        else:
            out["other"] += 1
    out["total"] = len(records)
    return out


def fitting_side(scenario: Scenario, side: float) -> float:
    """``side``, or less where the dig area is narrower: a square local area must fit in it
    (paper-switch's 2.0 × 1.75 m dig area is one local area)."""
    xmin, xmax, ymin, ymax = site_box(scenario)
    return min(side, xmax - xmin, ymax - ymin)


def diggable_volume(scenario: Scenario) -> float:
    """Material above the floor (or above the lowest cell) inside the dig area (m³)."""
    t = scenario.terrain
    xs, ys = t.cell_centres()
    poly = Polygon(scenario.site.dig_area)
    from shapely import contains_xy

    X, Y = np.meshgrid(xs, ys)
    inside = contains_xy(poly, X, Y)
    floor = scenario.site.floor if scenario.site.floor is not None else float(t.z[inside].min())
    return float(np.clip(t.z - floor, 0.0, None)[inside].sum() * t.cell_area)


def truck_side(scenario: Scenario) -> tuple[float, float]:
    """Unit axis direction from the dig area's centre toward the truck (the loading side)."""
    xmin, xmax, ymin, ymax = site_box(scenario)
    cx, cy = 0.5 * (xmin + xmax), 0.5 * (ymin + ymax)
    tp = scenario.machines.truck_pose
    dx, dy = tp.x - cx, tp.y - cy
    if abs(dy) >= abs(dx):
        return (0.0, 1.0 if dy >= 0 else -1.0)
    return (1.0 if dx >= 0 else -1.0, 0.0)


@dataclass(frozen=True)
class Layout:
    """How the areas face: the loading side (``toward_truck``, the drag direction) and the lateral
    axis signed toward the side the excavator starts on. Read once from a run's first state:
    closed loop, the truck and the excavator move, and axes read again from where they stand
    turned the areas (and their stands) to another side of the site between steps."""

    toward_truck: tuple[float, float]
    toward_start: tuple[float, float]


def site_layout(scenario: Scenario) -> Layout:
    """The :class:`Layout` of ``scenario``'s machines where they stand."""
    xmin, xmax, ymin, ymax = site_box(scenario)
    ux, uy = truck_side(scenario)
    tx, ty = -uy, ux
    ep = scenario.machines.excavator_pose
    if (ep.x - 0.5 * (xmin + xmax)) * tx + (ep.y - 0.5 * (ymin + ymax)) * ty < 0:
        tx, ty = -tx, -ty
    return Layout((ux, uy), (tx, ty))


#: How far (m, and in tiles) rounding may move a tile's edge past the dig area's and still count as inside.
TILE_TOL = 1e-9


def candidate_areas(scenario: Scenario, z: np.ndarray, side: float, depth: float, vmax: float, base_offset: float,
                    truck_offset: float, truck_angle: float = 0.0, layout: Layout | None = None,
                    facing_away: float | None = None, away_turns: tuple[float, ...] = (),
                    judge: StandJudge = AT_THE_STAND) -> list[Area]:
    """Areas tiling the dig area, with a volume estimate from the grid (top ``depth`` metres).

    The base sits ``base_offset`` beyond the area's centre toward the truck's side; the truck
    ``truck_offset`` from the base, turned by ``truck_angle`` from straight behind it toward the
    excavator's starting side (π/2: beside the base, a quarter swing from the area instead of a
    half swing; the excavator tours away from its start, so the truck stays out of its way).
    ``layout``: the sides to face (default: :func:`site_layout` of ``scenario``). A tile within
    ``facing_away`` of the truck's side also faces away from it (the base beyond it), its stand
    turned by each of ``away_turns`` (rad) in turn when the straight one is too steep; ``judge``:
    see :func:`level_stand`."""
    t = scenario.terrain
    xmin, xmax, ymin, ymax = site_box(scenario)
    lay = layout or site_layout(scenario)
    (ux, uy), (tx, ty) = lay.toward_truck, lay.toward_start
    floor = scenario.site.floor if scenario.site.floor is not None else float(z.min())
    xs, ys = t.cell_centres()
    # the tiles' count and containment tolerate rounding (TILE_TOL): a dig area exactly k tiles
    # wide, or exactly one tile wide, away from the origin (a sealed draw's shifted site) gave
    # widths of 11.999999999999998 m and tile edges one ulp outside it, and lost a row or its only tile
    poly = Polygon(scenario.site.dig_area).buffer(TILE_TOL, join_style="mitre")
    nxa = max(int(math.floor((xmax - xmin) / side + TILE_TOL)), 1)
    nya = max(int(math.floor((ymax - ymin) / side + TILE_TOL)), 1)
    ox = xmin + 0.5 * ((xmax - xmin) - nxa * side)
    oy = ymin + 0.5 * ((ymax - ymin) - nya * side)
    out = []
    # the dig area's edge on the truck's side, along the loading axis
    edge = max(x * ux + y * uy for x, y in scenario.site.dig_area)
    dx_t = math.cos(truck_angle) * ux + math.sin(truck_angle) * tx
    dy_t = math.cos(truck_angle) * uy + math.sin(truck_angle) * ty
    for a in range(nxa):
        for b in range(nya):
            x0, y0 = ox + a * side, oy + b * side
            cx, cy = x0 + side / 2, y0 + side / 2
            if not poly.contains(Polygon([(x0, y0), (x0 + side, y0), (x0 + side, y0 + side), (x0, y0 + side)])):
                continue
            ix = (xs >= x0) & (xs < x0 + side)
            iy = (ys >= y0) & (ys < y0 + side)
            cells = z[np.ix_(iy, ix)]
            est = float(np.minimum(np.clip(cells - floor, 0, None), depth).sum() * t.cell_area)
            est = min(est, vmax)
            if est < 0.05:
                continue
            area = None
            sides = [(ux, uy)]
            if facing_away is not None and (edge - (cx * ux + cy * uy)) + base_offset <= facing_away:
                sides.append((-ux, -uy))  # the base beyond the area from the truck: the truck may stand on the dig's bearing
            for k, (sx, sy) in enumerate(sides):
                base = level_stand(scenario, z, (cx, cy), (sx, sy), base_offset, side, judge)
                for turn in away_turns if base is None and k == 1 else ():
                    d = (math.cos(turn) * sx - math.sin(turn) * sy, math.sin(turn) * sx + math.cos(turn) * sy)
                    if (base := level_stand(scenario, z, (cx, cy), d, base_offset, side, judge)) is not None:
                        sx, sy = d
                        break
                if base is None:
                    continue  # no stand in reach of this area is level enough for the referee's tilt rule
                truck = (base[0] + dx_t * truck_offset, base[1] + dy_t * truck_offset)
                px, py = cx - sx * side / 2, cy - sy * side / 2
                area = Area(px, py, math.atan2(sy, sx), base, truck, est, (cx, cy), toward=area)
            if area is not None:
                out.append(area)
    if len(out) == 1 and out[0].toward is not None:
        out = [out[0].toward]  # a dig area that is one local area (Fig. 6's set-up) keeps the paper's layout
    return out


#: How far (m) a stand may slide along the line from the area toward the truck's side when the
#: nominal one is too steep: the area stays in reach for every one of these.
STAND_SHIFTS = (0.0, 0.5, -0.5, 1.0, -1.0)


def level_stand(scenario: Scenario, z: np.ndarray, centre: tuple[float, float], toward: tuple[float, float],
                base_offset: float, side: float, judge: StandJudge = AT_THE_STAND) -> tuple[float, float] | None:
    """The stand nearest the nominal one (``base_offset`` from the area's centre toward the
    truck's side) on which the referee's tilt rule lets the excavator work, facing the area;
    None when every stand in reach is too steep. The referee judges the tilt where the machine
    stands (:func:`earthbench.rules.track_level_and_tilt`), so a plan from a steep
    stand would be invalid whatever the NLP does there. ``judge``: how the tilt is judged
    (:class:`.judge.StandJudge`; by default at the stand, on ``z``)."""
    es = scenario.machines.excavator
    ux, uy = toward
    yaw = math.atan2(-uy, -ux)
    half = side / math.sqrt(2.0)
    for shift in STAND_SHIFTS:
        d = base_offset + shift
        if d - half < es.reach_min or d + half > es.reach_max:
            continue
        base = (centre[0] + ux * d, centre[1] + uy * d)
        if judge.tilt(scenario, z, es, Pose(base[0], base[1], yaw)) <= es.max_tilt - TILT_MARGIN:
            return base
    return None


def greedy_tour(areas: list[Area], start: tuple[float, float], target: float, speed: float, work_per_m3: float,
                reserve: float = 1.3, swing_per_m3: float = 0.0) -> list[Area]:
    """Areas in visiting order: best volume per second of travel and work, until ``reserve × target``;
    an area's work counts ``swing_per_m3`` seconds a m³ for each radian of its swing (``Area.swing``)."""
    left = list(areas)
    tour: list[Area] = []
    pos, got = start, 0.0
    while left and got < reserve * target:
        def score(a: Area, pos: tuple[float, float] = pos) -> float:
            travel = math.hypot(a.base[0] - pos[0], a.base[1] - pos[1]) / speed
            return a.estimate / (travel + (work_per_m3 + swing_per_m3 * a.swing) * a.estimate + 1.0)

        best = max(left, key=score)
        left.remove(best)
        tour.append(best)
        pos, got = best.base, got + best.estimate
    return tour + sorted(left, key=lambda a: -a.estimate)


def local_seeds(area: Area, k_active: int, m: int, bucket_w: float, drag: float, surf: RbfSurface, eta0: float,
                truck: tuple[float, float]) -> list[PhaseSeed]:
    """m bucket contacts spread over the area: rows across the drag, the first k_active dig."""
    ux, uy = math.cos(area.psi), math.sin(area.psi)
    nx_, ny_ = -uy, ux
    side = math.hypot(area.centre[0] - area.px, area.centre[1] - area.py) * 2
    across = max(side - bucket_w, 0.0)
    cols = max(int(math.floor(side / bucket_w)), 1)
    offs_c = [(-across / 2 + across * j / (cols - 1)) if cols > 1 else 0.0 for j in range(cols)]
    rows = [0.0, max(side - drag, 0.0) * 0.5, max(side - drag, 0.0)]
    slots = [(a, c) for a in rows for c in offs_c]
    seeds = []
    for j in range(m):
        a, c = slots[j % len(slots)]
        px = area.px + a * ux + c * nx_
        py = area.py + a * uy + c * ny_
        seeds.append(PhaseSeed(px, py, area.psi, eta0 if j < k_active else 0.0, area.base, truck, float(surf(px, py))))
    return seeds


def shared_truck_stand(bases: list[tuple[float, float]], trucks: list[tuple[float, float]], reach: float,
                       clear: float) -> tuple[float, float]:
    """Where the global guess parks the truck: it stays put after phase 0 (``Shape.hold_truck``),
    so it must be in dump reach of every base the guess visits and clear of each. The candidates
    are the areas' own stands and their mean; the one with the least total shortfall (first on a
    tie). planners/stl_tamp/NOTES.md: from the first area's stand alone, later bases stood up to 11 m
    away (a violation of 73 m² at the start), and IPOPT spent its first ~60 iterations there."""
    mean = (sum(t[0] for t in trucks) / len(trucks), sum(t[1] for t in trucks) / len(trucks))

    def shortfall(t: tuple[float, float]) -> float:
        d = [math.hypot(b[0] - t[0], b[1] - t[1]) for b in bases]
        return sum(max(0.0, x - reach) + max(0.0, clear - x) for x in d)

    return min([mean] + list(trucks), key=shortfall)
