"""Robust total-least-squares fits of lines and planes (iterative MAD rejection)."""

from __future__ import annotations

import numpy as np

__all__ = ["fit_line_robust", "fit_plane_robust", "fit_subspace_robust"]


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
