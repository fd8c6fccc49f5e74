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

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from gnomon import _kernel
from gnomon.camera.models import CameraModel, Pose
from gnomon.util.fitting import fit_line_robust

# Crossings a frame needs for a line.
MIN_POINTS = 10
# Each frame's robust line fit (gnomon.util.fitting.fit_line_robust): outliers beyond FIT_K robust σ, at most
# FIT_ITERATIONS fits.
FIT_K = 3.0
FIT_ITERATIONS = 5

__all__ = [
    "LineMemo", "PlaneInCamera", "ReferenceLines", "ReferencePlane", "fit_line_robust", "isochrone_crossings",
    "lines_on_plane", "mask_crossings", "measure_reference_lines", "ransac_line", "region_mask",
]
# A frame's own fit sets the line's direction when its inliers span at least
# this fraction of the longest lines seen on the plane; shorter lines keep
# only their offset (their direction comes from the neighbouring frames).
MIN_EXTENT_FRACTION = 0.5
# A frame's fit is a line when its inliers extend at least this many times their RMS distance to it
# (a scatter of wrong shadow times gives ≈ 3.5).
MIN_EXTENT_TO_RMS = 20.0
# How many measured frames (at most this far away) set an extrapolated line's direction.
EXTRAPOLATION_FRAMES = 8
# Frames between two measured lines at most this far apart interpolate their direction.
MAX_INTERPOLATION_GAP = 60
# A frame's line whose inliers scatter more than this many times the plane's median line RMS is not the
# shadow's (a handful of crossings where the sweep stops, a few stray dips): real captures' lines stay
# within 4.8 times their plane's median (frog, three phone videos, a desk-lamp capture); the
# desk-lamp capture's two last frames' "lines" of 25 scattered crossings sit at 19 and 24 times.
MAX_LINE_SCATTER = 8.0


@dataclass(frozen=True)
class PlaneInCamera:
    """A plane ``n·X = d`` in the camera frame, with an in-plane basis (e1, e2)."""

    normal: np.ndarray
    offset: float
    origin: np.ndarray
    e1: np.ndarray
    e2: np.ndarray

    @classmethod
    def from_world(cls, point_world: np.ndarray, normal_world: np.ndarray, pose: Pose) -> PlaneInCamera:
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


@dataclass(frozen=True)
class ReferencePlane:
    """A bare reference plane: its name, the plane (camera frame), where the image sees it
    bare and swept (``mask``, (H, W) bool) and its rectangles ``(u0, v0, u1, v1)`` (for display)."""

    name: str
    plane: PlaneInCamera
    mask: np.ndarray
    regions: tuple[tuple[int, int, int, int], ...] = ()


@dataclass
class ReferenceLines:
    """Per-frame shadow lines on one reference plane (camera frame).

    ``point[t]`` and ``direction[t]`` (unit) define the line at frame t; rows of
    NaN mark frames without a reliable line. ``rms`` is the fit's residual RMS
    in world units, ``count`` its inliers, ``pixels[t]`` the inlier crossings
    (image pixels, for display), ``extent[t]`` the length its inliers cover
    along it (world units). ``extrapolated[t]``: the line was too short to
    set its own direction, which comes from the neighbouring frames.
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
    extent: np.ndarray | None = None  # (N,) world units covered along the line by its inliers

    @property
    def found(self) -> np.ndarray:
        return np.isfinite(self.point[:, 0])

    def speed(self, t: int) -> float:
        """How far the line at frame ``t`` moves across itself per frame (world units per frame):
        the mean distance, perpendicular to its direction, to the lines of the neighbouring frames
        that have one; 0.0 when neither has."""
        found = self.found
        d = self.direction[t]
        moves = []
        for s in (t - 1, t + 1):
            if 0 <= s < len(self.point) and found[s]:
                delta = self.point[s] - self.point[t]
                moves.append(float(np.linalg.norm(delta - (delta @ d) * d)))
        return float(np.mean(moves)) if moves else 0.0

    def speeds(self) -> np.ndarray:
        """(N,) :meth:`speed` of every frame at once (the same values; NaN at frames without a line
        that have a neighbour with one)."""
        found = self.found
        n = len(self.point)
        d = self.direction
        moves = []
        for step in (-1, 1):  # the previous frame's line, then the next one's
            has = np.zeros(n, dtype=bool)
            other = np.clip(np.arange(n) + step, 0, max(n - 1, 0))
            inside = (np.arange(n) + step >= 0) & (np.arange(n) + step < n)
            has[inside] = found[other[inside]]
            delta = self.point[other] - self.point
            along = delta[:, 0] * d[:, 0] + delta[:, 1] * d[:, 1] + delta[:, 2] * d[:, 2]  # delta @ d, row by row
            moves.append((has, np.linalg.norm(delta - along[:, None] * d, axis=1)))
        (has_a, a), (has_b, b) = moves
        with np.errstate(invalid="ignore"):
            return np.where(has_a & has_b, (a + b) / 2, np.where(has_a, a, np.where(has_b, b, 0.0)))


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


def isochrone_crossings(times: np.ndarray, n_frames: int,
                        unique: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sub-pixel points where a shadow-time patch crosses each integer frame.

    ``times``: (h, w) shadow times in frames (NaN = none) of one image region.
    Crossings are searched along the axis where the times change fastest
    (the scan direction). Returns (frame, u, v) arrays in region pixel
    coordinates, one entry per crossing. ``unique``: drop a frame's crossings
    on a row (or column) that crosses it more than once (a wrong time in one
    pixel adds a second crossing); otherwise keep them all, for a robust line
    fit to sort out.

    A float32 map goes to the kernel (``_kernel.isochrone_crossings``, lines in parallel: the
    same values in the same order); :func:`_isochrone_crossings_numpy` is the definition.
    """
    if isinstance(times, np.ndarray) and times.dtype == np.float32 and times.ndim == 2:
        return _kernel.isochrone_crossings(np.ascontiguousarray(times), int(n_frames), bool(unique))
    return _isochrone_crossings_numpy(times, n_frames, unique)


def _isochrone_crossings_numpy(times: np.ndarray, n_frames: int,
                               unique: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`isochrone_crossings` in numpy (the kernel's ``isochrone_crossings`` gives the same on float32
    maps)."""
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
    if unique:
        # A line (row or column) crossing the same frame twice is ambiguous there.
        key = rows * n_frames + frame
        _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
        single = counts[inverse] == 1
        rows, cols, frame = rows[single], cols[single], frame[single]
    ta, tb = a[rows, cols], b[rows, cols]
    along = cols + (frame - ta) / (tb - ta)
    if along_rows:
        return frame, along, rows.astype(np.float64)
    return frame, rows.astype(np.float64), along


def region_mask(
    shape: tuple[int, int],
    rectangles: Sequence[Sequence[int]] = (),
    polygons: Sequence[np.ndarray] = (),
    mask: np.ndarray | None = None,
) -> np.ndarray:
    """The union of a plane's reference regions as a boolean (H, W) image mask.

    ``rectangles``: ``[u0, v0, u1, v1]`` (pixels, ``u0 ≤ u < u1``, ``v0 ≤ v < v1``);
    ``polygons``: (K, 2) vertex arrays in pixels (a pixel belongs to a polygon
    when its centre is inside it); ``mask``: a boolean or 0/non-zero image of
    the same shape. Shapes may overlap: the regions of one plane are one set.
    """
    import cv2

    h, w = shape
    out = np.zeros((h, w), dtype=bool)
    for u0, v0, u1, v1 in rectangles:
        out[max(v0, 0):max(v1, 0), max(u0, 0):max(u1, 0)] = True
    if len(polygons):
        canvas = np.zeros((h, w), dtype=np.uint8)
        for poly in polygons:
            pts = np.round(np.asarray(poly, dtype=np.float64) * 16).astype(np.int32).reshape(-1, 1, 2)
            cv2.fillPoly(canvas, [pts], 1, lineType=cv2.LINE_8, shift=4)
        out |= canvas.astype(bool)
    if mask is not None:
        m = np.asarray(mask)
        if m.shape[:2] != (h, w):
            raise ValueError(f"region mask is {m.shape[1]}x{m.shape[0]}, the image {w}x{h}")
        out |= (m if m.ndim == 2 else m[..., 0]) != 0
    return out


def mask_crossings(times: np.ndarray, mask: np.ndarray, n_frames: int,
                   unique: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Isochrone crossings of the shadow-time map inside a region mask.

    Pixels outside ``mask`` are ignored (a crossing needs both neighbours
    inside), so holes (markers, an object) and several disjoint areas are one
    region. Returns (frame (K,), pixel (K, 2) as u, v).
    """
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))  # the mask's bounding box
    if rows.size == 0:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 2))
    v0, v1, u0, u1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    sub = np.where(mask[v0:v1, u0:u1], times[v0:v1, u0:u1], np.nan)
    f, u, v = isochrone_crossings(sub, n_frames, unique)
    return f, np.stack([u + u0, v + v0], axis=1)


def ransac_line(xy: np.ndarray, tolerance: float, trials: int = 300, seed: int = 0, candidates: int = 20) -> np.ndarray:
    """Inlier mask of the 2-D line through two of the points that covers the most length within ``tolerance``.

    For crossings of which many are not on the line (an object inside the
    region): an iterative least-squares fit starting from all of them can
    settle between the line and the object's curve, this cannot. Of the
    ``candidates`` lines with the most points within ``tolerance``, the one
    whose points cover the most length (bins of 4 × ``tolerance`` along it)
    wins: a shadow line runs across the whole plane, an object's crossings
    that happen to line up cluster on the object.
    """
    n = len(xy)
    if n < 2:
        return np.ones(n, dtype=bool)
    rng = np.random.default_rng(seed)
    a = rng.integers(0, n, trials)
    b = rng.integers(0, n, trials)
    d = xy[b] - xy[a]
    length = np.hypot(d[:, 0], d[:, 1])
    ok = length > 0
    a, d, length = a[ok], d[ok], length[ok]
    if not len(a):
        return np.ones(n, dtype=bool)
    direction = d / length[:, None]
    normal = np.stack([-direction[:, 1], direction[:, 0]], axis=1)
    counts = np.zeros(len(a), dtype=np.int64)
    for start in range(0, len(a), 50):  # (trials, n) residuals in chunks
        r = np.abs((xy[None, :, :] - xy[a[start:start + 50], None, :]) @ normal[start:start + 50, :, None])[..., 0]
        counts[start:start + 50] = (r <= tolerance).sum(axis=1)
    best, best_cover = np.ones(n, dtype=bool), -1
    for i in np.argsort(counts)[::-1][:candidates]:
        rel = xy - xy[a[i]]
        inl = np.abs(rel @ normal[i]) <= tolerance
        cover = np.unique(np.floor((rel[inl] @ direction[i]) / (4.0 * tolerance))).size
        if cover > best_cover:
            best, best_cover = inl, cover
    return best


def measure_reference_lines(
    times: np.ndarray,
    n_frames: int,
    reference: ReferencePlane,
    camera: CameraModel,
) -> ReferenceLines:
    """The shadow line on one reference plane at every integer frame.

    ``times``: (H, W) shadow-time map of the whole image (frames, NaN = none).
    The plane's regions (its ``mask``) are used together: see :func:`lines_on_plane`.
    """
    return lines_on_plane(times, n_frames, reference.plane, reference.mask, camera, reference.name)


class LineMemo:
    """The lines last measured on each plane and time map, handed back when they are asked for again.

    A scan's regions (:func:`gnomon.reconstruct.bare.off_plane`) end by measuring each plane's lines on its
    final mask, and its edges then measure the same lines on the same times: :meth:`measure` returns the
    stored :class:`ReferenceLines` when the times are the same array (identity: the caller must not write
    into it meanwhile), the plane the same object, the mask equal, the camera the same and the frames as
    many; otherwise it measures (:func:`measure_reference_lines`) and stores. One entry per (times, plane
    name): threads measuring different planes or times may share it."""

    def __init__(self) -> None:
        self._lines: dict[tuple[int, str], tuple[np.ndarray, PlaneInCamera, np.ndarray, CameraModel, int,
                                                 ReferenceLines]] = {}

    def measure(self, times: np.ndarray, n_frames: int, reference: ReferencePlane,
                camera: CameraModel) -> ReferenceLines:
        key = (id(times), reference.name)
        known = self._lines.get(key)
        if known is not None:
            k_times, k_plane, k_mask, k_camera, k_frames, lines = known
            if (k_times is times and k_plane is reference.plane and k_camera is camera and k_frames == n_frames
                    and np.array_equal(k_mask, reference.mask)):
                return lines
        lines = measure_reference_lines(times, n_frames, reference, camera)
        self._lines[key] = (times, reference.plane, reference.mask.copy(), camera, n_frames, lines)
        return lines


def along_extent(along: np.ndarray) -> float:
    """Length covered by points along a line (5th to 95th percentile, stretched to the full range)."""
    if along.size < 2:
        return 0.0
    lo, hi = np.percentile(along, [5.0, 95.0])
    return float(hi - lo) / 0.9


def lines_on_plane(
    times: np.ndarray,
    n_frames: int,
    plane: PlaneInCamera,
    mask: np.ndarray,
    camera: CameraModel,
    name: str = "plane",
    min_extent_fraction: float = MIN_EXTENT_FRACTION,
    ransac_tolerance: float | None = None,
    *,
    kernel: bool = True,
    max_scatter: float | None = MAX_LINE_SCATTER,
) -> ReferenceLines:
    """The shadow line on one reference plane at every integer frame, from all its regions at once.

    ``times``: (H, W) shadow times (frames, NaN = none); ``mask``: (H, W) bool,
    the bare parts of the plane (any shape, holes allowed); ``plane`` in the
    camera frame. Every crossing of frame t inside the mask is back-projected
    onto the plane and one robust line is fitted to them all. The fit sets the
    line's direction when its inliers cover at least ``min_extent_fraction``
    of the longest line seen on this plane (the 90th percentile of the
    frames' extents, world units along the line); a shorter line (at the ends
    of the sweep, or mostly hidden) keeps only its offset, with the direction
    interpolated from the measured frames (or extrapolated from the nearest
    few at the ends). A frame's own fit counts only when it is a line, not
    a scatter: its inliers' extent at least ``MIN_EXTENT_TO_RMS`` times their
    RMS distance to it. ``ransac_tolerance`` (world units): start each frame's
    fit from the RANSAC line (:func:`ransac_line`), for masks that may hold
    much besides the bare plane (a first guess at the regions).

    A frame's line whose residual RMS exceeds ``max_scatter`` times the median of the plane's lines is
    dropped (before the short lines take their direction from their neighbours, and again after):
    :data:`MAX_LINE_SCATTER`; None keeps every fit.

    Without RANSAC the frames' own fits are the kernel's (``_kernel.frame_lines``, frames in
    parallel; the same fits up to round-off, the first line's sense taken from
    :func:`~gnomon.util.fitting.fit_line_robust`); ``kernel=False`` fits them in numpy, one frame after
    the other (the definition).
    """
    frame, pix = mask_crossings(times, mask, n_frames)

    point = np.full((n_frames, 3), np.nan)
    direction = np.full((n_frames, 3), np.nan)
    rms = np.full(n_frames, np.nan)
    count = np.zeros(n_frames, dtype=np.int64)
    pixels: list[np.ndarray] = [np.zeros((0, 2)) for _ in range(n_frames)]
    extrapolated = np.zeros(n_frames, dtype=bool)
    points3d: list[np.ndarray] = [np.zeros((0, 3)) for _ in range(n_frames)]
    extent = np.zeros(n_frames)
    if len(frame) == 0:
        return ReferenceLines(name, plane, point, direction, rms, count, pixels, extrapolated, points3d, extent)

    on_plane = plane.intersect(camera.rays(pix))
    good = np.isfinite(on_plane[:, 0])
    frame, pix, on_plane = frame[good], pix[good], on_plane[good]
    xy = plane.to_plane_coords(on_plane)

    order = np.argsort(frame, kind="stable")
    bounds = np.searchsorted(frame[order], np.arange(n_frames + 1))
    per_frame = [order[bounds[t]:bounds[t + 1]] for t in range(n_frames)]

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
        extent[t] = along_extent(xy[idx][inl] @ d2)

    angle = np.full(n_frames, np.nan)  # line direction in plane coordinates
    if ransac_tolerance is None and kernel:
        # Every frame's own fit, and which of them set the direction (their extent against the
        # longest lines of the plane), per frame in the kernel (frames in parallel).
        accepted, centres, dirs, fit_rms, fit_count, fit_extent, inliers = _kernel.frame_lines(
            np.ascontiguousarray(xy[order]), bounds.astype(np.int64), FIT_K, FIT_ITERATIONS, MIN_POINTS,
            MIN_EXTENT_TO_RMS, min_extent_fraction)
        lines = np.flatnonzero(accepted)
        if lines.size:
            # The kernel's axes take a sense of their own; the first line keeps the one
            # fit_line_robust gives it (the others follow it).
            first = per_frame[lines[0]]
            if float(fit_line_robust(xy[first], FIT_K, FIT_ITERATIONS)[1] @ dirs[lines[0]]) < 0:
                dirs = -dirs
            point[lines] = plane.from_plane_coords(centres[lines])
            d3 = dirs[lines, :1] * plane.e1 + dirs[lines, 1:2] * plane.e2
            direction[lines] = [d / np.linalg.norm(d) for d in d3]
            rms[lines], count[lines], extent[lines] = fit_rms[lines], fit_count[lines], fit_extent[lines]
            angle[lines] = np.arctan2(dirs[lines, 1], dirs[lines, 0])
            pix_sorted, on_sorted = pix[order], on_plane[order]
            for f in lines.tolist():
                part = slice(bounds[f], bounds[f + 1])
                sel = pix_sorted[part][inliers[part]]
                pixels[f] = sel[np.argsort(sel[:, 1])]
                points3d[f] = on_sorted[part][inliers[part]]
    else:
        _own_lines_numpy(xy, per_frame, ransac_tolerance, min_extent_fraction, angle, keep)

    def drop_scattered() -> None:  # lines far more scattered than the plane's own: not the shadow's
        found = np.isfinite(rms) & np.isfinite(point[:, 0])
        if max_scatter is None or found.sum() < 3:
            return
        typical = float(np.median(rms[found]))
        for t in np.flatnonzero(found & (rms > max_scatter * typical)).tolist():
            point[t], direction[t], rms[t], count[t], extent[t], angle[t] = np.nan, np.nan, np.nan, 0, 0.0, np.nan
            pixels[t], extrapolated[t] = np.zeros((0, 2)), False

    drop_scattered()
    if not np.isfinite(angle).any():
        return ReferenceLines(name, plane, point, direction, rms, count, pixels, extrapolated, points3d, extent)

    # A short line's direction is poorly measured. It changes slowly with
    # time, so take it from the measured frames — interpolated between the
    # nearest ones on either side, or extrapolated linearly from the nearest
    # few at the ends — and fit only the line's offset.
    measured = np.flatnonzero(np.isfinite(angle))
    if len(measured) >= 3:
        unwrapped = np.unwrap(angle[measured])
        for t, idx in enumerate(per_frame):
            if np.isfinite(angle[t]) or len(idx) < MIN_POINTS:
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
            if inl.sum() < MIN_POINTS:
                continue
            along = xy[idx][inl] @ d2
            centre = np.mean(offsets[inl]) * normal2 + np.mean(along) * d2
            keep(t, idx, centre, d2, inl)
            extrapolated[t] = True
    drop_scattered()
    for t, idx in enumerate(per_frame):
        if not np.isfinite(point[t, 0]) and len(idx):
            points3d[t] = on_plane[idx]
    return ReferenceLines(name, plane, point, direction, rms, count, pixels, extrapolated, points3d, extent)


def _own_lines_numpy(xy: np.ndarray, per_frame: list[np.ndarray], ransac_tolerance: float | None,
                     min_extent_fraction: float, angle: np.ndarray, keep: Callable[..., None]) -> None:
    """:func:`lines_on_plane`'s own fits of the frames in numpy, with ``ransac_tolerance`` each started
    from its RANSAC line: the lines that set their direction are handed to ``keep`` and their angles
    written into ``angle`` (the kernel's ``frame_lines`` fits the same without RANSAC)."""
    # Every frame's own fit first; which of them set the direction is decided
    # by their extent against the longest lines of the plane.
    fits: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray, float]] = {}
    for t, idx in enumerate(per_frame):
        if len(idx) < MIN_POINTS:
            continue
        if ransac_tolerance is not None:
            first = ransac_line(xy[idx], ransac_tolerance)
            if first.sum() < MIN_POINTS:
                continue
            centre, d2, sub = fit_line_robust(xy[idx][first], FIT_K, FIT_ITERATIONS)
            inl = np.zeros(len(idx), dtype=bool)
            inl[np.flatnonzero(first)[sub]] = True
        else:
            centre, d2, inl = fit_line_robust(xy[idx], FIT_K, FIT_ITERATIONS)
        if inl.sum() < MIN_POINTS:
            continue
        ext = along_extent(xy[idx][inl] @ d2)
        spread = float(np.sqrt(np.mean(((xy[idx][inl] - centre) @ np.array([-d2[1], d2[0]])) ** 2)))
        if ext < MIN_EXTENT_TO_RMS * spread:
            continue
        fits[t] = (centre, d2, inl, ext)
    if not fits:
        return
    longest = float(np.percentile([f[3] for f in fits.values()], 90))
    for t in sorted(fits):
        centre, d2, inl, ext = fits[t]
        if ext < min_extent_fraction * longest:
            continue
        previous = angle[np.isfinite(angle)]
        if previous.size and np.cos(np.arctan2(d2[1], d2[0]) - previous[-1]) < 0:
            d2 = -d2  # keep a consistent sense, so angles can be interpolated
        angle[t] = np.arctan2(d2[1], d2[0])
        keep(t, per_frame[t], centre, d2, inl)
