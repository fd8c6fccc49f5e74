"""Shadow lines on the reference planes, one per frame.

Bouguet & Perona find, in each frame, the image points of a bare reference
plane where ``I − Ishadow`` changes sign along the scan direction, and fit a
line through them. That zero set is exactly the *isochrone* ``ts(x) = t`` of
the per-pixel shadow time: a pixel of the reference region is on the shadow
edge at frame t precisely when its shadow time equals t. Gnomon therefore
measures the reference lines on the shadow-time map after the streaming pass
(design note in the README):

* the threshold is each pixel's final ``(Imax + Imin)/2`` in irradiance, the
  same one that defines the shadow times of the scene, so any bias of the edge
  detector (penumbra shape, encoding) is common to both and cancels;
* memory stays O(pixels): no frames are kept for a second pass.

Crossings are located at sub-pixel precision along every row (or column) of
each region, back-projected through the camera model onto the reference plane
(so lens distortion is handled exactly: the line is straight on the plane,
not in the image), and fitted per frame with a robust total-least-squares
line in plane coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gnomon.camera import CameraModel, Pose
from gnomon.fieldlog import PlaneSpec

MIN_POINTS_PER_REGION = 5
# How many measured frames (at most this far away) set an extrapolated line's direction.
EXTRAPOLATION_FRAMES = 8
# Frames between two measured lines at most this far apart interpolate their direction.
MAX_INTERPOLATION_GAP = 60


@dataclass(frozen=True)
class PlaneInCamera:
    """A plane ``n·X = d`` in the camera frame, with an in-plane basis (e1, e2)."""

    normal: np.ndarray
    offset: float
    origin: np.ndarray
    e1: np.ndarray
    e2: np.ndarray

    @classmethod
    def from_world(cls, point_world: np.ndarray, normal_world: np.ndarray, pose: Pose) -> "PlaneInCamera":
        n = pose.R @ (normal_world / np.linalg.norm(normal_world))
        o = pose.world_to_camera(point_world)
        helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        e1 = np.cross(n, helper)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(n, e1)
        return cls(n, float(n @ o), o, e1, e2)

    def intersect(self, rays: np.ndarray) -> np.ndarray:
        """Camera rays (N, 3) → their points on the plane (N, 3), NaN when parallel or behind."""
        denom = rays @ self.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            s = self.offset / denom
        s[(np.abs(denom) < 1e-9) | (s <= 0)] = np.nan
        return rays * s[:, None]

    def to_plane_coords(self, points: np.ndarray) -> np.ndarray:
        rel = points - self.origin
        return np.stack([rel @ self.e1, rel @ self.e2], axis=1)

    def from_plane_coords(self, xy: np.ndarray) -> np.ndarray:
        return self.origin + xy[..., :1] * self.e1 + xy[..., 1:2] * self.e2


@dataclass
class ReferenceLines:
    """Per-frame shadow lines on one reference plane (camera frame).

    ``point[t]`` and ``direction[t]`` (unit) define the line at frame t; rows of
    NaN mark frames without a reliable line. ``rms`` is the fit's residual RMS
    in world units, ``count`` its inliers, ``pixels[t]`` the inlier crossings
    (image pixels, for display). ``extrapolated[t]``: the line was seen in one
    region only, so its direction comes from the neighbouring frames.
    """

    plane_name: str
    plane: PlaneInCamera
    point: np.ndarray  # (N, 3)
    direction: np.ndarray  # (N, 3)
    rms: np.ndarray  # (N,)
    count: np.ndarray  # (N,) int
    pixels: list[np.ndarray]
    extrapolated: np.ndarray  # (N,) bool: direction taken from neighbouring frames
    points: list[np.ndarray]  # per frame (K, 3) camera-frame crossings: the line's inliers, or all

    @property
    def found(self) -> np.ndarray:
        return np.isfinite(self.point[:, 0])


def _typical_step(times: np.ndarray, axis: int) -> float:
    """Median non-zero change of the shadow time between neighbours along ``axis``.

    Zero steps are left out: a sharp edge sampled by few frames gives plateaus
    of equal times, and the sweep's direction shows only in the steps between them.
    """
    if times.shape[axis] < 2:
        return 0.0
    d = np.diff(times, axis=axis)
    d = d[np.isfinite(d) & (d != 0)]
    return float(np.median(d)) if d.size else 0.0


def isochrone_crossings(times: np.ndarray, n_frames: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sub-pixel points where a shadow-time patch crosses each integer frame.

    ``times``: (h, w) shadow times in frames (NaN = none) of one image region.
    Crossings are searched along the axis where the times change fastest
    (the scan direction). Returns (frame, u, v) arrays in region pixel
    coordinates, one entry per crossing.
    """
    if times.size == 0:
        empty = np.zeros(0)
        return empty.astype(np.int64), empty, empty
    du, dv = _typical_step(times, axis=1), _typical_step(times, axis=0)
    along_rows = not (abs(dv) > abs(du))
    direction = np.sign(du if along_rows else dv)
    t = times if along_rows else times.T
    a, b = t[:, :-1], t[:, 1:]
    # Only crossings in the sweep's own direction: a wrong shadow time in a
    # single pixel makes a spike, whose two flanks cross in opposite senses.
    ok = np.isfinite(a) & np.isfinite(b) & ((b - a) * direction > 0)
    lo = np.where(ok, np.minimum(a, b), 0.0)
    hi = np.where(ok, np.maximum(a, b), -1.0)
    # Each pair owns the integer frames in [lo, hi), so a crossing that falls
    # exactly on a pixel centre is counted once.
    first = np.maximum(np.ceil(lo).astype(np.int64), 0)
    last = np.minimum(np.ceil(hi).astype(np.int64) - 1, n_frames - 1)
    n = np.where(ok, np.maximum(last - first + 1, 0), 0)
    rows, cols = np.nonzero(n)
    if rows.size == 0:
        empty = np.zeros(0)
        return empty.astype(np.int64), empty, empty
    reps = n[rows, cols]
    rows = np.repeat(rows, reps)
    cols = np.repeat(cols, reps)
    offsets = np.arange(reps.sum()) - np.repeat(np.cumsum(reps) - reps, reps)
    frame = first[rows, cols] + offsets
    # A line (row or column) crossing the same frame twice is ambiguous there.
    key = rows * n_frames + frame
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    unique = counts[inverse] == 1
    rows, cols, frame = rows[unique], cols[unique], frame[unique]
    ta, tb = a[rows, cols], b[rows, cols]
    along = cols + (frame - ta) / (tb - ta)
    if along_rows:
        return frame, along, rows.astype(np.float64)
    return frame, rows.astype(np.float64), along


def fit_line_robust(xy: np.ndarray, k: float = 3.0, iterations: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Total-least-squares 2-D line with iterative rejection of outliers.

    Residuals beyond ``k`` robust standard deviations (1.4826·MAD) are dropped
    and the line refitted until the inlier set is stable. Returns
    (centroid, unit direction, inlier mask).
    """
    mask = np.ones(len(xy), dtype=bool)
    centre = xy.mean(axis=0)
    direction = np.array([1.0, 0.0])
    for _ in range(iterations):
        pts = xy[mask]
        centre = pts.mean(axis=0)
        _, _, vt = np.linalg.svd(pts - centre, full_matrices=False)
        direction, normal = vt[0], vt[1]
        r = (xy - centre) @ normal
        sigma = 1.4826 * np.median(np.abs(r[mask]))
        scale = max(sigma, 1e-9 * (1.0 + float(np.abs(centre).max())))
        new_mask = np.abs(r) <= k * scale
        if new_mask.sum() < 2 or np.array_equal(new_mask, mask):
            break
        mask = new_mask
    return centre, direction, mask


def measure_reference_lines(
    times: np.ndarray,
    n_frames: int,
    plane_spec: PlaneSpec,
    camera: CameraModel,
    pose: Pose,
) -> ReferenceLines:
    """The shadow line on one reference plane at every integer frame.

    ``times``: (H, W) shadow-time map of the whole image (frames, NaN = none).
    A frame's line is kept when at least ``MIN_POINTS_PER_REGION`` inlier
    crossings lie in each of two regions (or in the only region).
    """
    plane = PlaneInCamera.from_world(plane_spec.point, plane_spec.normal, pose)
    frames, us, vs, region_ids = [], [], [], []
    for rid, (u0, v0, u1, v1) in enumerate(plane_spec.regions):
        f, u, v = isochrone_crossings(times[v0:v1, u0:u1], n_frames)
        frames.append(f)
        us.append(u + u0)
        vs.append(v + v0)
        region_ids.append(np.full(len(f), rid))
    frame = np.concatenate(frames)
    pix = np.stack([np.concatenate(us), np.concatenate(vs)], axis=1)
    region = np.concatenate(region_ids)

    point = np.full((n_frames, 3), np.nan)
    direction = np.full((n_frames, 3), np.nan)
    rms = np.full(n_frames, np.nan)
    count = np.zeros(n_frames, dtype=np.int64)
    pixels: list[np.ndarray] = [np.zeros((0, 2)) for _ in range(n_frames)]
    extrapolated = np.zeros(n_frames, dtype=bool)
    points3d: list[np.ndarray] = [np.zeros((0, 3)) for _ in range(n_frames)]
    if len(frame) == 0:
        return ReferenceLines(plane_spec.name, plane, point, direction, rms, count, pixels, extrapolated, points3d)

    on_plane = plane.intersect(camera.rays(pix))
    good = np.isfinite(on_plane[:, 0])
    frame, pix, region, on_plane = frame[good], pix[good], region[good], on_plane[good]
    xy = plane.to_plane_coords(on_plane)

    regions_needed = min(2, len(plane_spec.regions))
    order = np.argsort(frame, kind="stable")
    bounds = np.searchsorted(frame[order], np.arange(n_frames + 1))
    per_frame = [order[bounds[t]:bounds[t + 1]] for t in range(n_frames)]
    angle = np.full(n_frames, np.nan)  # line direction in plane coordinates

    def keep(t: int, idx: np.ndarray, centre: np.ndarray, d2: np.ndarray, inl: np.ndarray) -> None:
        normal2 = np.array([-d2[1], d2[0]])
        res = (xy[idx][inl] - centre) @ normal2
        d3 = d2[0] * plane.e1 + d2[1] * plane.e2
        point[t], direction[t] = plane.from_plane_coords(centre), d3 / np.linalg.norm(d3)
        rms[t] = float(np.sqrt(np.mean(res**2)))
        count[t] = int(inl.sum())
        sel = pix[idx][inl]
        pixels[t] = sel[np.argsort(sel[:, 1])]
        points3d[t] = on_plane[idx][inl]

    for t, idx in enumerate(per_frame):
        if len(idx) < MIN_POINTS_PER_REGION * regions_needed:
            continue
        centre, d2, inl = fit_line_robust(xy[idx])
        per_region = np.bincount(region[idx][inl], minlength=len(plane_spec.regions))
        if np.count_nonzero(per_region >= MIN_POINTS_PER_REGION) < regions_needed:
            continue
        if angle[np.isfinite(angle)].size and np.cos(np.arctan2(d2[1], d2[0]) - angle[np.isfinite(angle)][-1]) < 0:
            d2 = -d2  # keep a consistent sense, so angles can be extrapolated
        angle[t] = np.arctan2(d2[1], d2[0])
        keep(t, idx, centre, d2, inl)

    # When the line crosses only one region (at the ends of the sweep, or
    # where regions leave a gap) its direction is not measured well. It changes
    # slowly with time, so take it from the measured frames — interpolated
    # between the nearest ones on either side, or extrapolated linearly from
    # the nearest few at the ends — and fit only the line's offset.
    measured = np.flatnonzero(np.isfinite(angle))
    if len(measured) >= 3 and regions_needed == 2:
        unwrapped = np.unwrap(angle[measured])
        for t, idx in enumerate(per_frame):
            if np.isfinite(angle[t]) or len(idx) < 2 * MIN_POINTS_PER_REGION:
                continue
            before, after = measured[measured < t], measured[measured > t]
            if len(before) and len(after) and after[0] - before[-1] <= MAX_INTERPOLATION_GAP:
                theta = float(np.interp(t, measured, unwrapped))
            else:
                near = np.argsort(np.abs(measured - t))[:EXTRAPOLATION_FRAMES]
                if np.min(np.abs(measured[near] - t)) > EXTRAPOLATION_FRAMES:
                    continue
                slope, intercept = np.polyfit(measured[near], unwrapped[near], 1)
                theta = slope * t + intercept
            d2 = np.array([np.cos(theta), np.sin(theta)])
            normal2 = np.array([-d2[1], d2[0]])
            offsets = xy[idx] @ normal2
            med = np.median(offsets)
            mad = 1.4826 * np.median(np.abs(offsets - med))
            inl = np.abs(offsets - med) <= 3.0 * max(mad, 1e-9 * (1.0 + abs(med)))
            if inl.sum() < 2 * MIN_POINTS_PER_REGION:
                continue
            along = xy[idx][inl] @ d2
            centre = np.mean(offsets[inl]) * normal2 + np.mean(along) * d2
            keep(t, idx, centre, d2, inl)
            extrapolated[t] = True
    for t, idx in enumerate(per_frame):
        if not np.isfinite(point[t, 0]) and len(idx):
            points3d[t] = on_plane[idx]
    return ReferenceLines(plane_spec.name, plane, point, direction, rms, count, pixels, extrapolated, points3d)
