"""The pieces of the STL-TAMP model both NLP layouts share: the fitted terrain with its lifted
derivatives, the sigmoid cut window, the cut terrain and the modelled volume (paper Eq. (1),
(20), (27)–(28)). :mod:`.model` writes them into the classic NLP (all variables in one block,
for IPOPT) and :mod:`.staged` into the stage-by-stage one (for FATROP); both call the same
functions in the same order, so the two NLPs are the same mathematics (docs/DESIGN.md §6).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from .problem import PIVOT_HEIGHT, Shape


def sigmoid(x: Any, k: float) -> Any:
    return 1.0 / (1.0 + ca.exp(-k * x))


def softplus(x: Any, delta: float = 0.01) -> Any:
    """Smooth max(x, 0)."""
    return 0.5 * (x + ca.sqrt(x * x + delta * delta))


def tip_position(s: Any, spec: Any, floor: Any = 0.0) -> tuple[Any, Any, Any]:
    """Bucket tip (x, y, z) of state ``s`` (planar boom–arm on the swing bearing)."""
    bear = s[2] + s[3]
    r = spec.boom_length * ca.cos(s[4]) + spec.arm_length * ca.cos(s[4] + s[5])
    z = floor + PIVOT_HEIGHT + spec.boom_length * ca.sin(s[4]) + spec.arm_length * ca.sin(s[4] + s[5])
    return s[0] + r * ca.cos(bear), s[1] + r * ca.sin(bear), z


@dataclass(frozen=True)
class Cut:
    """One dig phase's cut: η, the corner (px, py), the drag direction (ux, uy), the floor h."""

    eta: Any
    px: Any
    py: Any
    ux: Any
    uy: Any
    h: Any = None


class Terrain:
    """The fitted RBF terrain of the parameters ``w`` (lattice weights) and ``o`` (origin).

    In SX each evaluation enters the graph as its second-order Taylor polynomial at the point
    itself, with symbolic coefficients (:attr:`anchors`); :meth:`substitute` replaces them, after
    differentiation, by the RBF's value, gradient and Hessian there — each one contraction over
    the weights instead of one per Hessian colour (planners/stl_tamp/NOTES.md, 0.8.0)."""

    def __init__(self, sh: Shape, P_w: Any, P_o: Any):
        ny_t, nx_t = sh.terrain_shape
        self.s2 = 2.0 * sh.terrain_sigma**2
        self.W = ca.reshape(P_w, nx_t, ny_t).T  # row-major (ny, nx) lattice weights
        self.o = P_o
        self.offs_x = ca.DM([a * sh.terrain_spacing for a in range(nx_t)])
        self.offs_y = ca.DM([b * sh.terrain_spacing for b in range(ny_t)])
        self.lifted = sh.symbolic == "SX"
        self.anchors: list[Any] = []
        self.anchor_vals: list[Any] = []

    def rbf(self, x: Any, y: Any) -> Any:
        ex = ca.exp(-((x - self.o[0] - self.offs_x) ** 2) / self.s2)
        ey = ca.exp(-((y - self.o[1] - self.offs_y) ** 2) / self.s2)
        return ca.mtimes(ey.T, ca.mtimes(self.W, ex))

    def taylor(self, x: Any, y: Any) -> list[Any]:
        """f0 at (x, y) with its gradient and Hessian, each one contraction with the weights."""
        s2, W = self.s2, self.W
        dx, dy = x - self.o[0] - self.offs_x, y - self.o[1] - self.offs_y
        ex = ca.exp(-(dx**2) / s2)
        ey = ca.exp(-(dy**2) / s2)
        ax, ay = -2.0 * dx / s2, -2.0 * dy / s2
        ex1, ey1 = ex * ax, ey * ay
        ex2, ey2 = ex * (ax * ax - 2.0 / s2), ey * (ay * ay - 2.0 / s2)
        w0, w1, w2 = ca.mtimes(W, ex), ca.mtimes(W, ex1), ca.mtimes(W, ex2)
        return [ca.mtimes(ey.T, w0), ca.mtimes(ey.T, w1), ca.mtimes(ey1.T, w0),
                ca.mtimes(ey.T, w2), ca.mtimes(ey1.T, w1), ca.mtimes(ey2.T, w0)]

    def f0(self, x: Any, y: Any) -> Any:
        """The fitted terrain at (x, y); in SX its Taylor polynomial at (x̄, ȳ) = (x, y)."""
        if not self.lifted:
            return self.rbf(x, y)
        a = ca.SX.sym(f"f0pt{len(self.anchors)}", 8)
        self.anchors.append(a)
        self.anchor_vals.append(ca.vertcat(x, y, *self.taylor(x, y)))
        ddx, ddy = x - a[0], y - a[1]
        return (a[2] + a[3] * ddx + a[4] * ddy + 0.5 * a[5] * ddx * ddx + a[6] * ddx * ddy
                + 0.5 * a[7] * ddy * ddy)

    def substitute(self, exprs: list[Any]) -> list[Any]:
        """``exprs`` with the Taylor coefficients replaced by their values (after differentiating)."""
        if not self.anchors:
            return exprs
        return ca.substitute(exprs, [ca.vertcat(*self.anchors)], [ca.vertcat(*self.anchor_vals)])


def window(sh: Shape, cut: Cut, x: Any, y: Any) -> Any:
    """The sigmoid window of the cut's bucket rectangle at (x, y), Eq. (27)–(28)."""
    kk, W, L = sh.sigmoid_k, sh.unit_width, sh.unit_length
    dx, dy = x - cut.px, y - cut.py
    a = dx * cut.ux + dy * cut.uy
    c = -dx * cut.uy + dy * cut.ux
    return (sigmoid(a, kk) - sigmoid(a - L, kk)) * (sigmoid(c + W / 2, kk) - sigmoid(c - W / 2, kk))


def height(sh: Shape, terrain: Terrain, cuts: list[Cut], x: Any, y: Any) -> Any:
    """The terrain at (x, y) after ``cuts`` in order, Eq. (1)."""
    z = terrain.f0(x, y)
    for cut in cuts:
        z = z - cut.eta * window(sh, cut, x, y) * softplus(z - cut.h)
    return z


def quadrature(sh: Shape) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gauss–Legendre nodes along the drag and across, and their weights, over the bucket's
    rectangle widened by ``widen`` (a sigmoid of steepness k leaks about 3/k of the box)."""
    L, W = sh.unit_length, sh.unit_width
    ga, wa = np.polynomial.legendre.leggauss(sh.quad[0])
    gc, wc = np.polynomial.legendre.leggauss(sh.quad[1])
    a_lo, a_hi = -sh.widen, L + sh.widen
    c_lo, c_hi = -W / 2 - sh.widen, W / 2 + sh.widen
    qa = a_lo + (ga + 1) * 0.5 * (a_hi - a_lo)
    qc = c_lo + (gc + 1) * 0.5 * (c_hi - c_lo)
    qw = np.outer(wa * 0.5 * (a_hi - a_lo), wc * 0.5 * (c_hi - c_lo))
    return qa, qc, qw


def dig(sh: Shape, terrain: Terrain, before: list[Cut], cut: Cut, floor: Any) -> tuple[Any, Any, Cut]:
    """One dig phase's contact height (the terrain at its corner after the earlier cuts), its
    modelled volume, Eq. (20), and the cut with its floor ``h``."""
    pz = height(sh, terrain, before, cut.px, cut.py)
    h = floor + softplus(pz - sh.unit_depth - floor)
    cut = Cut(cut.eta, cut.px, cut.py, cut.ux, cut.uy, h)
    qa, qc, qw = quadrature(sh)
    acc = 0
    for ia, av in enumerate(qa):
        for ic, cv in enumerate(qc):
            x = cut.px + av * cut.ux - cv * cut.uy
            y = cut.py + av * cut.uy + cv * cut.ux
            z = height(sh, terrain, before, x, y)
            acc = acc + float(qw[ia, ic]) * window(sh, cut, x, y) * softplus(z - h)
    return pz, cut.eta * acc, cut


def euler_step(s: Any, u: Any, dt: Any) -> Any:
    """Eq. (2), (13), (14): the change of state over one step, headings at mid-step."""
    yb = s[2] + 0.5 * u[1] * dt
    yd = s[8] + 0.5 * u[6] * dt
    f = ca.vertcat(u[0] * ca.cos(yb), u[0] * ca.sin(yb), u[1], u[2], u[3], u[4],
                   u[5] * ca.cos(yd), u[5] * ca.sin(yd), u[6])
    return f * dt


def contact_rows(sh: Shape, exc: Any, s: Any, tip: tuple[Any, Any, Any], cut: Cut, pz: Any) -> list[tuple[Any, float, float]]:
    """At a dig phase's contact node: the bucket tip on the cut's corner, heading back along the
    drag, Eq. (3) with (16), and the corner and the drag's end within reach, Eq. (15)."""
    rmin, rmax = exc.reach_min + sh.margin, exc.reach_max - sh.margin
    tx, ty, tz = tip
    bear = s[2] + s[3] + np.pi  # the drag runs back toward the machine
    gap = ((tx - cut.px) ** 2 + (ty - cut.py) ** 2 + (tz - pz) ** 2
           + (ca.cos(bear) - cut.ux) ** 2 + (ca.sin(bear) - cut.uy) ** 2)
    rows = [(cut.eta * (sh.eps_d - gap), 0.0, ca.inf)]
    ex_, ey_ = cut.px + sh.unit_length * cut.ux, cut.py + sh.unit_length * cut.uy
    for qx, qy in ((cut.px, cut.py), (ex_, ey_)):
        rows.append(((qx - s[0]) ** 2 + (qy - s[1]) ** 2, rmin**2, rmax**2))
    return rows


def corners(sh: Shape, cut: Cut) -> list[Any]:
    """The (x, y) of the cut rectangle's four corners (bounded by the site's box at solve time)."""
    L, W = sh.unit_length, sh.unit_width
    out = []
    for sa in (0.0, L):
        for sc in (-W / 2, W / 2):
            out.append(ca.vertcat(cut.px + sa * cut.ux - sc * cut.uy, cut.py + sa * cut.uy + sc * cut.ux))
    return out


def dump_reach_row(sh: Shape, exc: Any, truck: Any, s: Any) -> tuple[Any, float, float]:
    """The truck within the bucket's reach of the base."""
    reach_dt = exc.reach_max + truck.loading_radius - sh.margin
    return ((s[0] - s[6]) ** 2 + (s[1] - s[7]) ** 2, 0.0, reach_dt**2)


def work_row(sh: Shape, exc: Any, eta: Any, dtw: Any, dturn: Any) -> tuple[Any, float, float]:
    """A dig phase's work steps last its stroke and dump (and, with ``hold_base``, the swing to
    the truck, ``dturn``): a stroke and a dump take their full time however little the bucket
    takes in, so the work time saturates in η (concave), which makes fewer, fuller digs cheaper."""
    busy = 1.0 - ca.exp(-eta / sh.eta_saturation)
    nw = sh.steps - sh.contact_step
    if sh.hold_base:
        # the referee's durations: the net swing over the work steps, a smooth |·|, on top
        swing = ca.sqrt(dturn**2 + sh.swing_smooth**2)
        return (nw * dtw - swing / exc.swing_rate - busy * sh.work_time, 0.0, ca.inf)
    return (nw * dtw - busy * sh.work_time, 0.0, ca.inf)


def mu_load(truck: Any, eta: Any, s: Any, tip: tuple[Any, Any, Any]) -> Any:
    """The loading predicate, Eq. (18): a digging phase's bucket over the truck, normalised."""
    r2 = truck.loading_radius**2
    return (r2 - eta * ((tip[0] - s[6]) ** 2 + (tip[1] - s[7]) ** 2)) / r2


def mu_col(sh: Shape, exc: Any, s: Any) -> Any:
    """The clearance predicate, Eq. (23): base and truck apart, normalised."""
    lcol2 = (exc.clearance + sh.col_margin) ** 2
    return ((s[0] - s[6]) ** 2 + (s[1] - s[7]) ** 2 - lcol2) / lcol2
