"""Triangulation: each pixel's camera ray against the shadow plane at its shadow time.

The per-pixel work is the kernel's (``gnomon._kernel.triangulate``); this
module prepares its inputs and turns its output into depth and world points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gnomon import _kernel

# Rays within ~0.06° of grazing a shadow plane are dropped: depth error there
# grows like 1/(n·r) and such points are noise, not surface.
MIN_RAY_PLANE_COS = 1e-3


@dataclass
class Triangulation:
    """Result of triangulating a shadow-time map.

    ``points_cam`` (H, W, 3) float32 camera frame and ``depth`` (H, W) float32
    camera Z, both in world units with NaN where no point; ``valid`` (H, W) bool.
    """

    points_cam: np.ndarray
    depth: np.ndarray
    valid: np.ndarray


def triangulate(ray_map: np.ndarray, times: np.ndarray, planes: np.ndarray) -> Triangulation:
    """Intersect every pixel's ray with Π(ts), Π interpolated between integer frames.

    ``ray_map`` (H, W, 3) unit camera rays; ``times`` (H, W) frames (NaN = none);
    ``planes`` (N, 4) camera-frame ``[n, d]`` rows (NaN = no plane).
    """
    points, valid = _kernel.triangulate(
        np.ascontiguousarray(ray_map, dtype=np.float64),
        np.ascontiguousarray(times, dtype=np.float32),
        np.ascontiguousarray(planes, dtype=np.float64),
        MIN_RAY_PLANE_COS,
    )
    depth = np.where(valid, points[..., 2], np.nan).astype(np.float32)
    return Triangulation(points, depth, valid)


def triangulate_depth(ray_map: np.ndarray, times: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """``triangulate(ray_map, times, planes).depth`` (H, W) float32 camera Z, NaN = none, without the points:
    the kernel's ``triangulate_depth`` (the same intersections)."""
    return _kernel.triangulate_depth(
        np.ascontiguousarray(ray_map, dtype=np.float64),
        np.ascontiguousarray(times, dtype=np.float32),
        np.ascontiguousarray(planes, dtype=np.float64),
        MIN_RAY_PLANE_COS,
    )


NEIGHBOURS_8 = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))


def shifted(a: np.ndarray, dv: int, du: int, fill) -> np.ndarray:
    """``out[v, u] = a[v + dv, u + du]``, ``fill`` outside the image."""
    out = np.full_like(a, fill)
    h, w = a.shape[:2]
    out[max(0, -dv):h - max(0, dv), max(0, -du):w - max(0, du)] = \
        a[max(0, dv):h - max(0, -dv), max(0, du):w - max(0, -du)]
    return out


def supported_by_neighbours(depth: np.ndarray, max_relative_jump: float, min_support: int = 2) -> np.ndarray:
    """Mask of pixels with at least ``min_support`` of 8 neighbours at a similar depth.

    Similar: ``|Z − Z_n| ≤ max_relative_jump · Z``. An isolated wrong shadow
    time (a mixed pixel at an occlusion boundary, a glint) gives a depth that
    no neighbour shares; a real surface, even beside a depth step, has
    neighbours on its own side.
    """
    valid = np.isfinite(depth)
    support = np.zeros(depth.shape, dtype=np.int8)
    with np.errstate(invalid="ignore"):
        for dv, du in NEIGHBOURS_8:
            other = shifted(depth, dv, du, np.nan)
            support += np.abs(depth - other) <= max_relative_jump * np.abs(depth)
    return valid & (support >= min_support)
