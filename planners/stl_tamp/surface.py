"""A differentiable terrain surface: a sum of Gaussian RBFs on a lattice, fitted to a heightmap.

Step 1 of the STL-TAMP paper's Algorithm 1 turns the survey grid into a smooth function
``f(x, y)`` that an NLP can differentiate. We use

    f(x, y) = Σ_{a,b} W[b, a] · exp(−((x − cx_a)² + (y − cy_b)²) / (2 σ²))

with centres ``cx_a = x0 + a·h``, ``cy_b = y0 + b·h`` on a regular lattice and one shared width
``σ = sigma_factor · h``. The weights solve the regularised least-squares problem

    min_W  Σ_cells (f(cell centre) − z)²  +  λ · n_cells · ‖W‖²

with cvxpy. The design matrix is a Kronecker product ``A = A_y ⊗ A_x`` (the Gaussian is
separable), so its Gram matrix is ``G = (A_yᵀA_y) ⊗ (A_xᵀA_x)`` and ``Aᵀz = vec(A_yᵀ Z A_x)``.
We hand cvxpy the *same* problem in its compressed, exactly equivalent form
``min ‖R w − c‖²`` with ``RᵀR = G + λ·n_cells·I`` (Cholesky) and ``Rᵀc = Aᵀz``: the objective
differs from the one above only by the constant ``zᵀz − ‖c‖²``. This keeps the problem at
``n_bases`` rows instead of ``n_cells`` and the fit of a 12 m × 6 m map at 0.05 m under a second.

The fitted :class:`RbfSurface` evaluates ``f`` and ``∇f`` in numpy and builds the same
expression in CasADi (SX or MX, with numeric or symbolic weights), so a planner can put the
terrain into its NLP as a parameter vector (see :meth:`RbfSurface.casadi`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from earthbench.errors import ScenarioError
from earthbench.world import Heightmap


@dataclass(frozen=True, eq=False)
class RbfSurface:
    """``f(x, y) = Σ W[b, a] · exp(−‖(x, y) − (cx_a, cy_b)‖² / (2σ²))``.

    ``weights`` has shape ``(ny, nx)`` matching the lattice ``cx = x0 + h·arange(nx)``,
    ``cy = y0 + h·arange(ny)``. ``rms`` is the fit's root-mean-square error over the cells it
    was fitted to (m) and ``fit_time_s`` the wall time of the fit.
    """

    x0: float
    y0: float
    spacing: float
    sigma: float
    weights: np.ndarray
    rms: float = float("nan")
    max_error: float = float("nan")
    fit_time_s: float = float("nan")
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def shape(self) -> tuple[int, int]:
        return self.weights.shape  # type: ignore[return-value]

    @property
    def n_bases(self) -> int:
        return int(self.weights.size)

    @property
    def cx(self) -> np.ndarray:
        return self.x0 + self.spacing * np.arange(self.shape[1])

    @property
    def cy(self) -> np.ndarray:
        return self.y0 + self.spacing * np.arange(self.shape[0])

    # -- numpy ------------------------------------------------------------------------------
    def _factors(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        s2 = 2.0 * self.sigma**2
        dx = x[..., None] - self.cx  # (..., nx)
        dy = y[..., None] - self.cy  # (..., ny)
        return np.exp(-(dx**2) / s2), np.exp(-(dy**2) / s2), dx, dy

    def __call__(self, x: Any, y: Any) -> np.ndarray:
        """Height at points ``(x, y)`` (any broadcastable shapes)."""
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        ex, ey, _, _ = self._factors(x, y)
        return np.einsum("...b,ba,...a->...", ey, self.weights, ex)

    def gradient(self, x: Any, y: Any) -> tuple[np.ndarray, np.ndarray]:
        """``(∂f/∂x, ∂f/∂y)`` at points ``(x, y)``."""
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        ex, ey, dx, dy = self._factors(x, y)
        s2 = self.sigma**2
        gx = np.einsum("...b,ba,...a->...", ey, self.weights, -dx / s2 * ex)
        gy = np.einsum("...b,ba,...a->...", -dy / s2 * ey, self.weights, ex)
        return gx, gy

    def grid(self, terrain: Heightmap) -> np.ndarray:
        """The surface sampled at the cell centres of ``terrain`` (shape ``terrain.shape``)."""
        xs, ys = terrain.cell_centres()
        ex, ey, _, _ = self._factors(xs, ys)
        return ey @ self.weights @ ex.T

    # -- CasADi -------------------------------------------------------------------------------
    def casadi(self, x: Any, y: Any, weights: Any = None, origin: Any = None) -> Any:
        """The same ``f(x, y)`` as a CasADi expression (SX or MX, following ``x``/``y``).

        ``weights`` may be a symbolic vector of length ``n_bases`` (row-major over the
        ``(ny, nx)`` lattice), so a parametric NLP can swap terrains without being rebuilt;
        ``origin`` may likewise be a symbolic ``(x0, y0)`` pair for a lattice that moves.
        Without them the fitted numbers are embedded as constants.
        """
        import casadi as ca

        ny, nx = self.shape
        w = ca.DM(self.weights.reshape(-1)) if weights is None else weights
        if origin is None:
            ox, oy = self.x0, self.y0
        else:
            ox, oy = origin[0], origin[1]
        s2 = 2.0 * self.sigma**2
        ex = [ca.exp(-((x - (ox + a * self.spacing)) ** 2) / s2) for a in range(nx)]
        ey = [ca.exp(-((y - (oy + b * self.spacing)) ** 2) / s2) for b in range(ny)]
        total = 0
        for b in range(ny):
            row = 0
            for a in range(nx):
                row = row + w[b * nx + a] * ex[a]
            total = total + ey[b] * row
        return total

    def casadi_function(self, kind: str = "SX") -> Any:
        """A ``casadi.Function('f', [x, y], [f, ∇f])`` with the fitted weights embedded."""
        import casadi as ca

        sym = ca.SX if kind.upper() == "SX" else ca.MX
        x, y = sym.sym("x"), sym.sym("y")
        f = self.casadi(x, y)
        return ca.Function("f", [x, y], [f, ca.gradient(f, ca.vertcat(x, y))], ["x", "y"], ["f", "grad"])


def _basis_1d(points: np.ndarray, centres: np.ndarray, sigma: float) -> np.ndarray:
    return np.exp(-((points[:, None] - centres[None, :]) ** 2) / (2.0 * sigma**2))


def fit_rbf(
    terrain: Heightmap,
    *,
    spacing: float = 0.5,
    sigma_factor: float = 1.0,
    regularization: float = 1e-7,
    window: tuple[float, float, float, float] | None = None,
    margin: int = 1,
    solver: str = "cvxpy",
    shape: tuple[int, int] | None = None,
) -> RbfSurface:
    """Fit an :class:`RbfSurface` to ``terrain`` (or to the cells inside ``window``).

    ``spacing`` is the lattice step (m), ``sigma_factor`` the shared width in lattice steps,
    ``regularization`` λ (per cell, so it does not depend on the grid size); ``margin``
    lattice nodes are added outside the fitted region so its border is not under-supported.
    ``window = (xmin, xmax, ymin, ymax)`` fits only the cells whose centres fall inside it.
    ``shape = (ny, nx)`` fixes the lattice size (centred on the fitted cells) so that fits of
    different windows share one layout, e.g. as the parameter vector of a parametric NLP.
    ``solver="cvxpy"`` (default) solves with cvxpy; ``"cholesky"`` solves the identical
    normal equations directly (used to cross-check cvxpy in the tests).
    """
    if spacing <= 0 or sigma_factor <= 0 or regularization < 0:
        raise ScenarioError("fit_rbf needs spacing > 0, sigma_factor > 0 and regularization ≥ 0")
    t0 = time.perf_counter()
    xs, ys, z = _fitted_cells(terrain, window)
    sigma = sigma_factor * spacing
    nx, ny, x0, y0 = _lattice(xs, ys, spacing, margin, shape)
    cx = x0 + spacing * np.arange(nx)
    cy = y0 + spacing * np.arange(ny)
    ax = _basis_1d(xs, cx, sigma)  # (cells_x, nx)
    ay = _basis_1d(ys, cy, sigma)  # (cells_y, ny)
    n_cells = z.size
    gram = np.kron(ay.T @ ay, ax.T @ ax)  # row-major w = vec(W[ny, nx])
    gram[np.diag_indices_from(gram)] += regularization * n_cells
    rhs = (ay.T @ z @ ax).reshape(-1)
    import scipy.linalg  # here, not at import, so importing a planner stays cheap

    chol = scipy.linalg.cholesky(gram, lower=False)  # gram = Rᵀ R
    c = scipy.linalg.solve_triangular(chol, rhs, trans="T")
    weights, status = _least_squares(chol, c, solver)
    weights = weights.reshape(ny, nx)
    fitted = ay @ weights @ ax.T
    err = fitted - z
    return RbfSurface(
        x0=float(x0),
        y0=float(y0),
        spacing=float(spacing),
        sigma=float(sigma),
        weights=weights,
        rms=float(np.sqrt(np.mean(err**2))),
        max_error=float(np.max(np.abs(err))),
        fit_time_s=time.perf_counter() - t0,
        info={"solver": solver, "status": status, "n_cells": int(n_cells), "n_bases": int(nx * ny)},
    )


def _fitted_cells(terrain: Heightmap, window: tuple[float, float, float, float] | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cell centres (x, y) and heights :func:`fit_rbf` fits: all, or those inside ``window``."""
    xs, ys = terrain.cell_centres()
    z = terrain.z
    if window is not None:
        xmin, xmax, ymin, ymax = window
        ix = np.nonzero((xs >= xmin) & (xs <= xmax))[0]
        iy = np.nonzero((ys >= ymin) & (ys <= ymax))[0]
        if ix.size < 2 or iy.size < 2:
            raise ScenarioError(f"fit window {window} holds fewer than 2×2 cells of the terrain")
        xs, ys = xs[ix], ys[iy]
        z = z[np.ix_(iy, ix)]
    return xs, ys, z


def _lattice(xs: np.ndarray, ys: np.ndarray, spacing: float, margin: int,
             shape: tuple[int, int] | None) -> tuple[int, int, float, float]:
    """(nx, ny, x0, y0) of the basis lattice, centred on the fitted cells: ``margin`` nodes
    beyond them on every side, or the fixed ``shape = (ny, nx)``."""
    if shape is None:
        nx = int(math.ceil((xs[-1] - xs[0]) / spacing)) + 1 + 2 * margin
        ny = int(math.ceil((ys[-1] - ys[0]) / spacing)) + 1 + 2 * margin
    else:
        ny, nx = int(shape[0]), int(shape[1])
    x0 = 0.5 * (xs[0] + xs[-1]) - 0.5 * (nx - 1) * spacing
    y0 = 0.5 * (ys[0] + ys[-1]) - 0.5 * (ny - 1) * spacing
    return nx, ny, x0, y0


def _least_squares(chol: np.ndarray, c: np.ndarray, solver: str) -> tuple[np.ndarray, str]:
    """The weights w minimising ‖R w − c‖² (``chol`` = R, the Cholesky factor of the normal
    equations) with ``solver``, and its status."""
    import scipy.linalg

    if solver == "cvxpy":
        import cvxpy as cp

        w = cp.Variable(chol.shape[1])
        prob = cp.Problem(cp.Minimize(cp.sum_squares(chol @ w - c)))
        prob.solve(solver=cp.CLARABEL)
        if prob.status not in ("optimal", "optimal_inaccurate") or w.value is None:
            raise ScenarioError(f"the surface fit did not solve (cvxpy status {prob.status})")
        return np.asarray(w.value), prob.status
    if solver == "cholesky":
        return scipy.linalg.solve_triangular(chol, c), "direct"
    raise ScenarioError(f"unknown fit solver {solver!r}; use 'cvxpy' or 'cholesky'")
