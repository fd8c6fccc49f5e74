"""Where a reference plane's own shadow lines put each pixel's shadow time, and which pixels follow them.

A pixel of a bare reference plane has the shadow time its plane's lines predict: the line of frame t
passes through the pixel's point on the plane exactly when its shadow time is t.
:func:`predicted_times` interpolates that time between the lines that sweep the plane
(:func:`monotone_sweep`); :func:`off_plane_pieces` finds the pixels of a region that do not follow it on
an edge (an object, its cast shadow, another surface), which ``gnomon regions``
(:mod:`gnomon.runs.regions`) leaves out of its proposals and a scan out of its lines
(:mod:`gnomon.reconstruct.regions`). Camera frame, frames of the tracker.
"""

from __future__ import annotations

import cv2
import numpy as np

from gnomon import _kernel
from gnomon.geometry.reference_lines import PlaneInCamera, ReferenceLines

__all__ = ["MAX_SPEED_RATIO", "monotone_sweep", "off_plane_pieces", "plane_points", "predicted_times",
           "times_at_points"]

# A plane's lines are one sweep where consecutive lines move less than this times their median speed (per frame).
MAX_SPEED_RATIO = 8.0


def monotone_sweep(frames: np.ndarray, centres: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Which of a plane's lines sweep it monotonically and smoothly: the longest such run (bool mask).

    ``frames`` (N,) increasing frame of each line, ``centres`` (N, 2) a point
    of it and ``normals`` (N, 2) its unit normal, plane coordinates;
    ``normals`` is turned in place so that every normal points the way the
    lines move. Each line's position is its signed distance past the lines'
    mean centre; the sweep's sense is the sign of the median step between
    consecutive lines. The lines kept are the longest strictly increasing
    subsequence of positions, cut where it jumps by more than
    ``MAX_SPEED_RATIO`` times the median speed (per frame), of which the
    longest piece. A wrong line (an object's isochrone, a surface off the
    plane, behind, beyond or far ahead of the sweep) is left out instead of
    turning the sense or breaking the bracketing of every point.
    """
    n = len(centres)
    keep = np.zeros(n, dtype=bool)
    if n == 0:
        return keep
    normals *= np.where(normals @ normals[n // 2] < 0, -1.0, 1.0)[:, None]
    pos = np.einsum("ij,ij->i", centres - centres.mean(axis=0), normals)
    if n > 1 and np.median(np.diff(pos)) < 0:
        normals *= -1.0
        pos = -pos
    # Longest strictly increasing subsequence (patience sorting, O(n log n)).
    tails: list[int] = []
    parent = np.full(n, -1)
    for i in range(n):
        j = int(np.searchsorted(pos[tails], pos[i], side="left")) if tails else 0
        if j > 0:
            parent[i] = tails[j - 1]
        if j == len(tails):
            tails.append(i)
        else:
            tails[j] = i
    run = []
    i = tails[-1]
    while i >= 0:
        run.append(i)
        i = int(parent[i])
    idx = np.array(run[::-1])
    if len(idx) > 2:
        speed = np.diff(pos[idx]) / np.diff(np.asarray(frames, dtype=np.float64)[idx])
        cut = np.flatnonzero(speed > MAX_SPEED_RATIO * np.median(speed)) + 1
        pieces = np.split(idx, cut)
        idx = max(pieces, key=len)
    keep[idx] = True
    return keep


def predicted_times(lines: ReferenceLines, ray_map: np.ndarray) -> np.ndarray:
    """(H, W) the frame (sub-frame) at which the plane's shadow line passes each pixel's point.

    Only the lines that sweep the plane monotonically are used (the longest
    such run, :func:`monotone_sweep`). The pair of consecutive frames with a line whose lines
    bracket the point is found by bisection, and the point's signed distances
    to them interpolated linearly; pixels the lines never pass (or whose ray
    misses the plane) are NaN. :func:`plane_points` and :func:`times_at_points` are its two halves,
    for a caller that predicts several edges' times at the same pixels.
    """
    h, w = ray_map.shape[:2]
    out = np.full(h * w, np.nan)
    if np.count_nonzero(lines.found) < 2:
        return out.reshape(h, w)
    ok, xy = plane_points(lines.plane, ray_map)
    out[ok] = times_at_points(lines, xy)
    return out.reshape(h, w)


def plane_points(plane: PlaneInCamera, ray_map: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the rays ``ray_map`` (..., 3) (camera frame) meet ``plane``: the flat indices of the rays
    that meet it (in front of the camera) and their points in the plane's coordinates (K, 2)."""
    pts = plane.intersect(np.asarray(ray_map.reshape(-1, 3), dtype=np.float64))  # read only: no copy needed
    ok = np.flatnonzero(np.isfinite(pts[:, 0]))
    return ok, plane.to_plane_coords(pts[ok])


def times_at_points(lines: ReferenceLines, xy: np.ndarray, *, kernel: bool = True) -> np.ndarray:
    """(K,) :func:`predicted_times` at the points ``xy`` (K, 2) of the lines' plane (its coordinates,
    :func:`plane_points`): frames, NaN where the lines do not bracket the point.

    The bisection runs in the kernel (``_kernel.line_times``, points in parallel; element for element
    :func:`_times_at_points_numpy`, the definition, which ``kernel=False`` runs)."""
    plane = lines.plane
    found = np.flatnonzero(lines.found)
    if len(found) < 2:
        return np.full(len(xy), np.nan)
    centres = plane.to_plane_coords(lines.point[found])
    d3 = lines.direction[found]
    d2 = np.stack([d3 @ plane.e1, d3 @ plane.e2], axis=1)
    normals = np.stack([-d2[:, 1], d2[:, 0]], axis=1)
    keep = monotone_sweep(found, centres, normals)
    found, centres, normals = found[keep], centres[keep], normals[keep]
    if len(found) < 2:
        return np.full(len(xy), np.nan)
    offsets = np.einsum("ij,ij->i", centres, normals)
    steps = int(np.ceil(np.log2(len(found)))) + 1  # halve [0, N − 1] down to one pair
    if kernel:
        return _kernel.line_times(np.ascontiguousarray(xy, dtype=np.float64),
                                  np.ascontiguousarray(np.column_stack([normals, offsets])), found.astype(np.int64),
                                  steps)
    return _times_at_points_numpy(xy, normals, offsets, found, steps)


def _times_at_points_numpy(xy: np.ndarray, normals: np.ndarray, offsets: np.ndarray, found: np.ndarray,
                           steps: int) -> np.ndarray:
    """:func:`times_at_points`' bisection in numpy over the points between the first and the last line:
    ``normals`` (N, 2) and ``offsets`` (N,) the lines (signed distance ``x·n_x + y·n_y − offset``, > 0
    ahead of the line), ``found`` (N,) their frames, ``steps`` bisection steps."""
    out = np.full(len(xy), np.nan)
    nx, ny = np.ascontiguousarray(normals[:, 0]), np.ascontiguousarray(normals[:, 1])
    x, y = np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1])
    last = len(found) - 1

    def signed(k: np.ndarray | int) -> np.ndarray:  # > 0: the point is ahead of line k (not yet reached)
        return x * nx[k] + y * ny[k] - offsets[k]

    inside = np.flatnonzero((signed(0) > 0) & (signed(last) <= 0))  # ahead of the first line, passed by the last
    x, y = x[inside], y[inside]
    lo = np.zeros(len(inside), dtype=np.intp)
    hi = np.full(len(inside), last, dtype=np.intp)
    for _ in range(steps):
        mid = (lo + hi) // 2
        ahead = signed(mid) > 0
        lo = np.where(ahead, mid, lo)
        hi = np.where(ahead, hi, mid)
    s_lo, s_hi = signed(lo), signed(hi)
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = s_lo / (s_lo - s_hi)
    t = found[lo] + (found[hi] - found[lo]) * frac
    good = (hi == lo + 1) & np.isfinite(t)
    out[inside[good]] = t[good]
    return out


def off_plane_pieces(residual: np.ndarray, region: np.ndarray, tolerance: float,
                     min_area_px: int) -> tuple[np.ndarray, list[tuple[int, tuple[int, int, int, int]]]]:
    """The pieces of ``region`` (H, W) bool whose pixels do not follow their plane: ``residual`` (H, W) the
    worse of the edges' |measured − predicted| shadow time (frames, NaN where either is missing, not
    judged) above ``tolerance``, closed over small gaps (3 × 3) and kept where a connected piece has at
    least ``min_area_px`` pixels (scattered noisy pixels are no surface). Returns the pieces' mask and,
    largest first, (area px, bounding box (u0, v0, u1, v1)) of each."""
    with np.errstate(invalid="ignore"):
        off = (region & (residual > tolerance)).astype(np.uint8)
    off = cv2.morphologyEx(off, cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8)) & region.astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(off, connectivity=8)
    keep = np.zeros(n, dtype=bool)
    keep[1:] = stats[1:, cv2.CC_STAT_AREA] >= min_area_px
    pieces = sorted(((int(stats[k, cv2.CC_STAT_AREA]),
                      (int(stats[k, cv2.CC_STAT_LEFT]), int(stats[k, cv2.CC_STAT_TOP]),
                       int(stats[k, cv2.CC_STAT_LEFT] + stats[k, cv2.CC_STAT_WIDTH]),
                       int(stats[k, cv2.CC_STAT_TOP] + stats[k, cv2.CC_STAT_HEIGHT])))
                     for k in np.flatnonzero(keep)), reverse=True)
    return keep[labels], pieces
