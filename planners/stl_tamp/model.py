"""The STL-TAMP system model and its parametric NLP (paper Eq. (1)–(3), (13)–(28)).

One :class:`PhaseNLP` is an optimal-control problem over ``m + 1`` task phases of ``n``
motion steps each (phase 0 is the independent task — travel, η₀ = 0 — as in the paper's
Fig. 6; phases 1…m may dig). It is built **once per process and problem shape** and reused:
everything that changes between local areas is a *parameter* — the terrain (the weights and
lattice origin of a fitted :class:`~earthbench_planners.stl_tamp.surface.RbfSurface`), the initial machine state,
the target volume, the cost weights and a goal for the base at the end (terminal cost) — and
the contact box, η, fixed tasks and the initial guess are variable bounds and start values.
The ``separate`` baseline (tasks fixed, motions and times optimised) is the same NLP solved
with η and the contact parameters fixed through their bounds: see :meth:`PhaseNLP.solve`'s
``fixed_tasks``.

State ``s = (x_B, y_B, ψ_B, θ_turn, θ_boom, θ_arm, x_D, y_D, ψ_D)`` (Eq. (13)–(14)), input
``u = (v, ω_z, ω_turn, ω_boom, ω_arm, v_D, ω_D)``. Eq. (2) is an Euler step with the heading
taken at mid-step, ``x⁺ = x + v cos(ψ + ω dt/2) dt``: this makes every pair of nodes an exact
chord of a unicycle arc, so the node sequence is itself a path the referee accepts. Each phase
has ``k_c`` move steps of duration ``dtm`` and ``n − k_c`` work steps of duration ``dtw``; the
base is still during work steps (the referee requires it while digging and dumping), and the
contact, Eq. (3)/(16), is imposed at node ``k_c``.

Terrain, Eq. (1)/(27)–(28): ``f_{i+1} = f_i − η_i w_i · sp(f_i − h_i)`` with the sigmoid window
``w_i`` of the bucket rectangle (width × drag length) rotated to the drag heading ψ_i and
``h_i = max(floor, f_i(P_i) − d)``, both max and the positive part ``sp`` smoothed. The
positive part is our calibration to the referee's cut, which only lowers cells (the paper's
``h − f`` would fill a hollow). Volume, Eq. (20): Gauss–Legendre quadrature over the
rectangle widened by ``widen`` on every side (planners/stl_tamp/NOTES.md: a sigmoid of steepness k leaks about
``3/k`` of the box; the widened box catches what the sigmoid removes).

Specifications, Eq. (4)–(8), (17)–(24), with the smooth robustness of :mod:`earthbench_planners.stl_tamp.stl`;
the dump-still formula (22) stays in ρ_safe, but with ``Shape.hold_truck`` (default) it is also
enforced structurally by fixing the truck's inputs to 0 after phase 0: with the smooth ``G``
alone (ε_r = 5 cm normalised) IPOPT hit its iteration limit with ρ_safe ≈ −500 on our first
local test, and the referee needs the truck exactly still anyway.
predicates are normalised by their scale (η by 1, volume by V_max, distances² by the squared
radius) so that one sharpness fits all. Cost, Eq. (26), plus ``α_term ‖p_B(end) − goal‖²``.

Derivatives (SX): each terrain evaluation enters the graph as its second-order Taylor polynomial
at the point itself, with symbolic coefficients; after CasADi has differentiated the graph, the
coefficients become the RBF's value, gradient and Hessian there — the same derivatives, but
each a single contraction over the lattice weights instead of one per Hessian colour
(planners/stl_tamp/NOTES.md). The built functions are stored by :mod:`.nlp_cache` and loaded by later
processes.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from earthbench.world import ExcavatorSpec, TruckSpec
from .stl import And, Const, Finally, Globally, Or, Predicate, robustness_constraints

from . import compiled, graph, nlp_cache, staged
from .graph import tip_position  # noqa: F401  (its documented home until 0.11.0)
from .problem import ARM_BOUNDS, BOOM_BOUNDS, NU, NX, Shape, Solution, quantize


_PREPARED: list[Path | None] = [None]


def use_prepared(folder: str | os.PathLike[str] | None) -> None:
    """Load NLPs compiled in the planner's preparation from ``folder`` (None: none), for the NLPs
    this process builds from now on (:mod:`.compiled`)."""
    _PREPARED[0] = Path(folder) if folder is not None else None


def prepared_dir() -> Path | None:
    return _PREPARED[0]


def nlp_truck(truck: TruckSpec) -> TruckSpec:
    """The truck as an NLP sees it: without its capacity, which no constraint reads (the planner
    caps what it asks for at the truck's room). NaN, so a constraint that read it would fail
    loudly; left out of the key, so the NLPs prepared for the benchmark's truck serve a truck of
    any size (the ``scale`` ladder's 20–320 m³ ones)."""
    return dataclasses.replace(truck, capacity=math.nan)


def nlp_key(shape: Shape, exc: ExcavatorSpec, truck: TruckSpec, staged_layout: bool = False) -> str:
    """The name of an NLP in the disk cache and in the preparation's folder (``staged_layout``:
    its stage-by-stage form, :mod:`.staged`)."""
    return nlp_cache.key(shape, exc, nlp_truck(truck)) + ("_staged" if staged_layout else "")


def build_functions(shape: Shape, exc: ExcavatorSpec, truck: TruckSpec,
                    staged_layout: bool = False) -> tuple[str, dict[str, Any]]:
    """The key and the built (uncompiled) functions of an NLP (``staged_layout``: of its
    stage-by-stage form), from the disk cache or built here; what the preparation compiles."""
    name = nlp_key(shape, exc, truck, staged_layout)
    path = nlp_cache.load(name)
    fns = _unpack(path, staged.HELPER_NAMES if staged_layout else _FUNCTIONS + ("bounds",)) if path is not None else None
    if fns is None:
        if staged_layout:
            fns = staged.build(shape, exc, nlp_truck(truck))
        else:
            nlp = object.__new__(PhaseNLP)
            nlp._setup(shape, exc, truck)
            fns = nlp._build()
        built = fns
        nlp_cache.save(name, lambda tmp: _pack(built, tmp))  # where a case without the compiled ones finds it
    return name, fns


def one_blas_thread() -> bool:
    """Run the OpenBLAS that CasADi's IPOPT/MUMPS loads (its own copy, loaded with the plugin)
    on one thread. A second thread gave no speed-up of the local solve at twice the CPU, and a
    different plan (summation order): one thread makes the plan the same on every slot size.
    Returns whether the library was found."""
    import ctypes
    import glob
    import os

    try:  # the copies the process has loaded (a wheel ships several files, not symlinks)
        with open("/proc/self/maps") as f:
            paths = sorted({ln.split()[-1] for ln in f if "libcasadi-tp-openblas" in ln})
    except OSError:
        paths = []
    paths = paths or sorted(glob.glob(os.path.join(os.path.dirname(ca.__file__), "libcasadi-tp-openblas.so*")))
    done = False
    for path in paths:
        try:
            ctypes.CDLL(path).openblas_set_num_threads(1)
            done = True
        except (OSError, AttributeError):
            continue
    return done


_PHASE_VARS = ("dtm", "dtw", "eta", "px", "py", "psi", "V")
_FUNCTIONS = ("nlp", "tip", "rho", "vol", "pz")
_DERIVATIVES = ("hess_lag", "jac_g", "grad_f")  # nlpsol's options: given, it builds none of its own


def _pack(fns: dict[str, Any], path: str) -> None:
    """Write the built functions to ``path`` (CasADi's serialization), for :mod:`.nlp_cache`."""
    s = ca.FileSerializer(path)
    s.pack(sorted(fns))
    s.pack([fns[k] for k in sorted(fns)])
    del s  # closes the file


def _unpack(path: Any, required: tuple[str, ...] = _FUNCTIONS + ("bounds",)) -> dict[str, Any] | None:
    """The functions :func:`_pack` wrote to ``path``; None when it does not hold them."""
    try:
        d = ca.FileDeserializer(str(path))
        names, fns = d.unpack(), d.unpack()
    except RuntimeError:
        return None
    if not isinstance(names, list) or not isinstance(fns, list) or len(names) != len(fns) \
            or not set(required) <= set(names):
        return None
    return dict(zip(names, fns))


class _Rows:
    """The constraints g in order, with their bounds."""

    def __init__(self) -> None:
        self.g: list[Any] = []
        self.lbg: list[float] = []
        self.ubg: list[float] = []

    def add(self, expr: Any, lo: float, hi: float) -> None:
        self.g.append(expr)
        self.lbg.extend([lo] * expr.shape[0])
        self.ubg.extend([hi] * expr.shape[0])


class PhaseNLP:
    """The parametric NLP of one shape; build once, :meth:`solve` many times."""

    def __init__(self, shape: Shape, exc: ExcavatorSpec, truck: TruckSpec, site_box: tuple[float, float, float, float]):
        t0 = time.perf_counter()
        self._setup(shape, exc, truck)
        self.site_box = site_box
        # the built functions: compiled in the planner's preparation (compiled), else from the
        # disk cache when this NLP was built before (nlp_cache), else built here
        name = nlp_key(shape, exc, truck)  # the site's box only bounds g (below)
        self.key = name
        fns = compiled.load(prepared_dir(), name)
        if fns is not None:
            self.cache = "compiled"
        else:
            path = nlp_cache.load(name)
            fns = _unpack(path) if path is not None else None
            self.cache = "hit" if fns is not None else "miss" if nlp_cache.directory() is not None else "off"
        if fns is None:
            fns = self._build()
            if self.cache == "miss":
                nlp_cache.save(name, lambda tmp: _pack(fns, tmp))
        self._nlp_fn, self._tip_fn, self._rho_fn, self._vol_fn, self._pz_fn = (fns[k] for k in _FUNCTIONS)
        # compiled: the oracle's library holds the derivatives, and nlpsol finds them there
        self._derivs = {} if self.cache == "compiled" else {k: fns[k] for k in _DERIVATIVES if k in fns}
        lbg, ubg, site_rows = (np.array(v).reshape(-1) for v in fns["bounds"].call([]))
        rows = site_rows.astype(int)
        xmin, xmax, ymin, ymax = site_box  # every corner of every dig rectangle inside the site
        lbg[rows], ubg[rows] = xmin + 1e-3, xmax - 1e-3
        lbg[rows + 1], ubg[rows + 1] = ymin + 1e-3, ymax - 1e-3
        self.lbg, self.ubg = lbg, ubg
        self.ng = self.lbg.shape[0]
        self.build_time_s = time.perf_counter() - t0
        self._solvers: dict[tuple, Any] = {}
        self._unreported_build_s = self.build_time_s
        self._cache_unreported = True
        self._staged: staged.StagedSolver | None = None
        self._counts = {"fatrop": 0, "ipopt": 0, "fallback": 0}  # solves not yet reported (take_solver_counts)

    def _setup(self, shape: Shape, exc: ExcavatorSpec, truck: TruckSpec) -> None:
        """The sizes and layouts of the shape (what :meth:`_build` and the solves read)."""
        self.shape, self.exc, self.truck = shape, exc, nlp_truck(truck)
        sh = shape
        m1, n = sh.phases + 1, sh.steps
        self.m1, self.n = m1, n
        self.N = N = m1 * n
        self.kc = [n] + [sh.contact_step] * sh.phases  # phase 0: all move steps
        K = sh.terrain_shape[0] * sh.terrain_shape[1]
        self.K = K
        if sh.symbolic not in ("SX", "MX"):
            raise ValueError(f"Shape.symbolic must be 'SX' or 'MX', got {sh.symbolic!r}")
        self.p_parts = [("w", K), ("o", 2), ("s0", NX), ("vt", 1), ("alpha", 5), ("goal", 2), ("floor", 1)]
        self.v_parts = [("X", NX * N), ("U", NU * N)] + [(k, m1) for k in _PHASE_VARS] + [("slack", 2)]
        self.nw = sum(ln for _, ln in self.v_parts)

    def _build(self) -> dict[str, Any]:
        """The CasADi graph: the NLP (x, p) → (f, g), its derivatives (SX) and the helpers."""
        sh, m1, n, N = self.shape, self.m1, self.n, self.N
        sym = ca.SX.sym if sh.symbolic == "SX" else ca.MX.sym
        P = {k: sym(nm, ln) for k, nm, ln in (("w", "terrain_w", self.K), ("o", "terrain_o", 2), ("s0", "s0", NX),
                                               ("vt", "v_target", 1), ("a", "alpha", 5), ("goal", "goal", 2),
                                               ("floor", "floor", 1))}
        p = ca.vertcat(*P.values())  # α = (α_u, α_t, α_v, α_η, α_term)
        Xv, Uv = sym("X", NX, N), sym("U", NU, N)  # nodes 1..N (node 0 is the parameter s0)
        ph = {k: sym(k, m1) for k in _PHASE_VARS}
        slack = sym("slack", 2)
        w = ca.vertcat(ca.vec(Xv), ca.vec(Uv), *ph.values(), slack)
        X = [P["s0"]] + [Xv[:, k] for k in range(N)]
        U = [Uv[:, k] for k in range(N)]
        rows = _Rows()
        for k in range(N):  # dynamics, Eq. (2), (13), (14)
            i, j = divmod(k, n)
            dt = ph["dtm"][i] if j < self.kc[i] else ph["dtw"][i]
            rows.add(X[k + 1] - X[k] - graph.euler_step(X[k], U[k], dt), 0.0, 0.0)
        terrain = graph.Terrain(sh, P["w"], P["o"])
        cuts: list[graph.Cut] = []
        pz, vol = [], []
        for i in range(1, m1):  # terrain model, Eq. (1), (27), (28), and volume, Eq. (20)
            cut = graph.Cut(ph["eta"][i], ph["px"][i], ph["py"][i], ca.cos(ph["psi"][i]), ca.sin(ph["psi"][i]))
            pz_i, vol_i, cut = graph.dig(sh, terrain, cuts, cut, P["floor"])
            cuts.append(cut)
            pz.append(pz_i)
            vol.append(vol_i)
            rows.add(ph["V"][i] - vol_i, 0.0, 0.0)
        tips = [graph.tip_position(X[k], self.exc, P["floor"]) for k in range(N + 1)]
        site_rows = self._contacts(rows, X, ph, tips, cuts, pz)
        rho = self._specs(rows, X, ph, tips, slack)
        J = self._cost(X, U, ph, P)
        G = ca.vertcat(*rows.g)
        fns = self._derivatives(terrain, w, p, J, G) if terrain.lifted else {}
        G, J, vol_v, pz_v, *rho = terrain.substitute([G, J, ca.vertcat(*vol), ca.vertcat(*pz), *rho])
        fns["nlp"] = ca.Function("nlp", [w, p], [J, G], ["x", "p"], ["f", "g"])
        fns["tip"] = ca.Function("tip", [Xv, P["s0"], P["floor"]], [ca.horzcat(*[ca.vertcat(*t) for t in tips])])
        fns["rho"] = ca.Function("rho", [w, p], rho)
        fns["vol"] = ca.Function("vol", [w, p], [vol_v])
        # model terrain height at each dig phase's contact, after the earlier phases' cuts (guesses)
        fns["pz"] = ca.Function("pz", [w, p], [pz_v])
        fns["bounds"] = ca.Function("bounds", [], [ca.DM(rows.lbg), ca.DM(rows.ubg), ca.DM(site_rows)])
        return fns

    def _contacts(self, rows: _Rows, X: list[Any], ph: dict[str, Any], tips: list[Any], cuts: list[graph.Cut],
                  pz: list[Any]) -> list[int]:
        """Contact, reach and site constraints, Eq. (3), (15), (16), and each dig phase's work
        time; returns the rows of the dig corners (bounded by the site's box in __init__)."""
        sh, n = self.shape, self.n
        site_rows: list[int] = []
        for i in range(1, self.m1):
            kn = i * n + self.kc[i]
            cut = cuts[i - 1]
            for row in graph.contact_rows(sh, self.exc, X[kn], tips[kn], cut, pz[i - 1]):
                rows.add(*row)
            for corner in graph.corners(sh, cut):
                site_rows.append(len(rows.lbg))
                rows.add(corner, -ca.inf, ca.inf)
            rows.add(*graph.dump_reach_row(sh, self.exc, self.truck, X[kn]))
            dturn = X[(i + 1) * n][3] - X[kn][3]
            rows.add(*graph.work_row(sh, self.exc, ph["eta"][i], ph["dtw"][i], dturn))
        return site_rows

    def _specs(self, rows: _Rows, X: list[Any], ph: dict[str, Any], tips: list[Any], slack: Any) -> list[Any]:
        """The STL specifications, Eq. (4)–(8), (17)–(19), (22)–(24), as constraints ρ ≥ slack;
        returns the task's and safety's smooth robustness (the ``rho`` helper)."""
        sh, exc, truck, m1, n, N = self.shape, self.exc, self.truck, self.m1, self.n, self.N
        sig = {"dx": [X[k][6] for k in range(N + 1)], "dy": [X[k][7] for k in range(N + 1)], "__len__": N + 1}
        # A conjunction/G of lower bounds is imposed conjunct by conjunct (stl.robustness_constraints):
        # exact at the top level and sparse; the smoothing acts inside the disjunction (5) and the
        # finally (18).
        rho_task_parts = []
        for i in range(1, m1):
            eta_i, V_i = ph["eta"][i], ph["V"][i]
            phi0 = Predicate(lambda s_, k, e=eta_i: sh.eps_eta - e, "φ0")
            phi1 = Predicate(lambda s_, k, e=eta_i: e - sh.eps_eta, "φ1")
            phi_v = Predicate(lambda s_, k, v=V_i: (v - sh.eps_v) / sh.vmax, "φv")
            load = Predicate(lambda s_, k, e=eta_i: graph.mu_load(truck, e, X[k], tips[k]), "μload")
            phi_task = Or((And((phi0, Const(1e3))), And((phi1, phi_v, Finally(load, self.kc[i] + 1, n)))))  # Eq. (5)
            rho_task_parts.append(phi_task.rho(sig, i * n, smooth=sh.beta))
        mu_dump = Predicate(
            lambda s_, k: (sh.eps_r**2 - (s_["dx"][k] - s_["dx"][n]) ** 2 - (s_["dy"][k] - s_["dy"][n]) ** 2) / sh.eps_r**2,
            "μdump")
        mu_col = Predicate(lambda s_, k: graph.mu_col(sh, exc, X[k]), "μcol")
        phi_dump = Globally(mu_dump, n, N)
        phi_safe = And((phi_dump, Globally(mu_col, 0, N)))  # Eq. (22)–(24)
        for r in rho_task_parts:
            rows.add(r - slack[0], 0.0, ca.inf)
        safe_parts = robustness_constraints(Globally(mu_col, 0, N), sig, 0, smooth=sh.beta)
        if not sh.hold_truck:
            safe_parts += robustness_constraints(phi_dump, sig, 0, smooth=sh.beta)
        for r in safe_parts:
            rows.add(r - slack[1], 0.0, ca.inf)
        return [ca.mmin(ca.vertcat(*rho_task_parts)), phi_safe.rho(sig, 0)]

    def _cost(self, X: list[Any], U: list[Any], ph: dict[str, Any], P: dict[str, Any]) -> Any:
        """Eq. (26) plus the terminal cost toward the next area."""
        sh, m1, n, N = self.shape, self.m1, self.n, self.N
        qu = ca.DM(list(sh.q_u) + list(sh.q_u_truck))
        J_u = 0
        for k in range(N):
            J_u = J_u + ca.dot(qu, U[k] ** 2)
        t_final = 0
        for i in range(m1):
            t_final = t_final + self.kc[i] * ph["dtm"][i] + (n - self.kc[i]) * ph["dtw"][i]
        V_tot = ca.sum1(ph["V"][1:])
        a, goal = P["a"], P["goal"]
        return (a[0] * J_u + a[1] * t_final + a[2] * (V_tot - P["vt"]) ** 2 + a[3] * ca.sum1(ph["eta"][1:])
                + a[4] * ((X[N][0] - goal[0]) ** 2 + (X[N][1] - goal[1]) ** 2))

    @staticmethod
    def _derivatives(terrain: graph.Terrain, w: Any, p: Any, J: Any, G: Any) -> dict[str, Any]:
        """IPOPT's derivatives, the terrain's from its Taylor coefficients (:class:`.graph.Terrain`)."""
        lam_f, lam_g = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", G.shape[0])
        hess = ca.triu(ca.hessian(lam_f * J + ca.dot(lam_g, G), w)[0])
        jac, grad = ca.jacobian(G, w), ca.gradient(J, w)
        G, J, hess, jac, grad = terrain.substitute([G, J, hess, jac, grad])
        return {"hess_lag": ca.Function("nlp_hess_l", [w, p, lam_f, lam_g], [hess], ["x", "p", "lam_f", "lam_g"],
                                        ["triu_hess_gamma_x_x"]),
                "jac_g": ca.Function("nlp_jac_g", [w, p], [G, jac], ["x", "p"], ["g", "jac_g_x"]),
                "grad_f": ca.Function("nlp_grad_f", [w, p], [J, grad], ["x", "p"], ["f", "grad_f_x"])}

    def take_build_time(self) -> float:
        """Construction seconds (the graph, then each IPOPT solver with its derivatives) not yet
        reported: a planner adds them to its build time once."""
        t, self._unreported_build_s = self._unreported_build_s, 0.0
        return t

    def take_cache_state(self) -> str | None:
        """How this NLP was made — ``hit`` (loaded from the disk cache), ``miss`` (built and stored)
        or ``off`` (built, no cache) — the first time it is asked, then None."""
        state, self._cache_unreported = (self.cache if self._cache_unreported else None), False
        return state

    # -- packing -----------------------------------------------------------------------------------
    def pack_p(self, **vals: Any) -> np.ndarray:
        return np.concatenate([np.asarray(vals[k], float).reshape(-1) for k, _ in self.p_parts])

    def _slices(self) -> dict[str, slice]:
        out, o = {}, 0
        for k, ln in self.v_parts:
            out[k] = slice(o, o + ln)
            o += ln
        return out

    def pack_w(self, X: np.ndarray, U: np.ndarray, ph: dict[str, np.ndarray], slack: np.ndarray) -> np.ndarray:
        parts = [np.asarray(X[1:], float).T.reshape(-1, order="F"), np.asarray(U, float).T.reshape(-1, order="F")]
        parts += [np.asarray(ph[k], float) for k, _ in self.v_parts[2:-1]] + [np.asarray(slack, float)]
        return np.concatenate(parts)

    def unpack(self, w: np.ndarray, s0: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray], np.ndarray]:
        sl = self._slices()
        X = np.vstack([s0[None, :], w[sl["X"]].reshape(self.N, NX)])
        U = w[sl["U"]].reshape(self.N, NU)
        ph = {k: w[sl[k]].copy() for k, _ in self.v_parts[2:-1]}
        return X, U, ph, w[sl["slack"]].copy()

    def node_times(self, dtm: np.ndarray, dtw: np.ndarray) -> np.ndarray:
        dts = [dtm[i] if k < self.kc[i] else dtw[i] for i in range(self.m1) for k in range(self.n)]
        return np.concatenate([[0.0], np.cumsum(dts)])

    # -- bounds --------------------------------------------------------------------------------------
    def bounds(self, box: tuple[float, float, float, float], fixed_tasks: dict[str, np.ndarray] | None = None,
               max_dig_phases: int | None = None,
               stand: tuple[float, float, float] | None = None,
               truck_stand: tuple[float, float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Variable bounds. ``stand = (x, y, tol)``: the base ends phase 0 within ``tol`` of
        (x, y) (``Shape.hold_base``: it stands there for the whole horizon); ``truck_stand``: the
        same for the truck, at the stand the planner chose (``planners/stl_tamp/stand.py``)."""
        sh, exc, tr = self.shape, self.exc, self.truck
        m1, n, N = self.m1, self.n, self.N
        mg = 0.999
        lbx = np.full((N, NX), -np.inf)
        ubx = np.full((N, NX), np.inf)
        lbx[:, 4], ubx[:, 4] = BOOM_BOUNDS
        lbx[:, 5], ubx[:, 5] = ARM_BOUNDS
        ulim = np.array([exc.travel_speed, exc.yaw_rate, exc.swing_rate, exc.joint_rate, exc.joint_rate,
                         tr.travel_speed, tr.yaw_rate]) * mg
        if stand is not None:  # node n is column n - 1 (node 0 is the parameter s0)
            lbx[n - 1, :2] = (stand[0] - stand[2], stand[1] - stand[2])
            ubx[n - 1, :2] = (stand[0] + stand[2], stand[1] + stand[2])
        if truck_stand is not None:
            lbx[n - 1, 6:8], ubx[n - 1, 6:8] = np.subtract(truck_stand[:2], truck_stand[2]), np.add(truck_stand[:2], truck_stand[2])
        lbu = np.tile(-ulim, (N, 1))
        ubu = np.tile(ulim, (N, 1))
        for i in range(m1):
            for k in range(self.kc[i], n):  # the base is still while digging and dumping
                lbu[i * n + k, :2] = 0.0
                ubu[i * n + k, :2] = 0.0
        if sh.hold_truck:
            lbu[n:, 5:] = 0.0
            ubu[n:, 5:] = 0.0
        if sh.hold_base:
            lbu[n:, :2] = 0.0
            ubu[n:, :2] = 0.0
            lbu[:n, 2] = 0.0
            ubu[:n, 2] = 0.0
        ph_lb = {"dtm": np.full(m1, 0.01), "dtw": np.full(m1, 0.05), "eta": np.zeros(m1), "px": np.full(m1, box[0]),
                 "py": np.full(m1, box[2]), "psi": np.full(m1, -np.inf), "V": np.zeros(m1)}
        ph_ub = {"dtm": np.full(m1, sh.dtm_max), "dtw": np.full(m1, sh.dtw_max), "eta": np.ones(m1),
                 "px": np.full(m1, box[1]), "py": np.full(m1, box[3]), "psi": np.full(m1, np.inf),
                 "V": np.full(m1, sh.vmax)}
        ph_ub["eta"][0] = 0.0
        ph_ub["V"][0] = 0.0
        if max_dig_phases is not None:
            ph_ub["eta"][1 + max_dig_phases:] = 0.0
        if fixed_tasks:
            for key, vals in fixed_tasks.items():
                vals = np.asarray(vals, float)
                ph_lb[key][1:] = vals
                ph_ub[key][1:] = vals
        lb = self.pack_w(np.vstack([np.zeros(NX), lbx]), lbu, ph_lb, np.zeros(2))
        ub = self.pack_w(np.vstack([np.zeros(NX), ubx]), ubu, ph_ub, np.full(2, np.inf))
        return lb, ub

    # -- solve ------------------------------------------------------------------------------------------
    def solver(self, max_iter: int, options: dict[str, Any] | None = None,
               casadi_options: dict[str, Any] | None = None) -> Any:
        """The IPOPT solver for this iteration cap and options (built once). ``casadi_options`` go
        to ``nlpsol`` itself, e.g. ``{"expand": True}`` or ``{"jit": True, ...}``. There is no CPU-
        or wall-time cap: a plan must not depend on how loaded the machine is."""
        key = (max_iter, repr(sorted((options or {}).items())), repr(sorted((casadi_options or {}).items())))
        if key not in self._solvers:
            t0 = time.perf_counter()
            ipopt = {"max_iter": max_iter, "print_level": 0, "tol": 1e-6,
                     "acceptable_tol": 1e-3, "acceptable_iter": 5, "mu_strategy": "adaptive",
                     "linear_solver": "mumps", "hessian_approximation": "exact", "sb": "yes"}
            ipopt.update(options or {})
            self._solvers[key] = ca.nlpsol("stl_tamp", "ipopt", self._nlp_fn, {"ipopt": ipopt, "print_time": False,
                                                                      **self._derivs, **(casadi_options or {})})
            one_blas_thread()
            dt = time.perf_counter() - t0
            self.build_time_s += dt
            self._unreported_build_s += dt
        return self._solvers[key]

    def solve(self, params: np.ndarray, w0: np.ndarray, box: tuple[float, float, float, float], *,
              fixed_tasks: dict[str, np.ndarray] | None = None, max_dig_phases: int | None = None,
              max_iter: int = 300, options: dict[str, Any] | None = None,
              accept_feasible: float = 0.0, casadi_options: dict[str, Any] | None = None,
              stand: tuple[float, float, float] | None = None, solver: str = "ipopt",
              truck_stand: tuple[float, float, float] | None = None,
              fatrop_options: dict[str, Any] | None = None) -> Solution:
        """Solve from ``w0``. ``success`` is IPOPT's own success, or an acceptable-level stop with
        violation < 1e-4, or — when ``accept_feasible`` > 0 — an iteration cap whose last
        iterate violates no constraint by more than ``accept_feasible`` (status says which).
        ``solver="fatrop"``: FATROP on the stage-by-stage NLP (:mod:`.staged`; ``options``' μ₀
        and tolerance, ``fatrop_options`` on top), IPOPT from the same start when it fails
        (``info["fallback"]``); every solve is counted (:meth:`take_solver_counts`)."""
        lb, ub = self.bounds(box, fixed_tasks, max_dig_phases, stand, truck_stand)
        params, w0 = quantize(params), np.clip(quantize(w0), lb, ub)
        first: dict[str, Any] = {}
        if solver == "fatrop" and self.staged() is not None:
            sol = self._solve_staged(params, w0, lb, ub, max_iter, options or {}, fatrop_options or {})
            if sol.success:
                return sol
            self._counts["fallback"] += 1
            first = {"fallback": sol.status, "fatrop_iterations": sol.iterations, "fatrop_s": sol.solve_time_s}
        elif solver not in ("ipopt", "fatrop"):
            raise ValueError(f"unknown solver {solver!r}: 'fatrop' or 'ipopt'")
        self._counts["ipopt"] += 1
        S = self.solver(max_iter, options, casadi_options)
        t0 = time.perf_counter()
        res = S(x0=w0, p=params, lbx=lb, ubx=ub, lbg=self.lbg, ubg=self.ubg)
        dt = time.perf_counter() - t0 + first.get("fatrop_s", 0.0)
        st = self.last_stats = S.stats()
        w = np.array(res["x"]).reshape(-1)
        viol = self._violation(np.array(res["g"]).reshape(-1))
        status = st.get("return_status", "unknown")
        ok = bool(st.get("success", False)) or (status == "Solved_To_Acceptable_Level" and viol < 1e-4)
        if not ok and accept_feasible > 0 and status == "Maximum_Iterations_Exceeded" \
                and viol < accept_feasible:
            ok, status = True, f"{status} (feasible iterate accepted)"
        iters = int(st.get("iter_count", -1)) + first.get("fatrop_iterations", 0)
        return self._solution(w, params, ok, status, iters, dt, float(res["f"]),
                              {"max_violation": viol, "solver": "ipopt", **first})

    def _violation(self, gv: np.ndarray) -> float:
        return float(np.max(np.concatenate([self.lbg - gv, gv - self.ubg, [0.0]])))

    def _solve_staged(self, params: np.ndarray, w0: np.ndarray, lb: np.ndarray, ub: np.ndarray, max_iter: int,
                      options: dict[str, Any], fatrop_options: dict[str, Any]) -> Solution:
        """FATROP's solve; a success only when the classic NLP's constraints hold to 1e-4 at it."""
        assert self._staged is not None
        opts = {**staged.FATROP_DEFAULTS, "max_iter": max_iter,
                **{k: options[k] for k in ("mu_init", "tol") if k in options}, **fatrop_options}
        self._counts["fatrop"] += 1
        t0 = time.perf_counter()
        w, ok, status, iters = self._staged.solve(params, w0, lb, ub, params[self.K + 2:self.K + 2 + NX], opts)
        dt = time.perf_counter() - t0
        f, gv = (np.array(v).reshape(-1) for v in self._nlp_fn(w, params))
        viol = self._violation(gv)
        ok = ok and viol < 1e-4
        return self._solution(w, params, ok, "Solve_Succeeded" if ok else f"fatrop {status}", iters, dt, float(f[0]),
                              {"max_violation": viol, "solver": "fatrop"})

    def staged(self) -> staged.StagedSolver | None:
        """FATROP's form of this NLP (:mod:`.staged`), loaded on first use like the classic one
        (compiled, from the disk cache or built); None for a shape it does not cover."""
        if self._staged is None and self.shape.symbolic == "SX" and self.shape.hold_truck:
            t0 = time.perf_counter()
            name = nlp_key(self.shape, self.exc, self.truck, staged_layout=True)
            fns = compiled.load(prepared_dir(), name, staged.HELPER_NAMES)
            done = fns is not None
            fns = fns or build_functions(self.shape, self.exc, self.truck, staged_layout=True)[1]
            self._staged = staged.StagedSolver(fns, self.site_box, compiled=done)
            dt = time.perf_counter() - t0
            self.build_time_s += dt
            self._unreported_build_s += dt
        return self._staged

    def take_solver_counts(self) -> dict[str, int]:
        """Solves by FATROP and by IPOPT, and FATROP's failures that IPOPT solved again
        (``fallback``), since last asked."""
        out, self._counts = self._counts, {"fatrop": 0, "ipopt": 0, "fallback": 0}
        return out

    def reseed(self, sol: Solution, w0: np.ndarray, params: np.ndarray, eta_on: float, eta: float = 0.6) -> np.ndarray | None:
        """A restart for a solve that stopped short of its volume with idle phases.

        The disjunction (5) has a trap: once a phase's η has fallen to ε its load spec no longer
        binds, its arm drifts away from the truck, and raising η again would violate
        ``ρ^{φ1 ∧ φ_D}`` — IPOPT then reports a local optimum that misses the target volume.
        The restart takes the solution and gives the idle phases back their initial-guess arm
        motion and ``η = eta``. Returns None when there is nothing to reseed.
        """
        vt = float(params[self.K + 2 + NX])
        if float(np.sum(sol.V)) >= vt - 2 * self.shape.eps_v:
            return None
        idle = [i for i in range(1, self.m1) if sol.eta[i] < eta_on]
        if not idle:
            return None
        sl = self._slices()
        w = sol.info["w"].copy()
        X0 = w0[sl["X"]].reshape(self.N, NX)
        X = w[sl["X"]].reshape(self.N, NX)
        U0 = w0[sl["U"]].reshape(self.N, NU)
        U = w[sl["U"]].reshape(self.N, NU)
        e = w[sl["eta"]]
        for i in idle:
            ks = slice(i * self.n - 1 if i > 0 else 0, (i + 1) * self.n)
            X[ks, 3:6] = X0[ks, 3:6]
            U[i * self.n:(i + 1) * self.n, 2:5] = U0[i * self.n:(i + 1) * self.n, 2:5]
            e[i] = eta
        w[sl["X"]] = X.reshape(-1)
        w[sl["U"]] = U.reshape(-1)
        w[sl["eta"]] = e
        for key in ("px", "py", "psi"):
            w[sl[key]][idle] = w0[sl[key]][idle]
        return w

    def _solution(self, w: np.ndarray, params: np.ndarray, ok: bool, status: str, iters: int, dt: float, cost: float,
                  info: dict[str, Any]) -> Solution:
        s0 = params[self.K + 2:self.K + 2 + NX]
        X, U, ph, _ = self.unpack(w, s0)
        return Solution(X, U, ph["dtm"], ph["dtw"], ph["eta"], ph["px"], ph["py"], ph["psi"], ph["V"],
                        self.node_times(ph["dtm"], ph["dtw"]), ok, status, iters, dt, cost, info=dict(info, w=w))

    def evaluate(self, w: np.ndarray, params: np.ndarray) -> dict[str, Any]:
        """Model volumes and exact-vs-smooth robustness of a candidate (used for guesses and checks)."""
        vol = np.array(self._vol_fn(w, params)).reshape(-1)
        rt, rs = self._rho_fn(w, params)
        return {"volumes": vol, "rho_task": float(rt), "rho_safe": float(rs),
                "contact_heights": np.array(self._pz_fn(w, params)).reshape(-1)}

    def tips(self, X: np.ndarray, floor: float) -> np.ndarray:
        return np.array(self._tip_fn(X[1:].T, X[0], floor)).T
