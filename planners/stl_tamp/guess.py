"""Initial guesses for :class:`~earthbench_planners.stl_tamp.model.PhaseNLP` from inverse kinematics.

planners/stl_tamp/NOTES.md: from a constant guess IPOPT runs into its iteration limit; a guess that already
drives the base to its dig poses, swings the arm to spread-out contact points by inverse
kinematics and back to the truck converges. The guess here is *dynamically consistent*: base
and truck turn in place and then drive straight (both exact under the model's mid-step Euler
rule), joints move linearly, and the step durations are long enough for every rate limit at
80 %. It is therefore also the bounded fallback when a solve fails: the conversion to a plan
re-checks every referee rule on it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from earthbench.motion import wrap

from .problem import NU, NX, PIVOT_HEIGHT, inverse_kinematics

if TYPE_CHECKING:  # CasADi loads with the first solve, not with the planner (problem.py)
    from .model import PhaseNLP

DUMP_HEIGHT = 1.0  # tip height above the pivot over the truck (m)


@dataclass(frozen=True)
class PhaseSeed:
    """What one dig phase should do: contact, drag heading, η, base position and truck position."""

    px: float
    py: float
    psi: float
    eta: float
    base: tuple[float, float]
    truck: tuple[float, float]
    pz: float = 0.0  # terrain height at the contact


def _turn_then_drive(x0: float, y0: float, yaw0: float, x1: float, y1: float, steps: int,
                     speed: float, rate: float) -> tuple[np.ndarray, float]:
    """Nodes (steps+1, 3) turning in place toward (x1, y1) (forward or reverse), then driving."""
    out = np.zeros((steps + 1, 3))
    out[:, 0], out[:, 1], out[:, 2] = x0, y0, yaw0
    dist = math.hypot(x1 - x0, y1 - y0)
    if dist < 1e-6 or steps == 0:
        return out, 0.05
    bearing = math.atan2(y1 - y0, x1 - x0)
    fwd, rev = wrap(bearing - yaw0), wrap(bearing + math.pi - yaw0)
    delta = fwd if abs(fwd) <= abs(rev) else rev
    nt = steps // 2 if abs(delta) > 1e-3 and steps >= 2 else 0
    nd = steps - nt
    dt = max(abs(delta) / (0.8 * rate * max(nt, 1)) if nt else 0.0, dist / (0.8 * speed * nd), 0.05)
    for k in range(1, steps + 1):
        if k <= nt:
            out[k] = (x0, y0, yaw0 + delta * k / nt)
        else:
            f = (k - nt) / nd
            out[k] = (x0 + f * (x1 - x0), y0 + f * (y1 - y0), yaw0 + delta)
    return out, dt


def build_guess(nlp: PhaseNLP, s0: np.ndarray, seeds: list[PhaseSeed | None], floor: float) -> np.ndarray:
    """A start vector ``w0`` for ``nlp`` from per-phase seeds (None: an idle phase, η = 0)."""
    sh, m1, N = nlp.shape, nlp.m1, nlp.N
    X = np.zeros((N + 1, NX))
    X[0] = s0
    ph = {k: np.zeros(m1) for k in ("dtm", "dtw", "eta", "px", "py", "psi", "V")}
    seeds = list(seeds) + [None] * (m1 - 1 - len(seeds))
    active = [s for s in seeds if s is not None]
    first = active[0] if active else None
    last_seed: PhaseSeed | None = None
    for i in range(m1):
        seed = None if i == 0 else seeds[i - 1]
        if seed is not None:
            last_seed = seed
        ref = seed or last_seed
        dtm = _travel(nlp, X, i, seed, first)
        dtw = 0.05
        if ref is not None and i > 0:
            dtm, dtw = _arm(nlp, X, ph, i, seed, ref, floor, dtm)
        elif ref is not None:
            ph["px"][i], ph["py"][i], ph["psi"][i] = ref.px, ref.py, ref.psi
        ph["dtm"][i] = min(max(dtm, 0.01), sh.dtm_max)
        ph["dtw"][i] = min(max(dtw, 0.05), sh.dtw_max)
    if not active:
        ph["px"][:] = s0[0]
        ph["py"][:] = s0[1]
    U = _controls(nlp, X, ph)
    w0 = nlp.pack_w(X, U, ph, np.zeros(2))
    return w0


def _travel(nlp: PhaseNLP, X: np.ndarray, i: int, seed: PhaseSeed | None, first: PhaseSeed | None) -> float:
    """Phase ``i``'s base (and, in phase 0, truck) nodes, turn then drive; its move step."""
    exc, tr, n, kc, k0 = nlp.exc, nlp.truck, nlp.n, nlp.kc[i], i * nlp.n
    s = X[k0].copy()
    # base travel during the move steps
    if i == 0:
        goal_b = first.base if first is not None else (s[0], s[1])
    else:
        goal_b = seed.base if seed is not None else (s[0], s[1])
    base_nodes, dtm = _turn_then_drive(s[0], s[1], s[2], goal_b[0], goal_b[1], kc, exc.travel_speed, exc.yaw_rate)
    # the truck moves only in phase 0, over all its steps
    if i == 0 and first is not None:
        truck_nodes, dtt = _turn_then_drive(s[6], s[7], s[8], first.truck[0], first.truck[1], n,
                                            tr.travel_speed, tr.yaw_rate)
        # phase 0 shares one step duration: make it long enough for both machines
        dtm = max(dtm, dtt * n / max(kc, 1))
    else:
        truck_nodes = np.tile(s[6:9], (n + 1, 1))
    for k in range(1, n + 1):
        X[k0 + k] = X[k0]
        X[k0 + k, 0:3] = base_nodes[min(k, kc)]
        X[k0 + k, 6:9] = truck_nodes[k]
    return dtm


def _arm(nlp: PhaseNLP, X: np.ndarray, ph: dict[str, np.ndarray], i: int, seed: PhaseSeed | None, ref: PhaseSeed,
         floor: float, dtm: float) -> tuple[float, float]:
    """Dig phase ``i``'s arm by inverse kinematics, to the contact and on to the truck; its
    task; its move and work steps."""
    sh, exc, n, kc, k0 = nlp.shape, nlp.exc, nlp.n, nlp.kc[i], i * nlp.n
    b = X[k0 + kc]
    bear_c = math.atan2(ref.py - b[1], ref.px - b[0])
    r_c = math.hypot(ref.px - b[0], ref.py - b[1])
    turn_c = b[3] + wrap(bear_c - (b[2] + b[3]))
    boom_c, arm_c = inverse_kinematics(r_c, ref.pz - floor - PIVOT_HEIGHT, exc)
    bear_t = math.atan2(b[7] - b[1], b[6] - b[0])
    r_t = math.hypot(b[6] - b[0], b[7] - b[1])
    turn_t = turn_c + wrap(bear_t - bear_c)
    boom_t, arm_t = inverse_kinematics(min(r_t, exc.boom_length + exc.arm_length - 0.05), DUMP_HEIGHT, exc)
    prev = X[k0 + kc, 3:6].copy()
    # the arm reaches the contact at node kc: spread its motion over the move steps
    for k in range(1, kc + 1):
        f = k / kc
        X[k0 + k, 3:6] = prev + f * (np.array([turn_c, boom_c, arm_c]) - prev)
    if kc == 0:
        X[k0, 3:6] = (turn_c, boom_c, arm_c)
    nw = n - kc
    for k in range(kc + 1, n + 1):
        f = (k - kc) / nw
        X[k0 + k, 3:6] = (turn_c + f * (turn_t - turn_c), boom_c + f * (boom_t - boom_c), arm_c + f * (arm_t - arm_c))
    jrate = 0.8 * min(exc.swing_rate, exc.joint_rate)
    move_j = np.max(np.abs(np.array([turn_c, boom_c, arm_c]) - prev))
    work_j = max(abs(turn_t - turn_c), abs(boom_t - boom_c), abs(arm_t - arm_c))
    dtm = max(dtm, move_j / (jrate * max(kc, 1)))
    eta = seed.eta if seed is not None else 0.0
    swing = abs(turn_t - turn_c) / exc.swing_rate if sh.hold_base else 0.0  # priced on top (problem.Shape.hold_base)
    dtw = max(work_j / (jrate * nw), ((1.0 - math.exp(-eta / sh.eta_saturation)) * sh.work_time + swing) * 1.05 / nw, 0.05)
    ph["px"][i], ph["py"][i], ph["psi"][i], ph["eta"][i] = ref.px, ref.py, ref.psi, eta
    return dtm, dtw


def _controls(nlp: PhaseNLP, X: np.ndarray, ph: dict[str, np.ndarray]) -> np.ndarray:
    """The inputs from the node differences (exact for turn-then-drive nodes), clipped to the
    rates, and the nodes integrated again from them (``X`` in place)."""
    exc, tr, m1, n, N = nlp.exc, nlp.truck, nlp.m1, nlp.n, nlp.N
    times_dt = [ph["dtm"][i] if k < nlp.kc[i] else ph["dtw"][i] for i in range(m1) for k in range(n)]
    U = np.zeros((N, NU))
    for k in range(N):
        dt = times_dt[k]
        a, b = X[k], X[k + 1]
        for (ix, iy, iyaw, iv, iw) in ((0, 1, 2, 0, 1), (6, 7, 8, 5, 6)):
            dyaw = b[iyaw] - a[iyaw]
            mid = a[iyaw] + 0.5 * dyaw
            chord = (b[ix] - a[ix]) * math.cos(mid) + (b[iy] - a[iy]) * math.sin(mid)
            U[k, iv] = chord / dt
            U[k, iw] = dyaw / dt
        U[k, 2:5] = (b[3:6] - a[3:6]) / dt
    # the guess steps were sized for the rates; clip residual noise and rebuild the nodes exactly
    lim = np.array([exc.travel_speed, exc.yaw_rate, exc.swing_rate, exc.joint_rate, exc.joint_rate,
                    tr.travel_speed, tr.yaw_rate]) * 0.999
    U = np.clip(U, -lim, lim)
    for k in range(N):
        dt = times_dt[k]
        a, u = X[k], U[k]
        yb, yd = a[2] + 0.5 * u[1] * dt, a[8] + 0.5 * u[6] * dt
        X[k + 1] = a + dt * np.array([u[0] * math.cos(yb), u[0] * math.sin(yb), u[1], u[2], u[3], u[4],
                                      u[5] * math.cos(yd), u[5] * math.sin(yd), u[6]])
    return U


def fill_volumes(nlp: PhaseNLP, w0: np.ndarray, params: np.ndarray, goals: list[float] | None = None) -> np.ndarray:
    """Make the guess consistent with Eq. (20)–(21): η_i scaled so the model volume of each
    active phase is its goal (default 95 % of V_max, η ≤ 1), then V_i set to the model volume."""
    sl = nlp._slices()
    w = w0.copy()
    vmax = nlp.shape.vmax
    for _ in range(2):  # later phases see earlier cuts: two passes settle the chain
        ev = nlp.evaluate(w, params)
        eta = w[sl["eta"]].copy()
        for i in range(1, nlp.m1):
            if eta[i] <= 0:
                continue
            per_eta = ev["volumes"][i - 1] / eta[i]
            goal = 0.95 * vmax if goals is None else min(goals[i - 1], 0.95 * vmax)
            if per_eta > 1e-6:
                eta[i] = float(np.clip(goal / per_eta, 2 * nlp.shape.eps_eta, 1.0))
        w[sl["eta"]] = eta
    ev = nlp.evaluate(w, params)
    V = np.zeros(nlp.m1)
    V[1:] = np.clip(ev["volumes"], 0.0, vmax)
    w[sl["V"]] = V
    return w


def settle_contacts(nlp: PhaseNLP, s0: np.ndarray, seeds: list[PhaseSeed], floor: float,
                    params: np.ndarray) -> list[PhaseSeed]:
    """``seeds`` with each contact height taken from the model after the earlier phases' cuts:
    a later phase that digs where an earlier one cut would otherwise start with its tip up to a
    bucket's depth above the ground, the contact constraint (3) violated."""
    pz = nlp.evaluate(build_guess(nlp, s0, seeds, floor), params)["contact_heights"]
    return [dataclasses.replace(sd, pz=float(h)) for sd, h in zip(seeds, pz)]
