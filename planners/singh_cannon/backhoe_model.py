"""Forward model and dig evaluation of the Singh–Cannon refined planner for a backhoe.

Singh and Cannon (section 3.1.2) search a dig over two action parameters: the distance ``d``
along the radial line from the excavator and the approach angle ``α`` of the bucket (Fig. 6).
A forward model of the closed-loop dig controller predicts, for each candidate, the bucket's
trajectory through the terrain, the swept volume, the time and the energy; candidates that
leave the workspace or cut below the floor are rejected, and the rest are scored with the
product of three quality functions (Fig. 7). This module is that forward model, vectorised in
numpy over all candidates of one radial line at once.

Bucket trajectory (the controller we model)
-------------------------------------------
The bucket enters the terrain at the contact point ``c = base + d·u`` (``u`` the outward unit
vector of the radial line) with its bottom plate pitched down at the approach angle ``α``. A
depth servo holds the heel on the surface while the lip bites, so the lip settles at
``h(α) = min(h_max, L_b · sin α)`` below the surface at ``c`` (``L_b`` = lip-to-heel length of
the bucket); it then drags the lip horizontally toward the machine at that level,
``λ = z(c) − h(α)``, and curls out when the bucket is full, when the drag reaches the machine's
maximum drag length, when the lip would pass inside the reach annulus or leave the dig area.
That is exactly the flat cut the referee applies (``earthbench.cut.apply_cut``): cells whose
centres lie in the ``width × drag`` rectangle are lowered to ``λ`` in drag order until the
bucket holds its capacity. The swept volume is therefore computed on the grid cell by cell, the
same way, and the drag length we write is where the predicted bucket becomes full.

Soil resistance (energy and time)
---------------------------------
The cutting edge meets the soil at rake angle ``β = α``. The resistance per metre of width of a
layer of thickness ``t`` follows the two-dimensional wedge model of McKyes (the "fundamental
earthmoving equation" without surcharge and adhesion terms)::

    P(t, β) = γ t² N_γ(β) + c t N_c(β)
    N_γ = (cot β + cot ρ) / (2 [cos(β+δ) + sin(β+δ) cot(ρ+φ)])
    N_c = (1 + cot ρ · cot(ρ+φ)) / (cos(β+δ) + sin(β+δ) cot(ρ+φ))

with the failure-plane angle ``ρ`` chosen to minimise the passive force at a reference layer
of 0.3 m. The horizontal (drag) component is ``P · sin(β+δ)``. The cutting energy is the sum
over swept cells of ``r² · P(t_cell) · sin(β+δ)`` (force per width × cell width × cell length),
counting the last cell only by the fraction that fills the bucket. Penetration and the lift of
the full bucket are left out: they are nearly the same for every candidate of a region.

Stroke time = max(min_stroke_time, h / v_pen + max(drag / v_drag, E / P_drag) + t_curl): the
lip descends at ``v_pen``, drags at ``v_drag`` unless the hydraulic power ``P_drag`` limits it,
and curls for ``t_curl``; the machine's minimum stroke time is a floor. A dig's time also
includes the swing from the current upper-body bearing at the spec's swing rate.

Parameters (defaults in :class:`SoilModel` and :class:`ForwardModel`): γ = 17.7 kN/m³ (moist
sandy loam, ρ ≈ 1800 kg/m³), c = 8 kPa, φ = 32°, δ = 20°; L_b = 0.6 m; v_pen = 0.4 m/s;
v_drag = 1.0 m/s; P_drag = 20 kW; t_curl = 1.0 s. With them a full 1 m drag at 0.4 m depth
takes about the spec's 3 s minimum stroke, so easy digs cost only the minimum time.

Quality (Fig. 7)
----------------
``ξ(V) = 0`` below ``V_min``, ``min(V, V_max) / V_max`` above it (``V_max`` = the bucket
capacity still free, constant beyond); ``ψ(E)`` is 1 up to ``E_lo`` and falls linearly to 0
at ``E_hi``; ``ζ(T)`` is 1 up to ``T_lo`` and falls linearly to 0 at ``T_hi``. Quality =
ξ·ψ·ζ; a candidate with quality 0 is infeasible.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

from earthbench.world import ExcavatorSpec, Heightmap


_FACTORS: dict = {}


@dataclass(frozen=True)
class SoilModel:
    """Soil parameters of the resistance model (SI units, angles in radians)."""

    unit_weight: float = 17_700.0
    """γ = ρ·g (N/m³)."""
    cohesion: float = 8_000.0
    """c (Pa)."""
    friction_angle: float = math.radians(32.0)
    """φ, internal friction angle."""
    interface_friction: float = math.radians(20.0)
    """δ, soil–steel friction angle."""

    def factors_cached(self, rake: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`factors` for many rake angles with few distinct values (memoised per value)."""
        uniq, inv = np.unique(np.asarray(rake, dtype=float), return_inverse=True)
        key = (self, uniq.tobytes())
        hit = _FACTORS.get(key)
        if hit is None:
            hit = self.factors(uniq)
            if len(_FACTORS) > 256:
                _FACTORS.clear()
            _FACTORS[key] = hit
        return hit[0][inv], hit[1][inv], hit[2][inv]

    def factors(self, rake: np.ndarray, t_ref: float = 0.3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(N_γ, N_c, horizontal fraction)`` for each rake angle, at the critical failure plane."""
        beta = np.asarray(rake, dtype=float)[:, None]
        rho = np.radians(np.linspace(5.0, 85.0, 161))[None, :]
        phi, delta = self.friction_angle, self.interface_friction
        den = np.cos(beta + delta) + np.sin(beta + delta) / np.tan(rho + phi)
        with np.errstate(divide="ignore", invalid="ignore"):
            n_g = (1.0 / np.tan(beta) + 1.0 / np.tan(rho)) / (2.0 * den)
            n_c = (1.0 + 1.0 / (np.tan(rho) * np.tan(rho + phi))) / den
            p = self.unit_weight * t_ref**2 * n_g + self.cohesion * t_ref * n_c
        p = np.where((den > 0) & np.isfinite(p) & (p > 0), p, np.inf)
        k = np.argmin(p, axis=1)
        rows = np.arange(beta.shape[0])
        return n_g[rows, k], n_c[rows, k], np.sin(beta[:, 0] + delta)


@dataclass(frozen=True)
class ForwardModel:
    """The controller model and quality cut-offs of the refined planner."""

    soil: SoilModel = SoilModel()
    bucket_length: float = 0.6
    """L_b (m): lip-to-heel length; sets the lip depth h(α) = min(h_max, L_b sin α)."""
    alpha_min: float = math.radians(5.0)
    """Smallest approach angle searched; the largest is the one reaching the maximum cut depth."""
    n_d: int = 20
    """Candidate distances along the radial line."""
    n_alpha: int = 10
    """Candidate approach angles (n_d × n_alpha ≈ 200 candidates, as in the paper)."""
    penetration_speed: float = 0.4
    drag_speed: float = 1.0
    drag_power: float = 20_000.0
    curl_time: float = 1.0
    min_drag: float = 0.15
    """Shortest drag (m) worth a stroke; shorter ones are rejected."""
    fill_min: float = 0.9
    """V_min as a fraction of the bucket capacity (ξ = 0 below)."""
    energy_lo: float = 4_000.0
    energy_hi: float = 40_000.0
    """ψ cut-offs (J)."""
    time_span: float = 8.0
    """ζ is 1 up to the minimum stroke time and 0 this many seconds later."""

    def alphas(self, spec: ExcavatorSpec) -> np.ndarray:
        top = math.asin(min(1.0, spec.max_cut_depth / self.bucket_length))
        return np.linspace(self.alpha_min, max(top, self.alpha_min), self.n_alpha)

    def depth(self, alpha: np.ndarray, spec: ExcavatorSpec) -> np.ndarray:
        return np.minimum(spec.max_cut_depth, self.bucket_length * np.sin(alpha))


@dataclass(frozen=True)
class Candidates:
    """The evaluated candidates of one radial line (arrays of length K)."""

    d: np.ndarray
    alpha: np.ndarray
    depth: np.ndarray
    level: np.ndarray
    drag: np.ndarray
    volume: np.ndarray
    energy: np.ndarray
    time: np.ndarray
    quality: np.ndarray
    feasible: np.ndarray

    @property
    def best(self) -> int | None:
        if not self.feasible.any():
            return None
        q = np.where(self.feasible, self.quality, -1.0)
        k = int(np.argmax(q))
        return k if q[k] > 0 else None


class RadialLine:
    """The cells and workspace limits of one radial line (base, bearing) for the bucket width.

    ``s`` is each strip cell's distance along the line from the base, sorted descending (the
    drag runs toward the machine, so that is drag order); ``jj, ii`` index the grid. ``valid``
    samples whether the bucket's cross-section at distance ``s_grid`` lies in the dig area and
    outside every keep-out.
    """

    SAMPLE = 0.02

    def __init__(self, terrain: Heightmap, spec: ExcavatorSpec, base: tuple[float, float], bearing: float,
                 area, keep_outs=(), s_range: tuple[float, float] | None = None):
        self.terrain, self.spec = terrain, spec
        self.bx, self.by = base
        self.bearing = bearing
        self.ux, self.uy = math.cos(bearing), math.sin(bearing)
        lo, hi = s_range if s_range is not None else (spec.reach_min, spec.reach_max)
        lo, hi = max(lo, spec.reach_min), min(hi, spec.reach_max)
        self.lo, self.hi = lo, hi
        r = terrain.resolution
        half = spec.bucket_width / 2
        x0, y0 = terrain.origin
        ny, nx = terrain.shape
        px = (self.bx + self.ux * lo, self.bx + self.ux * hi)
        py = (self.by + self.uy * lo, self.by + self.uy * hi)
        pad = half + r
        i0 = max(int(math.floor((min(px) - pad - x0) / r)), 0)
        i1 = min(int(math.ceil((max(px) + pad - x0) / r)), nx)
        j0 = max(int(math.floor((min(py) - pad - y0) / r)), 0)
        j1 = min(int(math.ceil((max(py) + pad - y0) / r)), ny)
        if i0 >= i1 or j0 >= j1:
            self.s = np.zeros(0)
            self.jj = self.ii = np.zeros(0, dtype=int)
        else:
            cx = x0 + (np.arange(i0, i1) + 0.5) * r - self.bx
            cy = y0 + (np.arange(j0, j1) + 0.5) * r - self.by
            s = cy[:, None] * self.uy + cx[None, :] * self.ux
            across = cy[:, None] * self.ux - cx[None, :] * self.uy
            inside = (np.abs(across) <= half) & (s >= lo - r) & (s <= hi + r)
            jj, ii = np.nonzero(inside)
            order = np.argsort(-s[jj, ii], kind="stable")
            self.s = s[jj, ii][order]
            self.jj, self.ii = jj[order] + j0, ii[order] + i0
        self.flat = self.jj * nx + self.ii
        # workspace samples: the bucket's cross-section (3 points) every SAMPLE metres
        self.s_grid = np.arange(lo, hi + 1e-9, self.SAMPLE)
        if self.s_grid.size == 0:
            self.s_grid = np.array([lo])
        ok = np.ones(self.s_grid.size, dtype=bool)
        for off in (-half, 0.0, half):
            xs = self.bx + self.ux * self.s_grid - self.uy * off
            ys = self.by + self.uy * self.s_grid + self.ux * off
            ok &= shapely.contains_xy(area, xs, ys)
            for ko in keep_outs:
                ok &= ~shapely.contains_xy(ko, xs, ys)
        self.valid = ok

    def inner_limit(self, d: np.ndarray) -> np.ndarray:
        """For contacts at ``d``: the smallest distance the drag may reach (workspace and reach)."""
        bad = np.nonzero(~self.valid)[0]
        lim = np.full(d.shape, self.spec.reach_min)
        if bad.size:
            s_bad = self.s_grid[bad]
            k = np.searchsorted(s_bad, d, side="right") - 1  # last invalid sample at or before d
            has = k >= 0
            lim[has] = np.maximum(lim[has], s_bad[k[has]] + self.SAMPLE)
        # the contact itself must be on a valid sample stretch
        near = np.clip(np.searchsorted(self.s_grid, d), 0, self.s_grid.size - 1)
        prev = np.clip(near - 1, 0, self.s_grid.size - 1)
        ok = self.valid[near] & self.valid[prev]
        lim[~ok] = np.inf
        return lim


def evaluate(
    line: RadialLine,
    z: np.ndarray,
    d: np.ndarray,
    alpha: np.ndarray,
    model: ForwardModel,
    *,
    level_min: float,
    capacity: float,
    swing_time: float,
    v_min: float | None = None,
) -> Candidates:
    """Forward-simulate every candidate ``(d[k], alpha[k])`` of ``line`` on heights ``z``."""
    spec, terrain = line.spec, line.terrain
    r = terrain.resolution
    d = np.asarray(d, dtype=float)
    alpha = np.asarray(alpha, dtype=float)
    h = model.depth(alpha, spec)
    cx, cy = line.bx + line.ux * d, line.by + line.uy * d
    level = terrain.heights_at(cx, cy, z) - h
    inner = line.inner_limit(d)
    drag_max = np.minimum(spec.max_drag_length, d - inner)
    ok = (d <= spec.reach_max + 1e-9) & (d >= spec.reach_min) & (drag_max >= model.min_drag)
    ok &= level >= level_min + 1e-6
    drag_max = np.where(ok, drag_max, 0.0)

    # each candidate's window of strip cells, [a, b) in drag order (s descending), gathered into
    # a (K, W) matrix: the cells with 0 <= d - s <= drag_max, the referee's "along" coordinate.
    # Only feasible rows are simulated.
    n = d.size
    vol = np.zeros(n)
    energy = np.zeros(n)
    stop = drag_max.copy()
    has_full = np.zeros(n, dtype=bool)
    rows = np.nonzero(ok)[0]
    s = line.s
    if rows.size and s.size:
        dk, lk = d[rows], level[rows]
        a = np.searchsorted(-s, -dk, side="left")
        b = np.searchsorted(-s, -(dk - drag_max[rows]), side="right")
        width = max(int((b - a).max()), 1)
        idx = a[:, None] + np.arange(width)[None, :]
        win = idx < b[:, None]
        np.minimum(idx, s.size - 1, out=idx)
        t = np.take(z.ravel(), line.flat[idx])  # cell heights
        t -= lk[:, None]
        np.maximum(t, 0.0, out=t)
        t *= win  # layer thickness above the cut level (m)
        cap_t = capacity / (r * r)  # the capacity in metres of thickness summed over cells
        cum = np.cumsum(t, axis=1)
        full = cum >= cap_t
        hf = full[:, -1].copy()
        first = np.argmax(full, axis=1)
        last = np.where(hf, first, width - 1)
        ar = np.arange(rows.size)
        vol[rows] = np.minimum(cum[:, -1], cap_t) * (r * r)
        stop[rows] = np.where(hf, dk - s[idx[ar, last]], drag_max[rows])
        has_full[rows] = hf
        # cutting energy: force per width × cell area, the last cell by the fraction that fits
        n_g, n_c, horiz = model.soil.factors_cached(alpha[rows])
        g = t * (model.soil.unit_weight * n_g)[:, None]
        g += (model.soil.cohesion * n_c)[:, None]
        g *= t
        cg = np.cumsum(g, axis=1)
        t_last, g_last = t[ar, last], g[ar, last]
        with np.errstate(divide="ignore", invalid="ignore"):
            frac = np.where(hf & (t_last > 0), (cap_t - (cum[ar, last] - t_last)) / t_last, 1.0)
        energy[rows] = (cg[ar, last] - g_last * (1.0 - np.clip(frac, 0.0, 1.0))) * horiz * (r * r)
    drag = np.where(has_full, np.minimum(drag_max, stop + 0.25 * r), drag_max)
    swept = np.where(has_full, stop, drag_max)
    stroke = h / model.penetration_speed + np.maximum(swept / model.drag_speed, energy / model.drag_power) + model.curl_time
    stroke = np.maximum(spec.min_stroke_time, stroke)
    time = swing_time + stroke

    vmin = model.fill_min * capacity if v_min is None else v_min
    xi = xi_volume(vol, vmin, capacity)
    psi = falling(energy, model.energy_lo, model.energy_hi)
    zeta = falling(time, spec.min_stroke_time, spec.min_stroke_time + model.time_span)
    quality = np.where(ok, xi * psi * zeta, 0.0)
    return Candidates(d, alpha, h, level, drag, vol, energy, time, quality, ok & (quality > 0))


def xi_volume(v: np.ndarray, v_min: float, v_max: float) -> np.ndarray:
    """ξ of Fig. 7: 0 below ``v_min`` (vetoed), ``v / v_max`` up to ``v_max``, 1 beyond."""
    v = np.asarray(v, dtype=float)
    return np.where(v >= v_min - 1e-12, np.minimum(v, v_max) / v_max, 0.0)


def falling(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """ψ and ζ of Fig. 7: 1 up to ``lo``, falling linearly to 0 at the cut-off ``hi``, 0 beyond."""
    return np.clip((hi - np.asarray(x, dtype=float)) / (hi - lo), 0.0, 1.0)


def candidate_grid(model: ForwardModel, spec: ExcavatorSpec, d_lo: float, d_hi: float) -> tuple[np.ndarray, np.ndarray]:
    """The n_d × n_alpha grid of (d, α) over a region's radial bounds, flattened."""
    ds = np.linspace(d_lo, d_hi, model.n_d) if d_hi > d_lo else np.full(model.n_d, d_lo)
    dd, aa = np.meshgrid(ds, model.alphas(spec), indexing="ij")
    return dd.ravel(), aa.ravel()
