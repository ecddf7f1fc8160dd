"""Signal temporal logic over discrete time steps, with exact and smooth robustness.

Formulas are small immutable trees::

    mu = Predicate(lambda s, k: s["x"][k] - 1.0)       # x_k − 1 > 0
    phi = Globally(mu, 0, 5) & Finally(Predicate.gt("y", 0.2), 2, 8)
    phi.rho(signal)                 # exact robustness at step 0 (min/max), floats or CasADi
    phi.rho(signal, smooth=20.0)    # smooth robustness (log-sum-exp, sharpness 20)

A *signal* is any mapping from names to sequences indexed by step (numpy arrays, lists of
floats, or lists/vectors of CasADi expressions); its length is the length of its first entry
unless given as ``signal["__len__"]``. Temporal operators use step intervals ``[k + a, k + b]``
clipped to the signal's end (Maler & Nickovic's semantics on a finite, discrete trace; an
empty window is an error rather than a silent ±∞).

Smooth robustness replaces ``max`` by ``(1/β) log Σ exp(β x_i)`` and ``min`` by its mirror,
both evaluated with the max-shift ``m + (1/β) log Σ exp(β (x_i − m))`` so that nothing
overflows or underflows however far a signal is from its threshold (the shift ``m`` is the
exact max; the shifted expression is the same function, so its derivatives are the
log-sum-exp's). Bounds: ``max ≤ smax ≤ max + log(N)/β`` and ``min − log(N)/β ≤ smin ≤ min``,
so the smooth value converges to the exact one as ``β`` grows. A smooth ``G``/``∧`` is a lower
bound of the exact robustness (sound for constraints ``ρ̃ ≥ 0``); a smooth ``F``/``∨`` is an
upper bound — callers who need soundness for them check the exact robustness afterwards.
This is the plain log-sum-exp smoothing; Gilpin, Kurtz and Lin's measure differs only in
using a weighted mean for ``min`` to stay sound for ``∨``, which we did not need here.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

Signal = Mapping[str, Any]


def _is_casadi(values: Sequence[Any]) -> bool:
    try:
        import casadi as ca
    except ImportError:  # pragma: no cover - casadi is a runtime dependency
        return False
    return any(isinstance(v, (ca.SX, ca.MX, ca.DM)) for v in values)


def hard_max(values: Sequence[Any]) -> Any:
    if _is_casadi(values):
        import casadi as ca

        out = values[0]
        for v in values[1:]:
            out = ca.fmax(out, v)
        return out
    return max(float(v) for v in values)


def hard_min(values: Sequence[Any]) -> Any:
    if _is_casadi(values):
        import casadi as ca

        out = values[0]
        for v in values[1:]:
            out = ca.fmin(out, v)
        return out
    return min(float(v) for v in values)


def smooth_max(values: Sequence[Any], beta: float) -> Any:
    """``(1/β) log Σ exp(β x_i)`` with the max-shift; numpy floats or CasADi expressions."""
    if len(values) == 1:
        return values[0]
    if _is_casadi(values):
        import casadi as ca

        x = ca.vertcat(*values)
        m = ca.mmax(x)
        return m + ca.log(ca.sum1(ca.exp(beta * (x - m)))) / beta
    x = np.asarray(values, dtype=float)
    m = float(np.max(x))
    return m + math.log(float(np.sum(np.exp(beta * (x - m))))) / beta


def smooth_min(values: Sequence[Any], beta: float) -> Any:
    """``−(1/β) log Σ exp(−β x_i)`` with the shift; a lower bound of ``min``."""
    return -smooth_max([-v for v in values], beta)


class Formula:
    """Base class. ``rho(signal, k, smooth=None)`` is the robustness at step ``k``."""

    def rho(self, signal: Signal, k: int = 0, *, smooth: float | None = None) -> Any:
        raise NotImplementedError

    def satisfied(self, signal: Signal, k: int = 0) -> bool:
        return float(self.rho(signal, k)) > 0.0

    def __and__(self, other: Formula) -> And:
        return And((self, other))

    def __or__(self, other: Formula) -> Or:
        return Or((self, other))

    def __invert__(self) -> Not:
        return Not(self)


def signal_length(signal: Signal) -> int:
    if "__len__" in signal:
        return int(signal["__len__"])
    for key, v in signal.items():
        if not key.startswith("__"):
            try:
                return int(v.shape[0])  # numpy / CasADi column
            except AttributeError:
                return len(v)
    raise ValueError("an empty signal has no length; give signal['__len__']")


@dataclass(frozen=True)
class Predicate(Formula):
    """``μ(s, k) > 0`` for a function ``μ`` of the signal and the step."""

    fn: Callable[[Signal, int], Any]
    name: str = "μ"

    def rho(self, signal: Signal, k: int = 0, *, smooth: float | None = None) -> Any:
        return self.fn(signal, k)

    @staticmethod
    def gt(key: str, c: float, index: int | None = None) -> Predicate:
        """``signal[key][k] − c > 0`` (``index`` picks a component of a vector signal)."""
        if index is None:
            return Predicate(lambda s, k: s[key][k] - c, f"{key}>{c}")
        return Predicate(lambda s, k: s[key][k][index] - c, f"{key}[{index}]>{c}")

    @staticmethod
    def lt(key: str, c: float, index: int | None = None) -> Predicate:
        """``c − signal[key][k] > 0``."""
        if index is None:
            return Predicate(lambda s, k: c - s[key][k], f"{key}<{c}")
        return Predicate(lambda s, k: c - s[key][k][index], f"{key}[{index}]<{c}")


@dataclass(frozen=True)
class Not(Formula):
    arg: Formula

    def rho(self, signal: Signal, k: int = 0, *, smooth: float | None = None) -> Any:
        return -self.arg.rho(signal, k, smooth=smooth)


@dataclass(frozen=True)
class And(Formula):
    args: tuple[Formula, ...]

    def rho(self, signal: Signal, k: int = 0, *, smooth: float | None = None) -> Any:
        vals = [a.rho(signal, k, smooth=smooth) for a in self.args]
        return hard_min(vals) if smooth is None else smooth_min(vals, smooth)

    def __and__(self, other: Formula) -> And:
        return And(self.args + (other,))


@dataclass(frozen=True)
class Or(Formula):
    args: tuple[Formula, ...]

    def rho(self, signal: Signal, k: int = 0, *, smooth: float | None = None) -> Any:
        vals = [a.rho(signal, k, smooth=smooth) for a in self.args]
        return hard_max(vals) if smooth is None else smooth_max(vals, smooth)

    def __or__(self, other: Formula) -> Or:
        return Or(self.args + (other,))


def _window(signal: Signal, k: int, a: int, b: int) -> range:
    if a < 0 or b < a:
        raise ValueError(f"temporal interval [{a}, {b}] must satisfy 0 ≤ a ≤ b")
    n = signal_length(signal)
    lo, hi = k + a, min(k + b, n - 1)
    if lo > hi:
        raise ValueError(f"temporal window [{k + a}, {k + b}] lies beyond the signal's {n} steps")
    return range(lo, hi + 1)


@dataclass(frozen=True)
class Finally(Formula):
    """``F[a,b] φ``: φ holds at some step in ``[k + a, k + b]``."""

    arg: Formula
    a: int
    b: int

    def rho(self, signal: Signal, k: int = 0, *, smooth: float | None = None) -> Any:
        vals = [self.arg.rho(signal, j, smooth=smooth) for j in _window(signal, k, self.a, self.b)]
        return hard_max(vals) if smooth is None else smooth_max(vals, smooth)


@dataclass(frozen=True)
class Globally(Formula):
    """``G[a,b] φ``: φ holds at every step in ``[k + a, k + b]``."""

    arg: Formula
    a: int
    b: int

    def rho(self, signal: Signal, k: int = 0, *, smooth: float | None = None) -> Any:
        vals = [self.arg.rho(signal, j, smooth=smooth) for j in _window(signal, k, self.a, self.b)]
        return hard_min(vals) if smooth is None else smooth_min(vals, smooth)


@dataclass(frozen=True)
class Const(Formula):
    """A formula with a fixed robustness (``true`` is ``Const(+big)``), e.g. an empty φ_I."""

    value: float

    def rho(self, signal: Signal, k: int = 0, *, smooth: float | None = None) -> Any:
        return self.value


def robustness_constraints(formula: Formula, signal: Signal, k: int = 0, *, smooth: float | None = None) -> list[Any]:
    """Expressions ``r_j`` with ``min_j r_j = ρ^φ`` at the top-level min-operators of ``φ``.

    ``ρ^{φ1 ∧ φ2} ≥ s`` holds exactly when ``ρ^{φ1} ≥ s`` and ``ρ^{φ2} ≥ s``, and
    ``ρ^{G[a,b] φ} ≥ s`` when ``ρ^φ ≥ s`` at every step of the window. An optimiser that needs a
    lower bound on the robustness can therefore impose one constraint per conjunct/step instead
    of one smoothed minimum over all of them: the bound is then exact (no smoothing error) at
    the top level, and each constraint touches only its own steps — the smoothed minimum over
    a long horizon ties every step's variables together and makes the Hessian dense. Below the
    top-level ``∧``/``G`` (inside ``∨``, ``F``, ``¬``) the robustness is evaluated as usual,
    smooth when ``smooth`` is given. A constant conjunct is returned as its value (a number
    among the expressions), so ``min_j r_j = ρ^φ`` holds for every formula.
    """
    if isinstance(formula, And):
        out: list[Any] = []
        for a in formula.args:
            out.extend(robustness_constraints(a, signal, k, smooth=smooth))
        return out
    if isinstance(formula, Globally):
        out = []
        for j in _window(signal, k, formula.a, formula.b):
            out.extend(robustness_constraints(formula.arg, signal, j, smooth=smooth))
        return out
    # anything else, a constant conjunct included, is one constraint: min_j r_j must be ρ^φ, so
    # a conjunct ``Const(-1)`` bounds the robustness by −1 whatever the signal
    return [formula.rho(signal, k, smooth=smooth)]
