"""What fixes the STL-TAMP NLP and what comes out of it, without CasADi.

The state and input layout, the arm's bounds and inverse kinematics, :class:`Shape` (the NLP's
structure, its cache key), :class:`Solution` and the input rounding. Kept apart from
:mod:`.model` (the CasADi graph) so that importing the planners loads no CasADi: a case
process pays that import with its first solve, not at start-up (docs/DESIGN.md §10).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from earthbench.world import ExcavatorSpec

NX, NU = 9, 7
#: Every number handed to IPOPT (parameters and start point) is rounded to this grid (m, rad,
#: m³): IPOPT's path through a nonconvex problem magnifies any input difference, so a terrain
#: changed by 1e-9 m (another CPU's rounding in a fit) gave plans up to 33 % apart in time per m³.
#: Rounded, inputs that differ by far less than the quantum are the same input (unless one
#: straddles a rounding boundary: a chance of about 1e-5 per number), so the plan is the same.
QUANTUM = 1e-4
PIVOT_HEIGHT = 1.5  # boom pivot above the base's ground (m)
BOOM_BOUNDS = (-1.0, 1.3)
ARM_BOUNDS = (-2.9, -0.2)


@dataclass(frozen=True)
class Shape:
    """Everything that fixes the NLP's structure (its cache key with the machine specs)."""

    phases: int  # m: dig phases after phase 0
    steps: int  # n: motion steps per phase
    contact_step: int  # k_c: move steps before the contact node in a dig phase
    unit_width: float  # bucket (or local area) width
    unit_length: float  # drag length (or local area length)
    unit_depth: float  # d_dig
    vmax: float  # V_max per phase, Eq. (21)
    work_time: float  # s of work per phase at η = 1 (stroke + dump)
    terrain_shape: tuple[int, int]  # (ny, nx) of the RBF lattice parameter
    terrain_spacing: float
    terrain_sigma: float
    quad: tuple[int, int] = (3, 3)  # Gauss–Legendre nodes along the drag, across
    dtm_max: float = 2.0
    dtw_max: float = 3.0
    sigmoid_k: float = 20.0
    widen: float = 0.15
    eps_eta: float = 0.05
    eps_v: float = 0.01
    eps_d: float = 0.01
    eps_r: float = 0.05
    beta: float = 30.0
    margin: float = 0.1
    col_margin: float = 0.3
    q_u: tuple[float, ...] = (1.0, 10.0, 0.05, 0.05, 0.05)
    q_u_truck: tuple[float, ...] = (1.0, 10.0)
    eta_saturation: float = 0.1
    hold_truck: bool = True  # truck inputs fixed to 0 after phase 0 (see the class docstring)
    # the execution model (the referee's durations): the base stands still after phase 0 and the
    # upper body does not swing in phase 0 (a swing there is charged at the next dig), and the
    # work steps pay the swing on top of stroke and dump. False for the global layer, whose
    # phases are areas the base drives between.
    hold_base: bool = False
    swing_smooth: float = 0.02  # rad: the smoothing of |Δθ_turn| in the priced swing
    symbolic: str = "SX"  # "SX": scalar graphs, fastest here; "MX": matrix graphs (tests/bench compares them)


@dataclass
class Solution:
    """A solved (or fallen-back) NLP, unpacked."""

    X: np.ndarray  # (N+1, 9) nodes
    U: np.ndarray  # (N, 7)
    dtm: np.ndarray  # (m+1,)
    dtw: np.ndarray
    eta: np.ndarray
    px: np.ndarray
    py: np.ndarray
    psi: np.ndarray
    V: np.ndarray
    times: np.ndarray  # (N+1,) node times from the horizon's start
    success: bool
    status: str
    iterations: int
    solve_time_s: float
    cost: float
    used_fallback: bool = False
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def t_final(self) -> float:
        return float(self.times[-1])


def quantize(v: np.ndarray) -> np.ndarray:
    """``v`` rounded to the :data:`QUANTUM` grid (infinite bounds stay infinite)."""
    v = np.asarray(v, float)
    return np.where(np.isfinite(v), np.round(v / QUANTUM) * QUANTUM, v)


def inverse_kinematics(r: float, z_rel: float, spec: ExcavatorSpec) -> tuple[float, float]:
    """(boom, arm) angles putting the tip at horizontal radius ``r`` and height ``z_rel`` above the pivot."""
    l1, l2 = spec.boom_length, spec.arm_length
    d = min(max(math.hypot(r, z_rel), abs(l1 - l2) + 1e-3), l1 + l2 - 1e-3)
    c = (d * d - l1 * l1 - l2 * l2) / (2 * l1 * l2)
    arm = -math.acos(min(max(c, -1.0), 1.0))
    boom = math.atan2(z_rel, r) - math.atan2(l2 * math.sin(arm), l1 + l2 * math.cos(arm))
    boom = min(max(boom, BOOM_BOUNDS[0] + 1e-3), BOOM_BOUNDS[1] - 1e-3)
    arm = min(max(arm, ARM_BOUNDS[0] + 1e-3), ARM_BOUNDS[1] - 1e-3)
    return boom, arm
