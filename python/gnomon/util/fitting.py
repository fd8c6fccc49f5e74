"""Robust total-least-squares fits of lines and planes (iterative MAD rejection), and a small
Levenberg–Marquardt solver for a few parameters (a plane's pose from its markers)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["LeastSquares", "fit_line_robust", "fit_plane_robust", "fit_subspace_robust", "levenberg_marquardt"]


def fit_subspace_robust(points: np.ndarray, k: float = 3.0,
                        iterations: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Total-least-squares hyperplane of (N, D) points with iterative rejection of outliers.

    The residual of a point is its distance to the hyperplane through the
    inliers' centroid normal to their least-spread axis. Residuals beyond ``k``
    robust standard deviations (1.4826·MAD) are dropped and the fit repeated
    until the inlier set is stable (or fewer than D points would remain).
    Returns (centroid (D,), the inliers' principal axes (D, D) as rows, most
    spread first — the last row is the unit normal —, inlier mask (N,)).
    """
    dim = points.shape[1]
    mask = np.ones(len(points), dtype=bool)
    centre = points.mean(axis=0)
    axes = np.eye(dim)
    for _ in range(iterations):
        centre = points[mask].mean(axis=0)
        _, _, axes = np.linalg.svd(points[mask] - centre, full_matrices=False)
        r = (points - centre) @ axes[-1]
        scale = max(1.4826 * np.median(np.abs(r[mask])), 1e-9 * (1.0 + float(np.abs(centre).max())))
        new = np.abs(r) <= k * scale
        if new.sum() < dim or np.array_equal(new, mask):
            break
        mask = new
    return centre, axes, mask


def fit_line_robust(xy: np.ndarray, k: float = 3.0, iterations: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Robust 2-D line (see :func:`fit_subspace_robust`): (centroid, unit direction, inlier mask)."""
    centre, axes, mask = fit_subspace_robust(xy, k, iterations)
    return centre, axes[0], mask


def fit_plane_robust(points: np.ndarray, k: float = 3.0,
                     iterations: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Robust 3-D plane (see :func:`fit_subspace_robust`): (centroid, unit normal, inlier mask)."""
    centre, axes, mask = fit_subspace_robust(points, k, iterations)
    return centre, axes[-1], mask


@dataclass(frozen=True)
class LeastSquares:
    """A nonlinear least-squares solution: the parameters ``x``, the residuals ``fun`` there and their
    Jacobian ``jac`` (M, N) at ``x`` (central differences), ``iterations`` taken."""

    x: np.ndarray
    fun: np.ndarray
    jac: np.ndarray
    iterations: int


def _jacobian(fun: Callable[[np.ndarray], np.ndarray], x: np.ndarray,
              many: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
    """Central differences, steps of ε^(1/3) relative to each parameter (at least ε^(1/3)). ``many``: ``fun``
    over the (2N, N) rows x + step_i e_i, x − step_i e_i (for each i in turn) in one call, (2N, M) residuals
    each ``fun``'s for its row (the same numbers); without it ``fun`` is called row by row."""
    step = np.finfo(float).eps ** (1.0 / 3.0) * np.maximum(1.0, np.abs(x))
    rows = np.empty((2 * len(x), len(x)))
    for i in range(len(x)):
        dx = np.zeros_like(x)
        dx[i] = step[i]
        rows[2 * i], rows[2 * i + 1] = x + dx, x - dx
    r = many(rows) if many is not None else [fun(row) for row in rows]
    return np.stack([(r[2 * i] - r[2 * i + 1]) / (2.0 * step[i]) for i in range(len(x))], axis=1)


def levenberg_marquardt(fun: Callable[[np.ndarray], np.ndarray], x0: np.ndarray, *, max_iterations: int = 100,
                        xtol: float = 1e-12, ftol: float = 1e-12,
                        many: Callable[[np.ndarray], np.ndarray] | None = None) -> LeastSquares:
    """Minimise ``sum(fun(x)**2)`` from ``x0`` (N,) for residuals ``fun(x)`` (M,), M ≥ N: Levenberg–Marquardt
    with Marquardt's scaling (the damping proportional to diag(JᵀJ), so the parameters' units do not matter).

    For a handful of parameters started near the minimum (a pose refined from a closed-form one): it stops
    when a step changes no parameter by more than ``xtol`` relative or lowers the sum of squares by less
    than ``ftol`` relative, or after ``max_iterations``. A step never raises the sum of squares.

    ``many`` (optional): ``fun`` over (K, N) parameter rows at once, (K, M) residuals each exactly ``fun``'s
    for its row; the Jacobian's 2N evaluations are then one call (the same numbers, less overhead).
    """
    x = np.asarray(x0, dtype=np.float64).copy()
    r = np.asarray(fun(x), dtype=np.float64)
    cost = float(r @ r)
    jac = _jacobian(fun, x, many)
    damping = 1e-3
    iterations = 0
    while iterations < max_iterations:
        iterations += 1
        a = jac.T @ jac
        g = jac.T @ r
        scale = np.maximum(np.diag(a), 1e-300)
        while damping < 1e16:
            step = np.linalg.solve(a + damping * np.diag(scale), -g)
            r_new = np.asarray(fun(x + step), dtype=np.float64)
            cost_new = float(r_new @ r_new)
            if cost_new <= cost:
                break
            damping *= 10.0
        else:
            break  # no step lowers the sum of squares: a minimum to machine precision
        x, r, gain, cost = x + step, r_new, cost - cost_new, cost_new
        damping = max(damping / 10.0, 1e-12)
        jac = _jacobian(fun, x, many)
        if np.all(np.abs(step) <= xtol * (np.abs(x) + xtol)) or gain <= ftol * (cost + gain):
            break
    return LeastSquares(x, r, jac, iterations)
