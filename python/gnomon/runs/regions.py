"""Proposing each reference plane's bare, swept areas from a first pass.

A pixel of a bare reference plane has a shadow time that the plane's own
shadow lines predict: on the plane, the line of frame t passes through the
pixel's point exactly when its shadow time is t. A pixel of an object, of its
cast shadow, of a marker (too little contrast), of another plane or of a
surface off the plane has no shadow time or another one. So:

1. fit the plane's lines over a *seed* — the area inside its markers (their
   convex hull in the image), or the regions the field log already gives —
   with the robust line fit of :mod:`gnomon.geometry.reference_lines` (objects inside
   the seed are outliers of each frame's line); with two or more planes, the
   frame's crossings on all of them are fitted together by one shadow plane
   (:func:`ransac_shadow_plane`): an object's isochrone back-projected onto a
   plane it is not on can look like a line on that plane alone (the frog's
   belly on the desk in the CMU frog capture), never like one coplanar with
   the other planes' lines; with one plane (a desk and a known lamp) nothing else
   tells the plane's line from a flat-topped object's, so a frame's short line that
   sits off the line its long neighbours predict is refitted to the crossings near
   that prediction (:func:`follow_the_sweep`);
2. predict every pixel's shadow time from those lines (the frame at which
   the line, interpolated between consecutive frames, crosses the pixel's
   point on the plane), for the entering and the leaving edge, from the
   longest run of lines that sweep the plane monotonically (a wrong line
   beyond the sweep, e.g. an off-plane surface's isochrone, is left out);
3. keep the pixels whose measured times agree with both predictions within
   ``tolerance`` frames, and that no other plane explains as well; open the
   mask (drop speckle), drop small pieces and pieces that do not reach into
   the seed (another surface parallel to the plane: a box's face in front of
   the wall), and stay ``margin_px`` away from everything else (blur,
   penumbra);
4. refit the lines over that mask plus what the shadow crossed in frames that had no line (a frame that
   lost its line would otherwise lose its stripe, and with it the crossings that could give it the line
   back), a frame without a line between long ones taking the line its crossings near their prediction
   make (:func:`follow_the_sweep` with ``fill_gaps``), and repeat.

Inputs are plain values (shadow-time maps, planes in the camera frame, seeds,
the camera model); :mod:`gnomon.commands.regions` reads the field log, runs the
first pass and writes the masks.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from gnomon.camera.models import CameraModel
from gnomon.geometry.plane_tie import CornerTie
from gnomon.geometry.plane_times import monotone_sweep, off_plane_pieces, predicted_times
from gnomon.geometry.reference_lines import (
    MIN_POINTS,
    PlaneInCamera,
    ReferenceLines,
    lines_on_plane,
    mask_crossings,
)
from gnomon.reconstruct.bare import MIN_PIECE_PX
from gnomon.reconstruct.corners import tie_camera_planes
from gnomon.util.fitting import fit_plane_robust

__all__ = ["PlaneRegion", "follow_the_sweep", "hull_mask", "line_gaps", "monotone_sweep", "nearest_plane",
           "pixel_footprint", "predicted_times", "propose_regions", "ransac_shadow_plane", "shadow_lines",
           "smooth_times", "tie_on_seeds"]

# The first lines (over the seed, which may hold objects) are RANSAC lines of this tolerance, in pixels on the plane.
RANSAC_PIXELS = 2.0
# Neighbouring shadow times of a smooth swept surface differ by less than this (frames).
SMOOTH_STEP = 2.0
# follow_the_sweep: a short line's crossings within this many RANSAC tolerances of the line its long
# neighbours predict are the plane's (an object's top, tens of mm higher, lies farther off).
FOLLOW_WINDOW = 10.0
# follow_the_sweep(fill_gaps=True): a frame without a line gets one only between long lines at most this many
# frames apart (a hand's sweep is smooth over a second or so, not over the whole capture).
MAX_FOLLOW_GAP = 40


@dataclass
class PlaneRegion:
    """A proposed region of one plane.

    ``mask`` (H, W) bool: bare, swept and consistent with the plane;
    ``residual`` (H, W) float: measured − predicted shadow time (frames, the
    worse of the two edges; NaN where there is none); ``tolerance`` the
    frames used; ``lines_found`` frames with a line on the final mask.
    ``seed_left_out`` pixels of the seed that do not follow the plane (an
    object, its shadow: cut out), in ``seed_pieces`` [(area px, (u0, v0, u1,
    v1))], the largest first; ``gaps`` [(first, last)] runs of at least
    ``MIN_GAP_FRAMES`` frames inside the sweep without a line on the plane
    (the stripes their shadow crossed are missing from the mask).
    """

    name: str
    mask: np.ndarray
    residual: np.ndarray
    tolerance: float
    lines_found: int
    seed_left_out: int = 0
    seed_pieces: list[tuple[int, tuple[int, int, int, int]]] = field(default_factory=list)
    gaps: list[tuple[int, int]] = field(default_factory=list)


def ransac_shadow_plane(points: np.ndarray, label: np.ndarray, normals: np.ndarray, tolerance: np.ndarray,
                        trials: int = 300, seed: int = 0, candidates: int = 20) -> np.ndarray:
    """Inlier mask of the shadow plane through crossings on two or more reference planes.

    ``points`` (N, 3) camera frame: one frame's crossings, each back-projected
    onto its own reference plane ``label`` (N,) int, whose unit normals are
    ``normals`` (P, 3); ``tolerance`` (P,) world units per plane. A straight
    edge's shadow lies in one plane whatever the light, so the crossings of
    one frame on every reference plane are coplanar; those of an object inside
    a region (its own isochrone, back-projected onto a plane it is not on) are
    not. Candidates are planes through two crossings of one reference plane
    and one of another; of the ``candidates`` with the most points within
    tolerance, the one whose inliers cover the most length along the lines it
    cuts on the reference planes (bins of 4 × tolerance, summed over the
    planes) wins: the shadow runs across every plane, an object's crossings
    that happen to fit cluster on the object.
    """
    n = len(points)
    kinds = np.unique(label)
    out = np.zeros(n, dtype=bool)
    if len(kinds) < 2 or n < 3:
        return out
    rng = np.random.default_rng(seed)
    groups = [np.flatnonzero(label == k) for k in kinds]
    pair = rng.integers(0, len(kinds), (trials, 2))
    pair[:, 1] = (pair[:, 0] + 1 + rng.integers(0, len(kinds) - 1, trials)) % len(kinds)
    a = np.array([groups[i][rng.integers(0, len(groups[i]))] for i in pair[:, 0]])
    b = np.array([groups[i][rng.integers(0, len(groups[i]))] for i in pair[:, 0]])
    c = np.array([groups[j][rng.integers(0, len(groups[j]))] for j in pair[:, 1]])
    nrm = np.cross(points[b] - points[a], points[c] - points[a])
    size = np.linalg.norm(nrm, axis=1)
    ok = size > 1e-9 * (1.0 + np.abs(points).max()) ** 2
    if not ok.any():
        return out
    nrm = nrm[ok] / size[ok, None]
    off = np.einsum("ij,ij->i", nrm, points[a[ok]])
    tol = tolerance[label]
    counts = np.zeros(len(nrm), dtype=np.int64)
    for s in range(0, len(nrm), 50):
        r = np.abs(points @ nrm[s:s + 50].T - off[s:s + 50])  # (N, chunk)
        counts[s:s + 50] = (r <= tol[:, None]).sum(axis=0)
    best_cover = -1
    for i in np.argsort(counts)[::-1][:candidates]:
        inl = np.abs(points @ nrm[i] - off[i]) <= tol
        cover, planes_cut = 0, 0
        for k in kinds:
            sel = inl & (label == k)
            along = np.cross(nrm[i], normals[k])
            if sel.sum() < 2 or np.linalg.norm(along) < 1e-9:
                continue
            planes_cut += 1
            cover += np.unique(np.floor((points[sel] @ along) / np.linalg.norm(along) / (4.0 * tolerance[k]))).size
        if planes_cut < 2:
            continue
        if cover > best_cover:
            out, best_cover = inl, cover
    return out


def shadow_lines(times: np.ndarray, n_frames: int, planes: list[PlaneInCamera], masks: list[np.ndarray],
                 camera: CameraModel, names: list[str], tolerance: list[float]) -> list[ReferenceLines]:
    """Each plane's shadow line at every frame, the planes' crossings fitted together where they can be.

    First each plane's own RANSAC line (:func:`~gnomon.geometry.reference_lines.lines_on_plane`,
    ``tolerance`` world units per plane); then, in every frame where two or
    more planes have crossings inside their ``masks``, one shadow plane is
    fitted to all of them (:func:`ransac_shadow_plane`, refined by a robust
    least-squares plane over its inliers) and each plane's line is where it
    cuts that plane. A plane whose crossings that frame do not lie on the
    shadow plane (an object inside its mask) has no line then.
    """
    # every fit kept: a first guess's lines over seeds that hold objects scatter unevenly, and its
    # per-pixel consistency test judges them (the scan's lines drop the scattered ones)
    lines = [lines_on_plane(times, n_frames, p, m, camera, nm, ransac_tolerance=tol, max_scatter=None)
             for p, m, nm, tol in zip(planes, masks, names, tolerance, strict=True)]
    if len(planes) < 2:
        return [follow_the_sweep(lines[0], times, n_frames, masks[0], camera, tolerance[0], fill_gaps=True)]
    pts, lab, frm, pixs = [], [], [], []
    for k, (plane, mask) in enumerate(zip(planes, masks, strict=True)):
        f, pix = mask_crossings(times, mask, n_frames)
        on = plane.intersect(camera.rays(pix)) if len(f) else np.zeros((0, 3))
        good = np.isfinite(on[:, 0])
        pts.append(on[good])
        lab.append(np.full(int(good.sum()), k))
        frm.append(f[good])
        pixs.append(pix[good])
    points, label, frame, pixel = (np.concatenate(x) for x in (pts, lab, frm, pixs))
    normals = np.array([p.normal for p in planes])
    tol = np.asarray(tolerance, dtype=np.float64)
    order = np.argsort(frame, kind="stable")
    bounds = np.searchsorted(frame[order], np.arange(n_frames + 1))
    for t in range(n_frames):
        idx = order[bounds[t]:bounds[t + 1]]
        counts = np.bincount(label[idx], minlength=len(planes))
        if (counts >= MIN_POINTS).sum() < 2:
            continue
        idx = idx[counts[label[idx]] >= MIN_POINTS]
        inl = ransac_shadow_plane(points[idx], label[idx], normals, tol, seed=t)
        if (np.bincount(label[idx][inl], minlength=len(planes)) >= MIN_POINTS).sum() < 2:
            continue
        centre, normal, sub = fit_plane_robust(points[idx][inl])
        keep = np.flatnonzero(inl)[sub]
        for k, plane in enumerate(planes):
            ln = lines[k]
            mine = keep[label[idx][keep] == k]
            if counts[k] < MIN_POINTS:
                continue
            if len(mine) < MIN_POINTS:
                ln.point[t], ln.direction[t] = np.nan, np.nan
                continue
            along = np.cross(normal, plane.normal)
            along /= np.linalg.norm(along)
            q = points[idx][mine].mean(axis=0)
            across = np.cross(plane.normal, along)
            q = q + across * ((normal @ centre - normal @ q) / (normal @ across))
            ln.point[t], ln.direction[t] = q, along
            ln.rms[t] = float(np.sqrt(np.mean(((points[idx][mine] - centre) @ normal) ** 2)))
            ln.count[t] = len(mine)
            ln.pixels[t] = pixel[idx][mine]
            ln.points[t] = points[idx][mine]
            ln.extrapolated[t] = False
    return [follow_the_sweep(ln, times, n_frames, m, camera, tol, fill_gaps=True, hold_short=False)
            for ln, m, tol in zip(lines, masks, tolerance, strict=True)]


def follow_the_sweep(lines: ReferenceLines, times: np.ndarray, n_frames: int, mask: np.ndarray,
                     camera: CameraModel, tolerance: float, *, fill_gaps: bool = False,
                     hold_short: bool = True) -> ReferenceLines:
    """One plane's short lines held to the sweep: each frame whose line was too short to set its own
    direction (``extrapolated``) and lies more than 3 ``tolerance`` (world units) off the line its nearest
    long lines before and after predict (offset and direction interpolated in time) is refitted to its
    crossings within ``FOLLOW_WINDOW`` ``tolerance`` of that prediction (the predicted direction, their
    median offset: the interpolation over a gap of tens of frames errs by a few tolerances where a hand
    sweeps unevenly), or loses its line when fewer than ``MIN_POINTS`` are there. Changes ``lines`` in
    place and returns it.

    With one reference plane nothing else tells the desk's line from an object's: where the shadow
    crosses an object with a flat top (a bowl upside down), that top's isochrone is one straight run with
    more crossings than the desk's two stretches on either side, and the RANSAC line is the object's. The
    sweep moves smoothly, so the long lines around such frames say where the desk's line is.

    ``fill_gaps``: also the frames with no line at all between two long lines at most
    ``MAX_FOLLOW_GAP`` frames apart get one the same way, when at least ``MIN_POINTS`` of their
    crossings near the prediction lie within 3 ``tolerance`` of their median offset: where an object
    beside the plane's short stretch of shadow took a frame's RANSAC line (or its joint shadow plane)
    from it, the stretch is still there, and a region left without its stripe loses it for good.
    ``hold_short=False`` leaves the short lines as they are (two planes' joint shadow planes judged them).
    """
    plane = lines.plane
    long_ = np.flatnonzero(lines.found & ~lines.extrapolated)
    short = np.flatnonzero(lines.found & lines.extrapolated) if hold_short else np.zeros(0, dtype=np.int64)
    missing = np.zeros(0, dtype=np.int64)
    if fill_gaps and len(long_) >= 2:
        inside = np.zeros(n_frames, dtype=bool)
        inside[long_[0]:long_[-1] + 1] = True
        missing = np.flatnonzero(inside & ~lines.found)
    if len(long_) < 2 or not (len(short) or len(missing)):
        return lines
    frame, pix = mask_crossings(times, mask, n_frames)
    on = plane.intersect(camera.rays(pix)) if len(frame) else np.zeros((0, 3))
    good = np.isfinite(on[:, 0])
    frame, pix, on = frame[good], pix[good], on[good]
    xy = plane.to_plane_coords(on)
    centres = plane.to_plane_coords(lines.point)
    d2 = np.stack([lines.direction @ plane.e1, lines.direction @ plane.e2], axis=1)
    is_missing = np.zeros(n_frames, dtype=bool)
    is_missing[missing] = True
    for t in sorted(short.tolist() + missing.tolist()):
        before, after = long_[long_ < t], long_[long_ > t]
        if not len(before) or not len(after):
            continue
        a, b = int(before[-1]), int(after[0])
        if is_missing[t] and b - a > MAX_FOLLOW_GAP:
            continue
        w = (t - a) / (b - a)
        da, db = d2[a], d2[b] * (1.0 if d2[a] @ d2[b] >= 0 else -1.0)
        d = (1.0 - w) * da + w * db
        d /= np.linalg.norm(d)
        n = np.array([-d[1], d[0]])
        predicted = (1.0 - w) * float(centres[a] @ n) + w * float(centres[b] @ n)
        if not is_missing[t] and abs(float(centres[t] @ n) - predicted) <= 3.0 * tolerance:
            continue
        mine = np.flatnonzero(frame == t)
        near = mine[np.abs(xy[mine] @ n - predicted) <= FOLLOW_WINDOW * tolerance]
        if is_missing[t] and len(near) >= MIN_POINTS:  # a line, not a scatter: most near their median
            offsets = xy[near] @ n
            near = near[np.abs(offsets - np.median(offsets)) <= 3.0 * tolerance]
        if len(near) < MIN_POINTS:
            if not is_missing[t]:
                lines.point[t], lines.direction[t], lines.rms[t], lines.count[t] = np.nan, np.nan, np.nan, 0
            continue
        offsets = xy[near] @ n
        along = xy[near] @ d
        centre = float(np.median(offsets)) * n + float(np.mean(along)) * d
        lines.point[t] = plane.from_plane_coords(centre)
        d3 = d[0] * plane.e1 + d[1] * plane.e2
        lines.direction[t] = d3 / np.linalg.norm(d3)
        lines.rms[t] = float(np.sqrt(np.mean((offsets - np.median(offsets)) ** 2)))
        lines.count[t] = len(near)
        lines.pixels[t] = pix[near]
        lines.points[t] = on[near]
        lines.extrapolated[t] = True
    return lines


def crossed_without_line(times: np.ndarray, found: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels whose shadow time (frames) lies next to a frame without a line (``found``
    (N,) per frame): a line there would predict them, so a region that drops them must not also drop
    the crossings that could give that frame its line."""
    n = len(found)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(times) & (times > -1.0) & (times < n)
        lo = np.clip(np.floor(np.where(ok, times, 0.0)).astype(np.int64), 0, n - 1)
    hi = np.minimum(lo + 1, n - 1)
    return ok & ~(found[lo] & found[hi])


def pixel_footprint(plane: PlaneInCamera, camera: CameraModel, where: np.ndarray) -> float:
    """Median size of a pixel on the plane (world units) over the pixels of ``where``: the larger of its two sides."""
    v, u = np.nonzero(where)
    if u.size == 0:
        return float("nan")
    pick = np.linspace(0, u.size - 1, min(u.size, 2000)).astype(int)
    base = np.stack([u[pick], v[pick]], axis=1).astype(np.float64)
    p0 = plane.intersect(camera.rays(base))
    sides = [np.linalg.norm(plane.intersect(camera.rays(base + step)) - p0, axis=1)
             for step in ([1.0, 0.0], [0.0, 1.0])]
    return float(np.nanmedian(np.maximum(*sides)))


def smooth_times(times: np.ndarray, max_step: float = SMOOTH_STEP) -> np.ndarray:
    """The shadow times of pixels whose four neighbours all have one within ``max_step`` frames; NaN elsewhere.

    Wrong times (too little contrast: a marker's black squares, a cast
    shadow, dark carpet) are scattered at random and leave speckle; a surface
    swept by the shadow has smooth times.
    """
    t = np.asarray(times, dtype=np.float64)
    ok = np.isfinite(t)
    padded = np.pad(t, 1, constant_values=np.nan)
    h, w = t.shape
    with np.errstate(invalid="ignore"):
        for dv, du in ((0, 1), (2, 1), (1, 0), (1, 2)):
            ok &= np.abs(padded[dv:dv + h, du:du + w] - t) <= max_step
    return np.where(ok, t, np.nan)


def _clean(mask: np.ndarray, margin_px: int, min_area_px: int, seed: np.ndarray | None = None) -> np.ndarray:
    m: np.ndarray = mask.astype(np.uint8)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))
    m = cv2.morphologyEx(m, cv2.MORPH_OPEN, kernel)
    if margin_px > 0:
        m = cv2.erode(m, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * margin_px + 1, 2 * margin_px + 1)))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
    keep = np.zeros(n, dtype=bool)
    keep[1:] = stats[1:, cv2.CC_STAT_AREA] >= min_area_px
    if seed is not None:  # only pieces that reach into the seed (not another surface parallel to the plane)
        touching = np.zeros(n, dtype=bool)
        touching[np.unique(labels[seed & (labels > 0)])] = True
        keep &= touching
    return keep[labels]


def nearest_plane(planes: list[PlaneInCamera], ray_map: np.ndarray) -> np.ndarray:
    """(H, W) index of the plane each pixel's ray meets first (−1: none in front of the camera).

    Reference planes that meet in a concave corner (a desk and the wall behind
    it, the ground and a facade) are seen where their ray reaches them first.
    """
    rays = ray_map.reshape(-1, 3).astype(np.float64)
    depth = np.full((len(planes), len(rays)), np.inf)
    for k, plane in enumerate(planes):
        hit = plane.intersect(rays.copy())
        ok = np.isfinite(hit[:, 0])
        depth[k, ok] = hit[ok, 2]
    out = np.argmin(depth, axis=0)
    out[~np.isfinite(depth.min(axis=0))] = -1
    return out.reshape(ray_map.shape[:2])


def propose_regions(
    time_maps: list[np.ndarray],
    n_frames: int,
    planes: list[PlaneInCamera],
    names: list[str],
    seeds: list[np.ndarray],
    camera: CameraModel,
    *,
    tolerance: float | None = None,
    margin_px: int = 2,
    min_area_px: int = 200,
    iterations: int = 3,
) -> list[PlaneRegion]:
    """Each plane's bare, swept pixels, consistent with its own shadow lines.

    ``time_maps``: the (H, W) shadow-time maps of the edges used (frames, NaN
    = none), as the scan uses them (:func:`gnomon.reconstruct.edges.edge_time_maps`: a
    fast sweep's staircase re-timed, so that the tolerance is not the
    staircase's ±0.5 frame and an isochrone bending off the plane shows);
    ``planes`` in the camera frame; ``seeds`` (H, W) bool, where to fit the
    first lines. A pixel is a candidate of the plane its ray meets
    first (:func:`nearest_plane`). Lines are RANSAC lines (the seed and the
    candidates hold objects too); each iteration refits them over the last
    proposal plus the candidates the last lines did not reach (so the region
    grows to every frame the shadow crosses the plane in).
    ``tolerance`` (frames): how far a pixel's time may be from the
    prediction; by default 3 robust standard deviations of the residuals
    inside the current region (the seed at first), at least 0.25 frame.
    """
    ray_map = camera.ray_map()
    time_maps = [smooth_times(t) for t in time_maps]
    swept = np.logical_and.reduce([np.isfinite(t) for t in time_maps])
    nearest = nearest_plane(planes, ray_map)
    footprint = [pixel_footprint(plane, camera, seed) for plane, seed in zip(planes, seeds, strict=True)]
    current = [s & (nearest == k) for k, s in enumerate(seeds)]
    unreached = [np.zeros_like(s) for s in seeds]
    found = [0] * len(planes)
    found_frames = [np.zeros(n_frames, dtype=bool) for _ in planes]
    residuals: list[np.ndarray] = []
    tolerances: list[float] = []
    for _ in range(iterations):
        residuals = []
        fit_on = [current[k] | (unreached[k] & (nearest == k) & swept) for k in range(len(planes))]
        worst: list[np.ndarray | None] = [None] * len(planes)
        lost = [np.zeros(ray_map.shape[:2], dtype=bool) for _ in planes]
        preds: list[np.ndarray] = [np.full(ray_map.shape[:2], np.nan)] * len(planes)
        for times in time_maps:
            lines = shadow_lines(times, n_frames, planes, fit_on, camera, names,
                                 [RANSAC_PIXELS * f for f in footprint])
            for k, ln in enumerate(lines):
                found[k] = int(ln.found.sum())
                found_frames[k] = ln.found
                preds[k] = predicted_times(ln, ray_map)
                lost[k] |= crossed_without_line(times, ln.found)
                r = np.abs(times - preds[k])  # NaN where either is missing
                w = worst[k]
                worst[k] = r if w is None else np.maximum(w, r)
        for k in range(len(planes)):
            # refitted next time: what no line reached, and what the shadow crossed in a frame without one
            unreached[k] = ~np.isfinite(preds[k]) | lost[k]
            w = worst[k]
            assert w is not None
            residuals.append(np.where(nearest == k, w, np.nan))
        tolerances = []
        for k, r in enumerate(residuals):
            inside = r[current[k] & np.isfinite(r)]
            if tolerance is not None:
                tolerances.append(float(tolerance))
            elif inside.size:
                tolerances.append(max(0.25, 3.0 * 1.4826 * float(np.median(inside))))
            else:
                tolerances.append(0.25)
        with np.errstate(invalid="ignore"):
            current = [_clean(np.isfinite(r) & (r <= tolerances[k]), margin_px, min_area_px, seeds[k])
                       for k, r in enumerate(residuals)]
    out = []
    for k in range(len(planes)):
        off, pieces = off_plane_pieces(residuals[k], seeds[k] & (nearest == k), tolerances[k], MIN_PIECE_PX)
        out.append(PlaneRegion(names[k], current[k], residuals[k], tolerances[k], found[k],
                               int((off & ~current[k]).sum()), pieces, line_gaps(found_frames[k])))
    return out


#: Fewer frames missing between two lines are no gap worth a word (a stripe a few pixels wide).
MIN_GAP_FRAMES = 3


def line_gaps(found: np.ndarray) -> list[tuple[int, int]]:
    """Runs (first, last) of at least :data:`MIN_GAP_FRAMES` frames without a line between a plane's first and
    last lines."""
    have = np.flatnonzero(found)
    if len(have) < 2:
        return []
    jumps = np.flatnonzero(np.diff(have) > MIN_GAP_FRAMES)
    return [(int(have[j] + 1), int(have[j + 1] - 1)) for j in jumps]


def tie_on_seeds(time_maps: list[np.ndarray], n_frames: int, planes: list[PlaneInCamera], names: list[str],
                 seeds: list[np.ndarray], camera: CameraModel,
                 untied: tuple[tuple[str, str], ...]) -> tuple[list[PlaneInCamera], dict[str, CornerTie | None]]:
    """The planes, each of ``untied`` (plane, anchor) moved to the distance where its shadow lines meet its
    anchor's (:func:`gnomon.reconstruct.corners.tie_camera_planes`), the lines fitted over the seeds with
    RANSAC (they may hold objects); and each tie (None: too few frames' lines met)."""
    lines_of: dict[str, list[ReferenceLines]] = {}
    for name in {n for pair in untied for n in pair}:
        k = names.index(name)
        tolerance = RANSAC_PIXELS * pixel_footprint(planes[k], camera, seeds[k])
        lines_of[name] = [lines_on_plane(times, n_frames, planes[k], seeds[k], camera, name,
                                         ransac_tolerance=tolerance, max_scatter=None) for times in time_maps]
    return tie_camera_planes(planes, names, untied, lines_of)


def hull_mask(shape: tuple[int, int], pixels: np.ndarray, shrink: float = 0.0) -> np.ndarray:
    """(H, W) bool: the convex hull of some pixels (e.g. a plane's markers), optionally shrunk towards its centre."""
    pts = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    c = pts.mean(axis=0)
    pts = c + (1.0 - shrink) * (pts - c)
    hull = cv2.convexHull(np.round(pts * 16).astype(np.int32).reshape(-1, 1, 2))
    canvas = np.zeros(shape, dtype=np.uint8)
    cv2.fillConvexPoly(canvas, hull, 1, lineType=cv2.LINE_8, shift=4)
    return canvas.astype(bool)
