"""The STL-TAMP NLP written stage by stage, for a solver that factorises stage by stage (FATROP).

:mod:`.model`'s classic NLP puts every node in one block and the per-phase variables (η, the
cut, the durations, the volume) in another, and its constraints tie any node to any phase:
IPOPT factorises that whole KKT system at once (MUMPS, most of a solve's time). Here the same
problem is an optimal-control problem over the ``N + 1`` nodes (docs/DESIGN.md §6): stage ``k``
holds a state ``z_k`` and a control ``v_k``, in the order ``z_0, v_0, z_1, …, z_N``, and each
stage's constraints follow its gap-closing rows ``z_{k+1} − F_k(z_k, v_k) = 0``.

- A phase's variables are controls at its first stage and states from then on, carried by
  ``F`` unchanged as long as a later stage reads them (a cut's corner, heading, η and contact
  height until the last phase has been posed: the terrain's nested cuts, Eq. (1)).
- What a constraint needs from an earlier node is lifted into the state: the swing at the
  contact (for the work time) and the running smooth maximum of the loading predicate over the
  window of F (18), ``a_{k+1} = smax(a_k, μ_k)`` — the log-sum-exp is associative, so the
  window's smooth maximum is the same function as the classic NLP's; the total volume for the
  cost's target term likewise.
- The first node is a state fixed by its bounds to the parameter ``s0``.

Every classic variable is one variable here (:attr:`StagedFunctions.classic`), so a start, its
bounds and a solution map across; the lifted states of a start come from ``lift`` (their
values at that start). Nothing of the model is written twice: the terrain, cuts, volume and
predicates are :mod:`.graph`'s, as in the classic NLP.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from . import graph
from .problem import NU, NX, Shape
from .stl import smooth_max, smooth_min

_CUT = ("eta", "px", "py", "psi", "pz")


class _Layout:
    """Which named items each stage's state and control hold, and for how long a phase's are kept."""

    def __init__(self, sh: Shape):
        self.m1, self.n = sh.phases + 1, sh.steps
        self.N = self.m1 * self.n
        self.kc = [self.n] + [sh.contact_step] * sh.phases
        N, n, m1 = self.N, self.n, self.m1
        self.states: list[list[tuple[str, int]]] = [[] for _ in range(N + 1)]
        self.ctrls: list[list[tuple[str, int]]] = [[] for _ in range(N + 1)]
        self.carry("s", NX, 0, N)
        for k in range(N):
            self.ctrls[k].append(("u", NU))
        self.ctrls[0].append(("slack", 2))
        self.carry("slack", 2, 1, N)
        last_pose = (m1 - 1) * n  # the last phase's first stage reads every earlier cut
        for i in range(m1):
            start, end = i * n, (i + 1) * n
            self.ctrls[start] += [(f"{k}{i}", 1) for k in ("dtm", "dtw", "eta", "px", "py", "psi", "V")]
            self.carry(f"dtm{i}", 1, start + 1, end - 1)
            self.carry(f"dtw{i}", 1, start + 1, end if i else end - 1)
            if i == 0:
                continue
            for k in _CUT:
                self.carry(f"{k}{i}", 1, start + 1, max(end, last_pose))
            self.carry(f"V{i}", 1, start + 1, end)
            kn = start + self.kc[i]
            if sh.hold_base:
                self.carry(f"turn{i}", 1, kn + 1, end)
            self.carry(f"acc{i}", 1, kn + 2, end)
        self.carry("Vc", 1, n + 1, N)

    def carry(self, name: str, size: int, first: int, last: int) -> None:
        for k in range(first, last + 1):
            self.states[k].append((name, size))


class _Stages:
    """The staged variables (symbols per stage and item) and the rows and cost of each stage."""

    def __init__(self, lay: _Layout):
        self.lay = lay
        self.Z = [{nm: ca.SX.sym(f"{nm}_{k}", sz) for nm, sz in lay.states[k]} for k in range(lay.N + 1)]
        self.V = [{nm: ca.SX.sym(f"{nm}_{k}", sz) for nm, sz in lay.ctrls[k]} for k in range(lay.N + 1)]
        self.gap: list[dict[str, Any]] = [{} for _ in range(lay.N)]
        self.path: list[list[tuple[Any, float, float]]] = [[] for _ in range(lay.N + 1)]
        self.site: list[list[int]] = [[] for _ in range(lay.N + 1)]  # per stage: which path rows are corners
        self.cost: list[Any] = [0] * (lay.N + 1)

    def get(self, k: int, name: str) -> Any:
        return self.Z[k][name] if name in self.Z[k] else self.V[k][name]

    def variables(self) -> list[Any]:
        out = []
        for k in range(self.lay.N + 1):
            out += [self.Z[k][nm] for nm, _ in self.lay.states[k]] + [self.V[k][nm] for nm, _ in self.lay.ctrls[k]]
        return out

    def rows(self) -> tuple[Any, list[float], list[float], list[int]]:
        """g in FATROP's order (each stage's gap-closing rows, then its own), bounds, corner rows."""
        g: list[Any] = []
        lbg: list[float] = []
        ubg: list[float] = []
        site: list[int] = []

        def add(expr: Any, lo: float, hi: float) -> None:
            g.append(expr)
            lbg.extend([lo] * expr.shape[0])
            ubg.extend([hi] * expr.shape[0])

        for k in range(self.lay.N + 1):
            if k < self.lay.N:
                for nm, _ in self.lay.states[k + 1]:
                    add(self.Z[k + 1][nm] - self.gap[k][nm], 0.0, 0.0)
            for j, row in enumerate(self.path[k]):
                if j in self.site[k]:
                    site.append(len(lbg))
                add(*row)
        return ca.vertcat(*g), lbg, ubg, site


def _phase_stage(st: _Stages, sh: Shape, terrain: graph.Terrain, P: dict[str, Any], i: int, k: int) -> None:
    """Phase ``i``'s first stage: its cut, contact height and volume, Eq. (1), (20), its corners,
    its time and η in the cost; its variables go on in the state."""
    lay, g = st.lay, st.gap[k]
    a = P["a"]
    dtm, dtw = st.get(k, f"dtm{i}"), st.get(k, f"dtw{i}")
    st.cost[k] = st.cost[k] + a[1] * (lay.kc[i] * dtm + (lay.n - lay.kc[i]) * dtw)
    for nm in ("dtm", "dtw", "eta", "px", "py", "psi", "V"):
        g[f"{nm}{i}"] = st.V[k][f"{nm}{i}"]
    if i == 0:
        return
    before = []
    for j in range(1, i):
        pz_j = st.get(k, f"pz{j}")
        h = P["floor"] + graph.softplus(pz_j - sh.unit_depth - P["floor"])
        psi = st.get(k, f"psi{j}")
        before.append(graph.Cut(st.get(k, f"eta{j}"), st.get(k, f"px{j}"), st.get(k, f"py{j}"), ca.cos(psi), ca.sin(psi), h))
    v = st.V[k]
    cut = graph.Cut(v[f"eta{i}"], v[f"px{i}"], v[f"py{i}"], ca.cos(v[f"psi{i}"]), ca.sin(v[f"psi{i}"]))
    pz, vol, cut = graph.dig(sh, terrain, before, cut, P["floor"])
    g[f"pz{i}"] = pz
    st.path[k].append((v[f"V{i}"] - vol, 0.0, 0.0))
    for corner in graph.corners(sh, cut):
        st.site[k].append(len(st.path[k]))
        st.path[k].append((corner, -ca.inf, ca.inf))
    st.cost[k] = st.cost[k] + a[3] * v[f"eta{i}"]
    g["Vc"] = v[f"V{i}"] if i == 1 else st.Z[k]["Vc"] + v[f"V{i}"]


def _node(st: _Stages, sh: Shape, exc: Any, truck: Any, P: dict[str, Any], k: int) -> None:
    """Stage ``k``'s own rows: the dynamics, clearance, the contact and the loading window of
    its phase, the end of the phase before it; what it carries on."""
    lay = st.lay
    s = st.Z[k]["s"]
    tip = graph.tip_position(s, exc, P["floor"])
    st.path[k].append((graph.mu_col(sh, exc, s) - st.get(k, "slack")[1], 0.0, ca.inf))  # Eq. (23), G over 0..N
    if k < lay.N:
        i, j = divmod(k, lay.n)
        u = st.V[k]["u"]
        dt = st.get(k, f"dtm{i}" if j < lay.kc[i] else f"dtw{i}")
        st.gap[k]["s"] = s + graph.euler_step(s, u, dt)
        qu = ca.DM(list(sh.q_u) + list(sh.q_u_truck))
        st.cost[k] = st.cost[k] + P["a"][0] * ca.dot(qu, u**2)
    for i in range(1, lay.m1):
        start, end = i * lay.n, (i + 1) * lay.n
        kn = start + lay.kc[i]
        if start < k <= end:
            _in_phase(st, sh, exc, truck, P, i, k, s, tip, kn, end)


def _in_phase(st: _Stages, sh: Shape, exc: Any, truck: Any, P: dict[str, Any], i: int, k: int, s: Any,
              tip: Any, kn: int, end: int) -> None:
    """Stage ``k`` inside dig phase ``i`` (after its first stage)."""
    eta = st.get(k, f"eta{i}")
    if k == kn:  # Eq. (3), (15), (16) at the contact
        psi = st.get(k, f"psi{i}")
        cut = graph.Cut(eta, st.get(k, f"px{i}"), st.get(k, f"py{i}"), ca.cos(psi), ca.sin(psi))
        st.path[k] += graph.contact_rows(sh, exc, s, tip, cut, st.get(k, f"pz{i}"))
        st.path[k].append(graph.dump_reach_row(sh, exc, truck, s))
    load = graph.mu_load(truck, eta, s, tip)
    if k > kn:  # F (18) over nodes kn+1 … end: the running smooth maximum
        acc = load if k == kn + 1 else smooth_max([st.Z[k][f"acc{i}"], load], sh.beta)
        if k < end:
            st.gap[k][f"acc{i}"] = acc
        else:
            V, phi0 = st.get(k, f"V{i}"), sh.eps_eta - eta
            task = smooth_max([smooth_min([phi0, 1e3], sh.beta),
                               smooth_min([eta - sh.eps_eta, (V - sh.eps_v) / sh.vmax, acc], sh.beta)], sh.beta)
            st.path[k].append((task - st.get(k, "slack")[0], 0.0, ca.inf))  # Eq. (5)
            dturn = s[3] - st.Z[k][f"turn{i}"] if sh.hold_base else 0.0
            st.path[k].append(graph.work_row(sh, exc, eta, st.get(k, f"dtw{i}"), dturn))
    if sh.hold_base and k == kn and k < end:
        st.gap[k][f"turn{i}"] = s[3]


def build(shape: Shape, exc: Any, truck: Any) -> dict[str, Any]:
    """The staged NLP's functions: ``nlp`` (x, p) → (f, g); FATROP's derivatives (``hess_lag``,
    the gradient of the Lagrangian and its whole Hessian; ``jac_g``; ``grad_f``); ``lift``
    (a classic start and the parameters → the staged start); ``layout`` (the stage sizes, the
    classic index of every staged variable, the rows of the dig corners, the bounds of g)."""
    if shape.symbolic != "SX" or not shape.hold_truck:
        raise ValueError("the staged NLP is written for SX graphs with the truck held after phase 0")
    lay = _Layout(shape)
    st = _Stages(lay)
    P = {k: ca.SX.sym(nm, ln) for k, nm, ln in (("w", "terrain_w", shape.terrain_shape[0] * shape.terrain_shape[1]),
                                                 ("o", "terrain_o", 2), ("s0", "s0", NX), ("vt", "v_target", 1),
                                                 ("a", "alpha", 5), ("goal", "goal", 2), ("floor", "floor", 1))}
    p = ca.vertcat(*P.values())
    terrain = graph.Terrain(shape, P["w"], P["o"])
    for k in range(lay.N + 1):
        if k < lay.N and k % lay.n == 0:
            _phase_stage(st, shape, terrain, P, k // lay.n, k)
        _node(st, shape, exc, truck, P, k)
        if k < lay.N:  # whatever the next state holds and no rule above set is carried
            for nm, _ in lay.states[k + 1]:
                if nm not in st.gap[k]:
                    st.gap[k][nm] = st.get(k, nm)
    a, goal, sN = P["a"], P["goal"], st.Z[lay.N]["s"]
    st.cost[lay.N] = a[2] * (st.Z[lay.N]["Vc"] - P["vt"]) ** 2 + a[4] * ((sN[0] - goal[0]) ** 2 + (sN[1] - goal[1]) ** 2)
    return _functions(st, terrain, P, p)


def _functions(st: _Stages, terrain: graph.Terrain, P: dict[str, Any], p: Any) -> dict[str, Any]:
    lay = st.lay
    x = ca.vertcat(*st.variables())
    G, lbg, ubg, site = st.rows()
    J = sum(st.cost[1:], st.cost[0])
    lam_f, lam_g = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", G.shape[0])
    lag = lam_f * J + ca.dot(lam_g, G)
    hess, grad_l = ca.hessian(lag, x)
    jac, grad = ca.jacobian(G, x), ca.gradient(J, x)
    G2, J2, hess, grad_l, jac, grad = terrain.substitute([G, J, hess, grad_l, jac, grad])
    classic, wc = _classic_index(lay)
    lift = _lift(st, P, wc, terrain)
    nx = [sum(sz for _, sz in lay.states[k]) for k in range(lay.N + 1)]
    nu = [sum(sz for _, sz in lay.ctrls[k]) for k in range(lay.N + 1)]
    ng = [sum(r[0].shape[0] for r in st.path[k]) for k in range(lay.N + 1)]
    return {
        "nlp": ca.Function("nlp", [x, p], [J2, G2], ["x", "p"], ["f", "g"]),
        "hess_lag": ca.Function("nlp_hess_l", [x, p, lam_f, lam_g], [grad_l, hess], ["x", "p", "lam_f", "lam_g"],
                                ["grad_gamma_x", "hess_gamma_x_x"]),
        "jac_g": ca.Function("nlp_jac_g", [x, p], [G2, jac], ["x", "p"], ["g", "jac_g_x"]),
        "grad_f": ca.Function("nlp_grad_f", [x, p], [grad], ["x", "p"], ["grad_f_x"]),
        "lift": ca.Function("lift", [wc, p], [lift]),
        "layout": ca.Function("layout", [], [ca.DM(nx), ca.DM(nu), ca.DM(ng), ca.DM(classic), ca.DM(site),
                                             ca.DM(lbg), ca.DM(ubg)]),
    }


def _classic_index(lay: _Layout) -> tuple[list[int], Any]:
    """Per staged variable, its index in the classic NLP's ``w`` (-1: a copy or a lifted value;
    -2: the first node, fixed to ``s0``), and the classic ``w`` as a symbol."""
    m1, N = lay.m1, lay.N
    nw = NX * N + NU * N + 7 * m1 + 2
    ph0 = NX * N + NU * N
    phase = {nm: ph0 + j * m1 for j, nm in enumerate(("dtm", "dtw", "eta", "px", "py", "psi", "V"))}
    out: list[int] = []
    for k in range(N + 1):
        for nm, sz in lay.states[k]:
            if nm == "s":
                out += list(range((k - 1) * NX, k * NX)) if k else [-2] * NX
            else:
                out += [-1] * sz
        for nm, _sz in lay.ctrls[k]:
            if nm == "u":
                out += list(range(NX * N + k * NU, NX * N + (k + 1) * NU))
            elif nm == "slack":
                out += [nw - 2, nw - 1]
            else:
                key, i = nm.rstrip("0123456789"), int(nm[len(nm.rstrip("0123456789")):])
                out.append(phase[key] + i)
    return out, ca.SX.sym("w_classic", nw)


def _lift(st: _Stages, P: dict[str, Any], wc: Any, terrain: graph.Terrain) -> Any:
    """The staged start of a classic start ``wc``: classic variables as they are, the first
    node ``s0``, every copy and lifted value as ``F`` makes it from the stage before."""
    lay = st.lay
    classic, _ = _classic_index(lay)
    vals: list[Any] = []
    pos = 0
    prev_syms: list[Any] = []
    prev_vals: list[Any] = []
    for k in range(lay.N + 1):
        syms, here = [], []
        items = [(nm, sz, st.Z[k]) for nm, sz in lay.states[k]] + [(nm, sz, st.V[k]) for nm, sz in lay.ctrls[k]]
        for nm, sz, where in items:
            idx = classic[pos:pos + sz]
            if idx[0] >= 0:
                v = ca.vertcat(*[wc[i] for i in idx])
            elif idx[0] == -2:
                v = P["s0"]
            else:
                v = ca.substitute(terrain.substitute([st.gap[k - 1][nm]]), prev_syms, prev_vals)[0]
            syms.append(where[nm])
            here.append(v)
            pos += sz
        vals += here
        prev_syms, prev_vals = syms, here
    return ca.vertcat(*vals)


#: What a FATROP ``nlpsol`` of the staged NLP evaluates (:mod:`.compiled` compiles these).
SOLVER_NAMES = ("nlp", "nlp_f", "nlp_g", "nlp_grad_f", "nlp_jac_g", "nlp_hess_l", "nlp_grad")
HELPER_NAMES = ("lift", "layout")
#: FATROP's settings that are no IPOPT setting: the first regularisation of the Hessian when the
#: stage recursion finds it indefinite (FATROP's default 1e-8 left 5 of 9 local solves of
#: ``paper-extensive`` seed 0 at 7 m³ in the disjunction trap, 1e-2 one; NOTES.md).
FATROP_DEFAULTS: dict[str, Any] = {"delta_w0": 1e-2, "print_level": 0}


def nlpsol_options(dims: dict[str, Any], fns: dict[str, Any] | None) -> dict[str, Any]:
    """``nlpsol``'s options for FATROP on the staged NLP: the stage sizes, and the derivatives
    built here (``fns``; None when they come compiled with the oracle's library)."""
    opts: dict[str, Any] = {"structure_detection": "manual", **dims, "print_time": False}
    if fns is not None:
        opts["cache"] = {"nlp_hess_l": fns["hess_lag"], "nlp_jac_g": fns["jac_g"], "nlp_grad_f": fns["grad_f"]}
    return opts


def solver_functions(fns: dict[str, Any]) -> dict[str, Any]:
    """The oracle and the functions FATROP evaluates, by CasADi's names (for :mod:`.compiled`)."""
    S = ca.nlpsol("stl_tamp_staged", "fatrop", fns["nlp"], nlpsol_options(dimensions(fns["layout"]), fns))
    return {"nlp": fns["nlp"], **{k: S.get_function(k) for k in SOLVER_NAMES[1:]}}


def dimensions(layout: Any) -> dict[str, Any]:
    nx, nu, ng = (np.array(v).reshape(-1).astype(int).tolist() for v in layout.call([])[:3])
    return {"N": len(nx) - 1, "nx": nx, "nu": nu, "ng": ng}


class StagedSolver:
    """FATROP on the staged NLP of a :class:`~.model.PhaseNLP`: starts, bounds and solutions in the
    classic layout, mapped across (:func:`build`)."""

    def __init__(self, fns: dict[str, Any], site_box: tuple[float, float, float, float], compiled: bool):
        self.fns = fns
        _, _, _, classic, site, lbg, ubg = (np.array(v).reshape(-1) for v in fns["layout"].call([]))
        self.dims = dimensions(fns["layout"])
        self.classic = classic.astype(int)
        rows = site.astype(int)
        xmin, xmax, ymin, ymax = site_box  # every corner of every dig rectangle inside the site
        lbg[rows], ubg[rows] = xmin + 1e-3, xmax - 1e-3
        lbg[rows + 1], ubg[rows + 1] = ymin + 1e-3, ymax - 1e-3
        self.lbg, self.ubg = lbg, ubg
        self._derived = None if compiled else fns
        self._solvers: dict[str, Any] = {}
        self.last_stats: dict[str, Any] = {}  # the last solve's, where its time went (scripts/stl_tamp_cpu.py)

    def solver(self, options: dict[str, Any]) -> Any:
        key = repr(sorted(options.items()))
        if key not in self._solvers:
            opts = nlpsol_options(self.dims, self._derived)
            self._solvers[key] = ca.nlpsol("stl_tamp_staged", "fatrop", self.fns["nlp"], {**opts, "fatrop": options})
        return self._solvers[key]

    def solve(self, params: np.ndarray, w0: np.ndarray, lb: np.ndarray, ub: np.ndarray, s0: np.ndarray,
              options: dict[str, Any]) -> tuple[np.ndarray, bool, str, int]:
        """FATROP from the classic start ``w0`` within the classic bounds: the classic solution,
        FATROP's success, its status and its iterations."""
        S = self.solver(options)
        c = self.classic
        mine = c >= 0
        lbs, ubs = np.full(c.shape, -np.inf), np.full(c.shape, np.inf)
        lbs[mine], ubs[mine] = lb[c[mine]], ub[c[mine]]
        lbs[c == -2] = ubs[c == -2] = s0
        x0 = np.clip(np.array(self.fns["lift"](w0, params)).reshape(-1), lbs, ubs)
        res = S(x0=x0, p=params, lbx=lbs, ubx=ubs, lbg=self.lbg, ubg=self.ubg)
        st = self.last_stats = S.stats()
        w = w0.copy()
        w[c[mine]] = np.array(res["x"]).reshape(-1)[mine]
        return w, bool(st.get("success", False)), str(st.get("return_status", "unknown")), int(st.get("iter_count", -1))
