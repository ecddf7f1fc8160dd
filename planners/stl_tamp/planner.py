"""The ``stl-tamp`` planner: hierarchical STL-TAMP (Satoh, Takano, Oyama) on CasADi + IPOPT."""

from __future__ import annotations

import copy
import math
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from earthbench.errors import EarthbenchError
from earthbench.plan import Plan, Prediction
from earthbench.planner import Observation, Planner, SharedFolder, closed_loop_setting
from earthbench.world import ExcavatorSpec, Scenario, TruckSpec
from .surface import fit_rbf

from .convert import Converter, SimState
from .judge import StandJudge
from .guess import PhaseSeed, build_guess, fill_volumes, settle_contacts
from .hierarchy import (
    Area,
    StlTampSolveError,
    Trace,
    diggable_volume,
    fitting_side,
    get_nlp,
    global_blocks,
    global_lattice,
    in_box,
    level_stand,
    Layout,
    LocalProblem,
    local_problem,
    local_seeds,
    nearest_block,
    nlp_start,
    shared_truck_stand,
    site_box,
    solve_counts,
)
from .problem import Shape, Solution
from .sizes import Sized, factors
from .stand import candidate_areas_for, place, served, stand_judge, to_stand, tour


class TargetTooLargeError(EarthbenchError, ValueError):
    """The target volume exceeds the material the dig area holds above its floor."""


@dataclass(frozen=True)
class LocalNLPConfig:
    """The local NLP's settings that ``stl-tamp`` and ``separate`` share (one model, two planners).
    The defaults are the paper's (m_l = 5, n = 10), which ``separate`` keeps; ``stl-tamp``'s
    :class:`Config` sets a smaller horizon (planners/stl_tamp/NOTES.md)."""

    m_local: int = 5
    n_steps: int = 10
    contact_step: int = 4
    dig_depth: float = 0.4
    sigmoid_k: float = 20.0
    quad_widen: float = 0.15
    eps_eta: float = 0.05
    eps_v: float = 0.01
    eps_d: float = 0.01
    beta: float = 30.0
    alpha_u: float = 0.01
    alpha_t: float = 1.0
    alpha_term: float = 0.2

    #: The settings in metres and in m³: the compact excavator's, scaled for another (.sizes).
    LENGTHS: ClassVar[tuple[str, ...]] = ("dig_depth", "eps_d")
    VOLUMES: ClassVar[tuple[str, ...]] = ("eps_v",)


_OMIT = {"omit_default": True}  # a setting left out of the configuration's hash at its default


@dataclass(frozen=True)
class Config(LocalNLPConfig):
    """Settings; defaults are the paper's values where it gives them (section V), but for two.

    Paper: S_l = 5 bucket areas with V_max = 1.0 m³ per area, L_drag = 1.0 m, d_dig = 0.4 m.
    Departures: m_l = 4 digs per local area (paper: 5), the fewest 0.28 m³ buckets that hold an
    area's V_max of 1.0 m³, and n = 8 motion steps per phase (paper: 10), 3 of them before the
    contact: as fast plans at two thirds of the CPU. Not given in the paper (our choices): the
    weights α, the ε constants, the sigmoid steepness k = 20 with the quadrature box widened by
    3/k, the STL sharpness β. Why each setting has its value, with the measurements and the
    versions that set it: planners/stl_tamp/NOTES.md, "Why the settings are what they are".
    """

    m_local: int = 4
    n_steps: int = 8
    contact_step: int = 3

    dtm_max: float = 4.0
    m_global_max: int = 12
    n_global: int = 4
    area_buckets: float = 5.0
    area_vmax: float = 1.0
    alpha_v: float = 2.0e4
    alpha_eta: float = 2.0
    eta_init: float = 0.7
    eta_on: float = 0.25
    min_dig_volume: float = 0.02
    repair: float = 0.5
    # the local problem's base ends phase 0 within stand_tol (m) of the area's level stand
    # (hierarchy.level_stand): a stand the NLP picks freely can be too steep for the tilt rule
    stand_tol: float = 0.1
    base_offset: float = 4.0
    truck_offset: float = 5.0
    # where the machines stand for an area: the base base_offset beyond its centre toward the
    # truck's side, the truck truck_offset from the base, turned truck_angle from straight behind
    # it toward the excavator's start (2.5 rad: a swing of about 37° between dig and dump)
    truck_angle: float = 2.5
    retime_moves: bool = True  # drive the NLP's paths as fast as the limits allow (convert.fastest_steps)
    fill_estimate: float = 0.85
    local_fit_spacing: float = 0.55
    local_fit_half: float = 2.75
    global_fit_spacing: float = 1.0
    local_fit_solver: str = "cholesky"  # per-area refits: the same least squares, solved directly
    global_layer: bool = True
    # the global problem's window (m): sites larger than this are split into windows of at most
    # this size, each with its own global problem over its areas (same shape: one solver), visited
    # nearest-first; a window's target is at most block_fill of what its areas are estimated to hold
    # (its phases: block_phases, so one window's target is at most block_phases - 1 areas; the
    # graph grows with the square of the phases, so fewer phases per window cost less per m³)
    global_window: tuple[float, float] = (12.0, 6.0)
    block_fill: float = 0.8
    block_phases: int = 8
    # iteration caps only: no CPU- or wall-time cap, so machine load never changes a plan
    max_iter: int = 250
    global_max_iter: int = 1500
    # IPOPT's barrier update: a monotone μ from 1.0, solved on to tol without the acceptable-level
    # stop, ends most local solves Solve_Succeeded
    mu_strategy: str = "monotone"
    mu_init: float = 1.0
    # the local solves leave each barrier subproblem at barrier_tol_factor·μ (IPOPT's default 10;
    # the global solve keeps 10)
    barrier_tol_factor: float = 100.0
    on_failure: str = "fallback"  # "fallback" (bounded by max_fallbacks; past it the area is left undug) or "raise"
    max_fallbacks: int = 6  # at least this many, or max_fallback_share of the local solves so far (large sites)
    max_fallback_share: float = 0.05
    volume_tol: float = 1e-4
    min_local_target: float = 0.8  # in buckets
    reseed: bool = True
    retry: bool = True  # a failed local solve is solved once more (on from its last iterate, or from all digs)
    ipopt_tol: float = 1e-4
    acceptable_tol: float = 1e-2  # IPOPT's acceptable level, after acceptable_iter iterates (0: never)
    acceptable_iter: int = 0
    accept_feasible: float = 1e-3  # accept a capped solve whose iterate violates no constraint by more
    # execute the NLP's own digs (contact, heading, depth, full drag) without contact repair or
    # last-bucket trimming: the paper's plans as they are (its Table I); the referee judges them
    as_planned: bool = False
    closed_loop: bool = closed_loop_setting()  # receding horizon, one local area per step (.receding)
    # "ipopt": the classic NLPs by IPOPT (the plans of every board); "fatrop": the NLPs stage by
    # stage, solved by FATROP (.staged), IPOPT from the same start when it fails (counted in
    # plan.info["solvers"]) — measured slower here, so not the default (NOTES.md, "issue 50").
    # Left out of the configuration's hash at its default (as closed_loop is: earthbench.planner).
    solver: str = field(default="ipopt", metadata=_OMIT)
    # 0.11.0 (issues 48, 49; .stand): the truck's stand, the face followed, the base kept, areas facing away
    place_truck: bool = field(default=True, metadata=_OMIT)
    follow_face: bool = field(default=True, metadata=_OMIT)
    keep_base: bool = field(default=True, metadata=_OMIT)
    face_away: bool = field(default=True, metadata=_OMIT)
    # 0.13.0 (issue 49; .stand.tour): the tiles the truck serves beyond them first, every area's swing priced
    swing_first: bool = field(default=True, metadata=_OMIT)
    side_by_swing: bool = field(default=False, metadata=_OMIT)  # issue 49: measured, off (.stand; NOTES.md, "0.12.0")
    standless_tries: int = field(default=8, metadata=_OMIT)  # 0.12.1: standless areas tried before passed over (0: never)

    LENGTHS = LocalNLPConfig.LENGTHS + ("stand_tol", "base_offset", "truck_offset", "local_fit_spacing",
                                        "local_fit_half", "global_fit_spacing", "global_window", "repair")
    VOLUMES = LocalNLPConfig.VOLUMES + ("area_vmax", "min_dig_volume")

    def __post_init__(self) -> None:
        if self.solver not in ("fatrop", "ipopt"):
            raise ValueError(f"solver must be 'fatrop' or 'ipopt', got {self.solver!r}")


class StlTampPlanner(Sized, Planner):
    """Hierarchical STL-TAMP: a global NLP over local areas, a local NLP per area (Algorithm 1).

    What each version changed, and why: planners/stl_tamp/README.md; the measurements behind it:
    planners/stl_tamp/NOTES.md."""

    name = "stl-tamp"
    version = "0.13.0"
    tracks = ("backhoe",)
    Config = Config
    reads = (SharedFolder("EARTHBENCH_NLP_CACHE", "earthbench/nlp"),)  # the built NLPs (.nlp_cache)

    # -- shapes ---------------------------------------------------------------------------------
    def local_shape(self, scenario: Scenario) -> Shape:
        return self._local_shape(scenario.machines.excavator)

    def _local_shape(self, e: ExcavatorSpec) -> Shape:
        c = self.config
        nt = int(round(2 * c.local_fit_half / c.local_fit_spacing)) + 1
        return Shape(phases=c.m_local, steps=c.n_steps, contact_step=c.contact_step, unit_width=e.bucket_width,
                     unit_length=e.max_drag_length, unit_depth=min(c.dig_depth, e.max_cut_depth), vmax=e.bucket_capacity,
                     work_time=e.min_stroke_time + e.min_dump_time, terrain_shape=(nt, nt),
                     terrain_spacing=c.local_fit_spacing, terrain_sigma=c.local_fit_spacing, sigmoid_k=c.sigmoid_k,
                     widen=c.quad_widen, eps_eta=c.eps_eta, eps_v=c.eps_v, eps_d=c.eps_d, beta=c.beta,
                     dtm_max=c.dtm_max, dtw_max=Shape.dtw_max * factors(e).work_time, hold_base=True)

    def area_side(self, scenario: Scenario) -> float:
        """√S_l, or less where the dig area is narrower (paper-switch's 2.0 × 1.75 m area is one
        local area: the contact box is the dig area itself, see :meth:`_local`)."""
        e = scenario.machines.excavator
        return fitting_side(scenario, math.sqrt(self.config.area_buckets * e.bucket_width * e.max_drag_length))

    def areas(self, scenario: Scenario, z: np.ndarray, side: float, layout: Layout | None = None,
              judge: StandJudge | None = None) -> list[Area]:
        """The candidate areas, some facing away from the truck (:func:`.stand.candidate_areas_for`)."""
        return candidate_areas_for(self.config, scenario, z, side, layout, judge)

    def _global_shape(self, exc: ExcavatorSpec, m_g: int, side: float, lattice: tuple[int, int], spacing: float,
                      sigma: float) -> Shape:
        c = self.config
        cap = exc.bucket_capacity * c.fill_estimate
        return Shape(phases=m_g, steps=c.n_global, contact_step=c.n_global // 2, unit_width=side, unit_length=side,
                     unit_depth=c.dig_depth, vmax=c.area_vmax,
                     work_time=c.area_vmax / cap * (exc.min_stroke_time + exc.min_dump_time + 2.0),
                     terrain_shape=lattice, terrain_spacing=spacing, terrain_sigma=sigma, quad=(3, 3),
                     dtm_max=6.0, dtw_max=15.0 * factors(exc).work_time, sigmoid_k=c.sigmoid_k, widen=c.quad_widen, eps_eta=c.eps_eta,
                     eps_v=c.eps_v, eps_d=c.eps_d, beta=c.beta)

    # -- preparation (docs/DESIGN.md §6 "Preparation") -----------------------------------------
    def prepared_shapes(self) -> list[tuple[str, Shape, ExcavatorSpec, TruckSpec]]:
        """The NLPs :meth:`prepare` compiles, per machine class with an excavator (its sizes:
        :mod:`.sizes`), from the class and this configuration alone: the local NLP and the global
        NLP of one window (``global_window``'s lattice) with ``block_phases`` phases, every windowed
        site's; for the compact class also 2 to ``block_phases`` - 1 phases (a site the window's
        size, the paper's maps). Another shape loads from the disk cache (:mod:`.nlp_cache`)."""
        from earthbench.classes import machine_class, machine_classes

        out = []
        for name in machine_classes():
            exc, truck = machine_class(name).excavator, machine_class(name).truck
            if exc is None:
                continue
            planner = self.sized_for(exc)
            c = planner.config
            side = math.sqrt(c.area_buckets * exc.bucket_width * exc.max_drag_length)
            lattice = global_lattice(c.global_window, c.global_fit_spacing)
            sigma = c.global_fit_spacing  # fit_rbf's width: one lattice step (sigma_factor 1)
            out.append((f"{name} local", planner._local_shape(exc), exc, truck))
            phases = range(c.block_phases, 1 if factors(exc).unit else c.block_phases - 1, -1) if c.global_layer else ()
            out += [(f"{name} global {m}", planner._global_shape(exc, m, side, lattice, c.global_fit_spacing, sigma),
                     exc, truck) for m in phases]
        return out

    def prepare(self, folder: Path, jobs: int = 1) -> dict[str, Any]:
        """Compile the NLPs of :meth:`prepared_shapes` into ``folder`` (:mod:`.compiled`), the
        compilers ``jobs`` at a time; returns what was compiled and how long it took."""
        from .preparation import compile_nlps

        return compile_nlps(self, folder, jobs)

    def _use_prepared(self) -> None:
        from .model import use_prepared

        use_prepared(self.prepared)

    # -- the plan -------------------------------------------------------------------------------
    def step(self, observation: Observation) -> Plan | None:
        """Closed loop: one receding-horizon step (:mod:`.receding`)."""
        from .receding import Horizon, step

        if observation.step == 0:
            self._use_prepared()
            self._horizon = Horizon()
            exc = observation.scenario.machines.excavator
            self._sized = self if exc is None else self.sized_for(exc)
        return step(self._sized, observation, self._horizon)

    def plan(self, scenario: Scenario) -> Plan:
        exc = scenario.machines.excavator
        if exc is not None and (planner := self.sized_for(exc)) is not self:
            return planner.plan(scenario)
        if scenario.soil is not None and self.config.swing_first:
            # open loop on a scan: 0.12's tiles (bases on the dig area judged on one scan and on the
            # plan's own model of its cuts stood on steep true ground: NOTES.md, "0.13.0")
            scan = copy.copy(self)
            scan.given = replace(self.given, swing_first=False)
            scan.config = replace(self.config, swing_first=False)
            return scan.plan(scenario)
        t_start = time.perf_counter()
        self._use_prepared()
        c = self.config
        target = self._target(scenario)
        trace = Trace()
        st = SimState.start(scenario)
        exc = scenario.machines.excavator
        box = site_box(scenario)
        side = self.area_side(scenario)
        conv = Converter(scenario, eta_on=c.eta_on, min_dig_volume=c.min_dig_volume, depth=c.dig_depth, repair=c.repair,
                         retime=c.retime_moves, follow_face=c.follow_face, keep_soil=True)

        st.judge = stand_judge(c, scenario)
        areas = self.areas(scenario, st.z, side, judge=st.judge)
        # V_max per area is the global layer's unit; a dig area that is one local area (Fig. 6's
        # set-up) has nothing to split the target over: its local problem takes up to m_l buckets
        vmax = c.area_vmax if len(areas) > 1 else max(c.area_vmax, c.m_local * exc.bucket_capacity)
        blocks = global_blocks(box, c.global_window)
        joints = (0.3, -1.5)
        remaining = target
        n_areas = 0
        predicted_model_volume = 0.0
        trace.global_ = {"used": False, "blocks": []}
        left = list(areas)
        # Algorithm 1 over groups of areas: the global problem of one window of the site (the
        # whole site when it fits, as on the paper's map), then its local problems; then the
        # window nearest to where the excavator stands, until the target is met
        while remaining > c.volume_tol and left:
            block = nearest_block(blocks, left, (st.exc.x, st.exc.y))
            in_block = [a for a in left if in_box(a.centre, block)]
            if len(blocks) > 1 and trace.standless.hopeless(c.standless_tries):  # no global solve over areas no stand serves
                kept = served(c, conv, st, in_block, min(remaining, vmax) / (exc.bucket_capacity * c.fill_estimate))
                trace.standless.passed += len(in_block) - len(kept)
                in_block = kept
            v_block = remaining if len(blocks) == 1 else min(remaining, c.block_fill * sum(a.estimate for a in in_block),
                                                             (c.block_phases - 1) * c.area_vmax)
            seed = tour(c, in_block, (st.exc.x, st.exc.y), v_block, exc)
            chosen = self._choose(scenario, st, seed, v_block, side, box, block, len(blocks) > 1, trace)
            queue = list(chosen) + [a for a in seed if all(math.dist(a.centre, b.centre) > side / 2 for b in chosen)]
            got_block = 0.0
            while queue and remaining > c.volume_tol and got_block < v_block - c.volume_tol:
                area = queue.pop(0)
                left = [a for a in left if math.dist(a.centre, area.centre) > side / 2]
                nxt = queue[0].base if queue else area.base
                got, model_v, joints = self._local(scenario, st, conv, area, nxt, remaining, vmax, joints, box, trace)
                remaining -= got
                got_block += got
                predicted_model_volume += model_v
                n_areas += 1
            left = [a for a in left if not in_box(a.centre, block)] if got_block <= c.volume_tol or not queue else left
            if not left and remaining > c.volume_tol and trace.regenerated < 3:
                # every area visited once: tile the lowered grid anew
                trace.regenerated += 1
                left = self.areas(scenario, st.z, side, judge=st.judge)
        if len(trace.global_["blocks"]) == 1:  # one window: the record as before
            trace.global_ = dict(trace.global_["blocks"][0])
        info = {"planner": self.name, "areas": n_areas, "digs": st.digs, "nlp_model_volume": predicted_model_volume,
                "fit_time_s": trace.fit_time_s, "build_time_s": trace.build_time_s, "nlp_cache": trace.nlp_cache,
                "fallbacks": trace.fallbacks, "local_solves": solve_counts(trace.locals_), "skipped": dict(conv.skips),
                "standless": trace.standless.record(), "solvers": dict(trace.solvers),
                "global": trace.global_, "local": trace.locals_, "plan_time_s": time.perf_counter() - t_start}
        return Plan(actions=tuple(st.actions),
                    predicted=Prediction(volume=st.loaded, makespan=max((a.t_end for a in st.actions), default=0.0)), info=info)

    @staticmethod
    def _target(scenario: Scenario) -> float:
        """The target volume, once the scenario is known to be one stl-tamp can plan for."""
        if scenario.machines.excavator is None:
            raise EarthbenchError("stl-tamp plans for a backhoe excavator; this scenario has none")
        target = scenario.task.target_volume
        holds = diggable_volume(scenario)
        if target > holds:
            raise TargetTooLargeError(
                f"target {target:.3f} m³ exceeds the {holds:.3f} m³ the dig area holds above its floor; "
                "lower task.target_volume or enlarge the site")
        return target

    def _choose(self, scenario: Scenario, st: SimState, tour: list[Area], v_block: float, side: float,
                box: tuple[float, float, float, float], block: tuple[float, float, float, float], windowed: bool,
                trace: Trace) -> list[Area]:
        """Algorithm 1, steps 1–3 for one window (``block``; ``windowed``: the site has several):
        the areas its global problem chooses, or the tour itself when there is nothing to choose
        between (paper-switch: the dig area is one local area); the record goes to ``trace``."""
        c = self.config
        if c.global_layer and len(tour) > 1:
            t0 = time.perf_counter()  # Algorithm 1, step 1: the surface function (of the window)
            if not windowed:
                surf_g = fit_rbf(scenario.terrain.with_z(st.z), spacing=c.global_fit_spacing, solver="cholesky")
            else:
                surf_g = fit_rbf(scenario.terrain.with_z(st.z), spacing=c.global_fit_spacing, window=block,
                                 shape=global_lattice(c.global_window, c.global_fit_spacing), solver="cholesky")
            trace.fit_time_s += time.perf_counter() - t0
            chosen, rec = self._global(scenario, st, surf_g, tour, v_block, side, box, block, windowed, trace)
            trace.global_["used"] = True
        else:
            chosen, rec = tour, {"used": False, "areas": len(tour)}
        trace.global_["blocks"].append(rec)
        return chosen

    def _ipopt_options(self, local: bool = True) -> dict[str, Any]:
        """IPOPT's settings; the local solves' barrier subproblems end at ``barrier_tol_factor``·μ
        (the global solve keeps IPOPT's 10: planners/stl_tamp/NOTES.md)."""
        c = self.config
        out = {"mu_strategy": c.mu_strategy, "mu_init": c.mu_init, "tol": c.ipopt_tol, "acceptable_tol": c.acceptable_tol,
               "acceptable_iter": c.acceptable_iter}
        if local:
            out["barrier_tol_factor"] = c.barrier_tol_factor
        return out

    # -- global layer ------------------------------------------------------------------------------
    def _global(self, scenario: Scenario, st: SimState, surf, tour: list[Area], target: float, side: float,
                box: tuple[float, float, float, float], window: tuple[float, float, float, float], fixed_phases: bool,
                trace: Trace) -> tuple[list[Area], dict[str, Any]]:
        """The global problem of one window: which of ``tour``'s areas to dig, in which order.
        ``fixed_phases``: one phase count (``block_phases``) for every window, so one solver serves
        the whole site; the dig phases a smaller target needs are bounded through η."""
        c, exc = self.config, scenario.machines.excavator
        need = int(math.ceil(target / c.area_vmax))
        m_g = c.block_phases if fixed_phases else max(1, min(c.m_global_max, need + 1, len(tour)))
        shape = self._global_shape(exc, m_g, side, surf.shape, surf.spacing, surf.sigma)
        t0 = time.perf_counter()
        nlp, _ = get_nlp(shape, scenario, box)
        floor = scenario.site.floor if scenario.site.floor is not None else 0.0
        truck = shared_truck_stand([a.base for a in tour[:m_g]], [a.truck for a in tour[:m_g]],
                                   exc.reach_max + scenario.machines.truck.loading_radius - shape.margin,
                                   exc.clearance + shape.col_margin)
        seeds = [PhaseSeed(a.px, a.py, a.psi, c.eta_init if j < need else 0.0, a.base, truck,
                           float(surf(a.px, a.py))) for j, a in enumerate(tour[:m_g])]
        s0 = nlp_start(st, shape, exc)
        params = nlp.pack_p(w=surf.weights.reshape(-1), o=(surf.x0, surf.y0), s0=s0, vt=target,
                            alpha=(c.alpha_u, c.alpha_t, c.alpha_v / 10, c.alpha_eta, 0.0), goal=(s0[0], s0[1]), floor=floor)
        w0 = fill_volumes(nlp, build_guess(nlp, s0, seeds, floor), params, [a.estimate for a in tour[:m_g]])
        cbox = (max(window[0], box[0]), min(window[1], box[1]), max(window[2], box[2]), min(window[3], box[3]))
        sol = nlp.solve(params, w0, cbox, max_iter=c.global_max_iter, accept_feasible=c.accept_feasible,
                        max_dig_phases=min(need, m_g) if fixed_phases else None, options=self._ipopt_options(local=False),
                        solver=c.solver)
        trace.add_build(nlp)
        rec = {"used": True, "phases": m_g, "status": sol.status, "iterations": sol.iterations,
               "solve_time_s": sol.solve_time_s, "success": sol.success, "eta": np.round(sol.eta, 3).tolist(),
               "volume": float(np.sum(sol.V)), "wall_s": time.perf_counter() - t0}
        if not sol.success:
            rec["fallback"] = "greedy tour"
            return tour, rec
        n = nlp.n
        # each area keeps its own truck stand (the local problem's phase 0 drives the truck there)
        off = (tour[0].truck[0] - tour[0].base[0], tour[0].truck[1] - tour[0].base[1])
        out = []
        for i in range(1, nlp.m1):
            if sol.eta[i] < c.eta_on and not (sol.eta[i] >= 2 * c.eps_eta and sol.V[i] >= 0.25 * c.area_vmax):
                continue
            u = (math.cos(sol.psi[i]), math.sin(sol.psi[i]))
            kn = i * n + nlp.kc[i]
            centre = (sol.px[i] + u[0] * side / 2, sol.py[i] + u[1] * side / 2)
            base = (float(sol.X[kn, 0]), float(sol.X[kn, 1]))
            reach = math.hypot(base[0] - centre[0], base[1] - centre[1])
            if reach > 1e-6:  # the global NLP knows no tilt rule: the nearest level stand on its line
                base = level_stand(scenario, st.z, centre, ((base[0] - centre[0]) / reach, (base[1] - centre[1]) / reach),
                                   reach, side, st.judge)
            if base is None:
                continue
            out.append(Area(float(sol.px[i]), float(sol.py[i]), float(sol.psi[i]), base,
                            (base[0] + off[0], base[1] + off[1]), float(sol.V[i]), centre, source="global"))
        return (out or tour), rec

    # -- local layer -------------------------------------------------------------------------------
    def _local(self, scenario: Scenario, st: SimState, conv: Converter, area: Area, goal: tuple[float, float],
               remaining: float, vmax: float, joints: tuple[float, float], box: tuple[float, float, float, float],
               trace: Trace) -> tuple[float, float, tuple[float, float]]:
        c, exc = self.config, scenario.machines.excavator
        t_wall = time.perf_counter()
        shape = self.local_shape(scenario)
        # a small remainder is still planned as (at least) a bucket of work: the conversion then
        # bisects the real dig's depth to take exactly what is missing
        v_local = min(max(remaining, c.min_local_target * exc.bucket_capacity), vmax)
        # phase 0: the base to the area's (or where it stands), the truck to its stand (.stand; side_by_swing: priced over all that is left)
        placed, stand = place(c, conv, st, area, (remaining if c.side_by_swing else v_local) / (exc.bucket_capacity * c.fill_estimate))
        standless = stand is None and c.place_truck
        if standless and trace.standless.hopeless(c.standless_tries):
            trace.standless.passed += 1  # such areas have only failed on this site: neither solved nor driven to
            return 0.0, 0.0, joints
        # terrain parameter: a fit of the current grid around the area (the digs so far included)
        lp = local_problem(scenario, st, area, shape, box, joints, fit_spacing=c.local_fit_spacing, fit_half=c.local_fit_half,
                           fit_solver=c.local_fit_solver, vt=v_local,
                           alpha=(c.alpha_u, c.alpha_t, c.alpha_v, c.alpha_eta, c.alpha_term), goal=goal)
        nlp, surf, floor, s0, params = lp.nlp, lp.surf, lp.floor, lp.s0, lp.params
        trace.fit_time_s += lp.fit_time_s
        cx, cy = area.centre
        area = placed
        truck = (stand.x, stand.y) if stand is not None else area.truck
        k_active = min(c.m_local, max(1, int(math.ceil(v_local / (exc.bucket_capacity * c.fill_estimate)))))
        seeds = local_seeds(area, k_active, c.m_local, exc.bucket_width, exc.max_drag_length, surf, c.eta_init, truck)
        seeds = settle_contacts(nlp, s0, seeds, floor, params)
        w0 = fill_volumes(nlp, build_guess(nlp, s0, seeds, floor), params)
        sol, n_iter, t_solve, retry = self._solve_local(lp, exc, area, truck, box, w0, stand is not None)
        trace.add_build(nlp)
        rec: dict[str, Any] = {"area": [round(cx, 3), round(cy, 3)], "source": area.source, "target": v_local,
                               "status": sol.status, "iterations": n_iter, "solve_time_s": t_solve,
                               "success": sol.success, "eta": np.round(sol.eta[1:], 3).tolist(),
                               "model_volume": float(np.sum(sol.V))}
        if retry is not None:
            rec["retry"] = retry
        if not sol.success:
            solved = sum("skipped" not in r for r in trace.locals_)
            allowed = max(c.max_fallbacks, math.ceil(c.max_fallback_share * (solved + 1)))
            if c.on_failure != "fallback":
                raise StlTampSolveError(
                    f"local solve for the area at ({cx:.2f}, {cy:.2f}) failed: IPOPT {sol.status} after "
                    f"{sol.iterations} iterations ({sol.solve_time_s:.2f} s)")
            if trace.fallbacks >= allowed:
                # past the bound on executed guesses the area is left undug (the tour goes on to
                # the next one): a large site no longer ends in an error for one hard area
                rec["skipped"] = f"fallback limit ({trace.fallbacks} of {allowed} used)"
                rec["loaded"], rec["wall_s"] = 0.0, time.perf_counter() - t_wall
                trace.locals_.append(rec)
                return 0.0, 0.0, joints
            trace.fallbacks += 1
            sol = nlp._solution(w0, params, False, "fallback: IK initial guess", 0, 0.0, float("nan"), {})
            rec["fallback"] = "IK initial guess"
        depths = None
        if c.as_planned:  # the NLP's own depth: its contact height less max(floor, that − d_dig)
            pz = nlp.evaluate(sol.info["w"], params)["contact_heights"]
            depths = np.clip(pz - np.maximum(floor, pz - shape.unit_depth), 0.0, shape.unit_depth)
        digs = st.digs
        got = self._emit(st, conv, nlp, sol, remaining, depths, stand)
        if standless:
            trace.standless.visited(st.digs > digs)
        rec["loaded"], rec["wall_s"] = got, time.perf_counter() - t_wall
        trace.locals_.append(rec)
        return got, float(np.sum(sol.V)), (float(sol.X[-1, 4]), float(sol.X[-1, 5]))

    def _solve_local(self, lp: LocalProblem, exc: ExcavatorSpec, area: Area, truck: tuple[float, float],
                     box: tuple[float, float, float, float], w0: np.ndarray,
                     truck_fixed: bool = False) -> tuple[Solution, int, float, str | None]:
        """The local NLP solved from ``w0`` with its contacts kept near the area and its stand near
        the area's level stand: retried once if it fails (``retry``), restarted once out of the
        disjunction trap if it succeeds (``reseed``). Returns the solution kept, the iterations
        and solve seconds of every solve, and how the retry went (None: no retry)."""
        c, nlp, params, s0, floor, surf = self.config, lp.nlp, lp.params, lp.s0, lp.floor, lp.surf
        cx, cy = area.centre
        half = math.hypot(cx - area.px, cy - area.py) + 0.5
        cbox = (max(cx - half, box[0]), min(cx + half, box[1]), max(cy - half, box[2]), min(cy + half, box[3]))
        stand = (area.base[0], area.base[1], c.stand_tol)
        at = (truck[0], truck[1], c.stand_tol) if truck_fixed else None  # the truck's stand (.stand)

        def solve(w: np.ndarray) -> Solution:
            return nlp.solve(params, w, cbox, max_iter=c.max_iter, accept_feasible=c.accept_feasible,
                             options=self._ipopt_options(), stand=stand, solver=c.solver, truck_stand=at)

        sol = solve(w0)
        n_iter, t_solve = sol.iterations, sol.solve_time_s
        retry = None
        start = w0
        if not sol.success and c.retry:
            # one more solve: on from the last iterate when IPOPT only ran out of iterations or
            # time, else from another start (Fig. 6's: every phase seeded as a dig)
            if sol.status.startswith("Maximum_"):
                w1, retry = sol.info["w"], "continued"
            else:
                seeds = local_seeds(area, c.m_local, c.m_local, exc.bucket_width, exc.max_drag_length, surf, 1.0, truck)
                seeds = settle_contacts(nlp, s0, seeds, floor, params)
                w1, retry = fill_volumes(nlp, build_guess(nlp, s0, seeds, floor), params), "every phase a dig"
            sol2 = solve(w1)
            n_iter, t_solve, retry = n_iter + sol2.iterations, t_solve + sol2.solve_time_s, f"{retry}: {sol2.status}"
            if sol2.success:
                sol, start = sol2, w1
        if sol.success and c.reseed:
            w1 = nlp.reseed(sol, start, params, c.eta_on)
            if w1 is not None:  # one bounded restart out of the disjunction trap (see PhaseNLP.reseed)
                sol2 = solve(w1)
                n_iter, t_solve = n_iter + sol2.iterations, t_solve + sol2.solve_time_s
                if sol2.success and float(np.sum(sol2.V)) > float(np.sum(sol.V)):
                    sol = sol2
        return sol, n_iter, t_solve, retry

    def _emit(self, st: SimState, conv: Converter, nlp, sol: Solution, remaining: float,
              depths: np.ndarray | None = None, stand=None) -> float:
        """Turn the phases of a local solution into actions (see :mod:`.convert`); with
        ``depths`` (the as-planned mode) each dig is the NLP's own at that depth."""
        n, kc = nlp.n, nlp.kc
        dts = np.diff(sol.times)
        U = sol.U
        loaded = 0.0
        if stand is None or to_stand(conv, st, U[:n, 0], U[:n, 1], dts[:n], stand) is None:
            conv.move_both(st, U[:n, 0], U[:n, 1], U[:n, 5], U[:n, 6], dts[:n])
        for i in range(1, nlp.m1):
            k0 = i * n
            if kc[i] > 0:
                conv.move_excavator(st, U[k0:k0 + kc[i], 0], U[k0:k0 + kc[i], 1], dts[k0:k0 + kc[i]])
            dig = sol.eta[i] >= self.config.eta_on or (sol.eta[i] >= 2 * self.config.eps_eta and sol.V[i] >= self.config.min_dig_volume)
            if dig and remaining - loaded > self.config.volume_tol:
                contact = (float(sol.px[i]), float(sol.py[i]))
                if depths is not None:
                    loaded += conv.dig_as_planned(st, contact, float(sol.psi[i]), float(depths[i - 1]))
                else:
                    loaded += conv.dig_and_dump(st, contact, float(sol.psi[i]), remaining - loaded)
        return loaded


def config_dict(config: Config) -> dict[str, Any]:
    return asdict(config)
