"""Is a pixel's shadow event sound? Checks a point must pass before it is written.

Each check is a pure function of plain arrays (camera frame, world units,
tracker frames) returning a boolean mask of the pixels that pass, so that the
pipeline can count every rejection by its reason.

* :func:`event_order`: the shadow arrives before it leaves (``enter < leave``).
* :func:`global_event_frames`: a sweeping shadow darkens a thin band of the
  image at a time; a frame in which a large part of the image has its
  "shadow" event (a cloud, a flicker, the lights dimmed) is a global event,
  and the events timed there are not the occluder's.
* :func:`contrast_above_noise`: the dip is deeper than the image noise allows
  by chance (random frames give large ``imax − imin`` everywhere, but never
  many σ of their own noise).
* :func:`pole_shadow_consistency` (sun + pole): the triangulated point must be
  where the pole's shadow can fall at that time — behind the pole as seen from
  the sun, below the pole's top — and the measured dip must last as long as a
  shadow of that width, moving at that speed, lasts there. A building's
  shadow, a cloud's flank, the sky or the evening's dimming give a time the
  plane table turns into *some* point; these checks are what rejects it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from gnomon.capture.tracking import MIN_CONTRAST_SIGMAS

__all__ = [
    "SUN_ANGULAR_RADIUS_RAD",
    "PoleConsistency",
    "contrast_above_noise",
    "DirectLight",
    "direct_light",
    "LightEstimate",
    "MIN_LAMP_CONDITIONING",
    "global_event_frames",
    "dip_in_frames",
    "contrast_like_neighbours",
    "fully_lit_like_neighbours",
    "occluded_fraction",
    "inside_sequence",
    "light_point_or_line",
    "LineResiduals",
    "reference_line_residuals",
    "not_in_global_event",
    "event_order",
    "pole_shadow_consistency",
]

SUN_ANGULAR_RADIUS_RAD = math.radians(0.533 / 2.0)
# The smallest over the largest singular value of the shadow planes' unit normals below which
# the planes fix a point light only along a line (they all contain nearly one direction).
MIN_LAMP_CONDITIONING = 0.02
TIP_MARGIN = 2.0  # sun disc radii (angular) between a point's sun ray and the pole's top


def event_order(enter: np.ndarray, leave: np.ndarray) -> np.ndarray:
    """Pixels whose shadow enters strictly before it leaves (both finite)."""
    with np.errstate(invalid="ignore"):
        return np.isfinite(enter) & np.isfinite(leave) & (leave > enter)


def inside_sequence(enter: np.ndarray, leave: np.ndarray, n_frames: int, margin: float = 1.0) -> np.ndarray:
    """Pixels whose whole dip lies inside the sequence with ``margin`` lit frames either side.

    A shadow already there in the first frame (or still there in the last)
    has only one edge in the data: the other is the sequence's end, not an event.
    """
    with np.errstate(invalid="ignore"):
        return (enter >= margin) & (leave <= n_frames - 1 - margin)


def contrast_above_noise(contrast_dn: np.ndarray, noise_dn: float,
                         sigmas: float = MIN_CONTRAST_SIGMAS) -> np.ndarray:
    """Pixels whose contrast (DN) exceeds ``sigmas`` times the image noise σI (DN).

    The extremes of a noisy constant pixel over hundreds of frames span about
    ±3σ, so 8σ leaves a margin; a real shadow is many tens of σ deep.
    """
    with np.errstate(invalid="ignore"):
        return np.isfinite(contrast_dn) & (contrast_dn >= sigmas * noise_dn)


def global_event_frames(times: np.ndarray, n_frames: int, *, spike: float = 10.0,
                        min_fraction: float = 0.4) -> np.ndarray:
    """Tracker frames (int array) in which far more pixels had their event than a sweep explains.

    ``times`` (H, W) tracker frames (NaN = none). A frame is a global event
    when its count of events exceeds ``spike`` times the median count over
    the frames that have any, and ``min_fraction`` of all the timed pixels.
    """
    t = times[np.isfinite(times)]
    if t.size == 0 or n_frames < 3:
        return np.zeros(0, dtype=np.int64)
    counts = np.bincount(np.clip(np.floor(t).astype(np.int64), 0, n_frames - 1), minlength=n_frames)
    busy = counts[counts > 0]
    limit = max(spike * float(np.median(busy)), min_fraction * t.size)
    return np.flatnonzero(counts > limit)


def not_in_global_event(times: np.ndarray, frames: np.ndarray, margin: float = 1.0) -> np.ndarray:
    """Pixels whose time is not within ``margin`` frames of a global-event frame (NaN times pass)."""
    ok = np.ones(times.shape, dtype=bool)
    for f in frames:
        with np.errstate(invalid="ignore"):
            ok &= ~((times >= f - margin) & (times < f + 1 + margin))
    return ok


def dip_in_frames(enter: np.ndarray, leave: np.ndarray, frames: np.ndarray | None, n_frames: int) -> np.ndarray:
    """(H, W) bool: pixels whose dip (from the frame before ``enter`` to the frame after ``leave``,
    tracker frames) includes one of ``frames`` (NaN times: False)."""
    marked = np.zeros(n_frames + 1, dtype=np.int64)
    if frames is not None and len(frames):
        marked[np.asarray(frames, dtype=np.int64) + 1] = 1
    count = np.cumsum(marked)  # count[i]: marked frames before frame i
    ok = np.isfinite(enter) & np.isfinite(leave)
    first = np.clip(np.floor(np.where(ok, enter, 0)), 0, n_frames - 1).astype(np.int64)
    last = np.clip(np.ceil(np.where(ok, leave, 0)), 0, n_frames - 1).astype(np.int64)
    return ok & (count[last + 1] - count[first] > 0)


# A lamp's own light on a pixel is hidden whole by the stick (an umbra): its dip takes the lamp's share of the
# pixel's lit level, ``(Imax − Imin)/Imax``, which over the directly lit surfaces of one capture varies only with
# how much the lamp adds to the room's other light there (docs/method.md, "Points only where the light
# reached"). A dip shallower than BOUNCE_SHARE of the capture's typical one (the median over the candidate
# points) is light bounced off another surface the shadow crossed; up to MOSTLY_BOUNCE_SHARE the pixel is lit
# mostly by bounced light and keeps its point only where both edges agree within EDGES_AGREE_SIGMAS.
BOUNCE_SHARE = 0.3
MOSTLY_BOUNCE_SHARE = 0.6
EDGES_AGREE_SIGMAS = 3.0
# Pixels (a disc of this radius) around a pixel the light does not reach within which a point's footprint (the
# lens's blur, ~3σ of a 0.7 px PSF) may take in its lit neighbours' light and their dip.
EDGE_OF_LIGHT_PX = 2


@dataclass(frozen=True)
class DirectLight:
    """Masks (H, W) of the candidate points refused because the light's own shadow did not make their dip.

    ``bounce_only``: the dip's share of the lit level is under ``BOUNCE_SHARE`` of the capture's typical
    share (light bounced off a surface the shadow crossed); ``edge_of_light``: a pixel the light does not
    reach (no dip, or a bounce-only one) lies within ``EDGE_OF_LIGHT_PX``: the pixel's footprint straddles
    the edge of the lamp's light (an object's cast shadow, a face turning away), and its dip is its lit
    neighbours', blurred in;
    ``edges_disagree``: lit mostly by bounced light (a share under ``MOSTLY_BOUNCE_SHARE`` of the typical
    one) and the two edges' depths differ by more than ``EDGES_AGREE_SIGMAS`` of their combined σ
    (or one edge is missing)."""

    bounce_only: np.ndarray
    edge_of_light: np.ndarray
    edges_disagree: np.ndarray

    @property
    def refused(self) -> np.ndarray:
        return self.bounce_only | self.edge_of_light | self.edges_disagree


def direct_light(candidates: np.ndarray, dip: np.ndarray, relative: np.ndarray,
                 depths: list[np.ndarray], sigmas: list[np.ndarray]) -> DirectLight:
    """Which candidate points (H, W) bool a light whose occluder hides it whole (a lamp and a stick) lit
    directly, judged from each pixel's dip: ``dip`` (H, W) bool the pixel has one beyond the image noise,
    ``relative`` its depth over the lit level ``(Imax − Imin)/Imax`` in linear irradiance, ``depths`` and
    ``sigmas`` each edge's camera Z and σZ (see :class:`DirectLight`). The typical share is the median of
    ``relative`` over the candidates with a dip."""
    typical = relative[candidates & dip & np.isfinite(relative)]
    if not typical.size:
        return DirectLight(*(np.zeros(candidates.shape, dtype=bool),) * 3)
    typical_share = float(np.median(typical))
    with np.errstate(invalid="ignore"):
        shallow = ~(relative >= BOUNCE_SHARE * typical_share)       # NaN: no level, shallow
        mostly = ~(relative >= MOSTLY_BOUNCE_SHARE * typical_share)
    unreached = ~dip | shallow
    r = EDGE_OF_LIGHT_PX
    dv, du = np.mgrid[-r:r + 1, -r:r + 1]
    disc = (du * du + dv * dv <= r * r).astype(np.uint8)
    edge = cv2.dilate(unreached.astype(np.uint8), disc, borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)
    bounce_only = candidates & dip & shallow
    edge_of_light = candidates & edge & ~bounce_only
    if len(depths) == 2:
        with np.errstate(invalid="ignore"):
            agree = np.abs(depths[0] - depths[1]) <= EDGES_AGREE_SIGMAS * np.hypot(sigmas[0], sigmas[1])
    else:  # one edge: nothing to check it against
        agree = np.zeros(candidates.shape, dtype=bool)
    disagree = candidates & mostly & ~shallow & ~agree & ~edge_of_light
    return DirectLight(bounce_only, edge_of_light, disagree)


def contrast_like_neighbours(contrast: np.ndarray, candidates: np.ndarray, *, size: int = 9,
                             min_ratio: float | np.ndarray = 0.55) -> np.ndarray:
    """Candidates whose dip is at least ``min_ratio`` as deep as the mean of the candidates around them.

    One occluder's shadow darkens a surface by an amount that varies slowly
    over it (albedo, distance, angle); a pixel whose dip is much shallower
    than its neighbours' saw the shadow only in part — its light was already
    partly blocked by something else (a building's penumbra, an overhang),
    or its footprint straddles a lit and an unlit surface — and its shadow
    time is biased. ``size``: the square neighbourhood's side (pixels);
    ``min_ratio``: a number, or one per pixel (H, W).
    """
    from scipy.ndimage import uniform_filter

    c = np.where(candidates & np.isfinite(contrast), contrast, 0.0).astype(np.float64)
    n = uniform_filter((candidates & np.isfinite(contrast)).astype(np.float64), size, mode="constant")
    mean = uniform_filter(c, size, mode="constant") / np.maximum(n, 1e-9)
    with np.errstate(invalid="ignore"):
        return candidates & (contrast >= min_ratio * mean)


@dataclass(frozen=True)
class PoleConsistency:
    """Masks (H, W) of the points passing each pole check, and all of them."""

    ok: np.ndarray
    shadow_side: np.ndarray  # behind the pole from the sun, and below its top
    duration: np.ndarray  # the dip lasts as long as the pole's shadow lasts there
    predicted_frames: np.ndarray  # float32 (H, W): the shadow's predicted duration, NaN = none
    occlusion: np.ndarray  # float32 (H, W): the share of the sun's disc the pole hides there, NaN = none


def occluded_fraction(pole_radius: float, distance: np.ndarray,
                      angular_radius: float = SUN_ANGULAR_RADIUS_RAD) -> np.ndarray:
    """The share of the sun's disc a pole of ``pole_radius`` hides, seen from ``distance`` (same units)
    along the sun ray, when the ray passes its axis: 1 inside the umbra (the pole wider than the
    disc there), else the area of the band of half-width ``r`` across a disc of radius ``ρ·s``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.clip(pole_radius / (angular_radius * np.abs(distance)), 0.0, 1.0)
        return (2.0 / np.pi) * (np.arcsin(u) + u * np.sqrt(1.0 - u * u))


def fully_lit_like_neighbours(relative_depth: np.ndarray, occlusion: np.ndarray, candidates: np.ndarray, *,
                              size: int = 9) -> np.ndarray:
    """Candidates that saw at least half the sun's disc when the pole's shadow passed, judged against
    the fully lit surface around them.

    A pixel whose light is ``a·(v·D + A)`` (direct sun D of which the share v
    of the disc is seen past other objects, ambient A) loses ``f·v·D`` when
    the pole hides the share ``f`` of the disc (``occlusion``): its relative
    dip ``relative_depth = (Imax − Imin)/Imax`` (linear) over ``f`` is
    ``q = v·D/(v·D + A)``. Another object's penumbra or a footprint that
    straddles a shadow's edge only lowers q, so the fully lit surface nearby is
    the best 3×3 patch (mean q) within the ``size`` × ``size`` neighbourhood:
    its ``Q = D/(D + A)``. Half the disc seen gives ``Q/(2 − Q)``; below that
    the pixel's dip is not the pole's alone and its time is biased.
    """
    from scipy.ndimage import maximum_filter, uniform_filter

    with np.errstate(invalid="ignore", divide="ignore"):
        q = np.where(candidates, relative_depth / occlusion, np.nan)
    ok = candidates & np.isfinite(q)
    n = uniform_filter(ok.astype(np.float64), 3, mode="constant")
    patch = np.where(n > 0.5, uniform_filter(np.where(ok, q, 0.0), 3, mode="constant") / np.maximum(n, 1e-9), 0.0)
    best = np.clip(maximum_filter(patch, size, mode="constant"), 0.0, 1.0)
    with np.errstate(invalid="ignore"):
        return candidates & ~(ok & (q < best / (2.0 - best)))


def _sun_at(sun_dirs: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Unit sun directions (…, 3) at fractional tracker frames t (linear between frames)."""
    n = len(sun_dirs)
    tt = np.clip(np.nan_to_num(t, nan=0.0), 0.0, n - 1.0)
    k = np.minimum(np.floor(tt).astype(np.int64), max(n - 2, 0))
    f = (tt - k)[..., None]
    d = sun_dirs[k] * (1.0 - f) + sun_dirs[np.minimum(k + 1, n - 1)] * f
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def pole_shadow_consistency(points_cam: np.ndarray, enter: np.ndarray, leave: np.ndarray,
                            sun_dirs_cam: np.ndarray, pole_base_cam: np.ndarray, pole_top_cam: np.ndarray,
                            pole_radius: float, *, angular_radius: float = SUN_ANGULAR_RADIUS_RAD,
                            duration_range: tuple[float, float] = (0.4, 2.5),
                            slack_frames: float = 1.5) -> PoleConsistency:
    """Check each triangulated point against the pole whose shadow it claims to have seen.

    ``points_cam`` (H, W, 3) camera frame (NaN = none); ``enter``, ``leave``
    (H, W) tracker frames; ``sun_dirs_cam`` (N, 3) towards the sun at each
    tracker frame; the pole's base and top (camera frame) and radius (world units).

    Shadow side: at the shadow's centre time, the sun ray from the point must
    reach the pole's axis going towards the sun (not away from it), between
    the pole's base and its top less the sun disc's spread there.

    Duration: across the shadow plane the shadow is ``w = max(2r, 2ρs)`` wide
    (the pole's width, or the sun disc's image at the distance ``s`` along the
    ray to the axis, whichever is larger: beyond ``s = r/ρ`` the shadow is an
    antumbra as wide as the disc), and the plane turns about the axis at the
    sun's angular speed ω around it, so it passes a point at horizontal
    distance ρh from the axis in ``w / (ω ρh)`` frames. The measured
    ``leave − enter`` must lie within ``duration_range`` times that, ±
    ``slack_frames`` (an edge is located to about a frame when the shadow
    crosses a pixel in one or two frames).
    """
    shape = enter.shape
    axis = pole_top_cam - pole_base_cam
    height = float(np.linalg.norm(axis))
    a = axis / height
    P = points_cam.reshape(-1, 3).astype(np.float64)
    e = enter.reshape(-1).astype(np.float64)
    lv = leave.reshape(-1).astype(np.float64)
    have = np.all(np.isfinite(P), axis=1) & np.isfinite(e) & np.isfinite(lv)
    side = np.zeros(P.shape[0], dtype=bool)
    duration = np.zeros(P.shape[0], dtype=bool)
    predicted = np.full(P.shape[0], np.nan, dtype=np.float32)
    occlusion = np.full(P.shape[0], np.nan, dtype=np.float32)
    if have.any() and len(sun_dirs_cam) >= 2:
        idx = np.flatnonzero(have)
        X = P[idx]
        tc = 0.5 * (e[idx] + lv[idx])
        d = _sun_at(sun_dirs_cam, tc)
        rel = X - pole_base_cam
        rel_h = rel - (rel @ a)[:, None] * a
        d_h = d - (np.einsum("ij,j->i", d, a))[:, None] * a
        dh = np.linalg.norm(d_h, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            along = -np.einsum("ij,ij->i", rel_h, d_h) / dh  # horizontal distance towards the pole
            s = along / dh  # ray length from the point to the axis
            z_axis = rel @ a + s * (d @ a)  # height of the ray above the base where it passes the axis
            # Near the pole's top the shadow's tip is blurred by the disc (and the top's shape):
            # the ray must pass the axis TIP_MARGIN disc radii below the top.
            ok_side = (along > 0) & (z_axis >= 0) & (z_axis <= height - TIP_MARGIN * angular_radius * s / dh)
            # Angular speed of the sun about the pole's axis (rad per tracker frame), at tc.
            d0 = _sun_at(sun_dirs_cam, tc - 0.5)
            d1 = _sun_at(sun_dirs_cam, tc + 0.5)
            h0 = d0 - (d0 @ a)[:, None] * a
            h1 = d1 - (d1 @ a)[:, None] * a
            cosang = np.einsum("ij,ij->i", h0, h1) / (np.linalg.norm(h0, axis=1) * np.linalg.norm(h1, axis=1))
            omega = np.arccos(np.clip(cosang, -1.0, 1.0))
            rho_h = np.linalg.norm(rel_h, axis=1)
            width = np.maximum(2.0 * pole_radius, 2.0 * angular_radius * np.abs(s))
            pred = width / (omega * rho_h)
            measured = lv[idx] - e[idx]
            lo, hi = duration_range
            ok_dur = np.isfinite(pred) & (measured >= lo * pred - slack_frames) & (measured <= hi * pred + slack_frames)
        side[idx] = ok_side
        duration[idx] = ok_dur
        predicted[idx] = pred.astype(np.float32)
        occlusion[idx] = occluded_fraction(pole_radius, s, angular_radius).astype(np.float32)
    return PoleConsistency((side & duration).reshape(shape), side.reshape(shape), duration.reshape(shape),
                           predicted.reshape(shape), occlusion.reshape(shape))


# Reference-line residuals: a warning when they are this many times what the pixel times' noise
# explains; an error when they exceed the shadow's own motion in one frame (the line of frame t
# can no longer be told from those of t ± 1: its plane means nothing).
LINE_RESIDUAL_WARN_RATIO = 3.0
LINE_RESIDUAL_MAX_FRAMES = 1.0


@dataclass(frozen=True)
class LineResiduals:
    """How well one plane's shadow lines fit their crossings, in frames of shadow motion.

    ``residual_frames``: the median over frames of each line's residual RMS
    divided by how far the line moves across itself per frame; ``expected_frames``:
    the median time σ of the crossing pixels (the scatter their noise explains);
    ``frames``: lines that entered the medians.
    """

    plane: str
    residual_frames: float
    expected_frames: float
    frames: int

    @property
    def ratio(self) -> float:
        return self.residual_frames / self.expected_frames if self.expected_frames > 0 else float("inf")


def reference_line_residuals(lines, sigma_t: np.ndarray) -> LineResiduals | None:
    """Residuals of one plane's lines (:class:`gnomon.geometry.reference_lines.ReferenceLines`) against the time
    σ map ``sigma_t`` (H, W, frames) of the pixels they were fitted to; None when fewer than three
    lines have a neighbour to measure their motion against."""
    residual, expected = [], []
    h, w = sigma_t.shape
    speeds = lines.speeds()
    for t in np.flatnonzero(lines.found):
        if lines.count[t] < 3 or lines.extrapolated[t] or not np.isfinite(lines.rms[t]):
            continue
        speed = float(speeds[t])
        if speed <= 0:
            continue
        px = np.rint(lines.pixels[t]).astype(np.int64)
        u, v = np.clip(px[:, 0], 0, w - 1), np.clip(px[:, 1], 0, h - 1)
        sig = sigma_t[v, u]
        sig = sig[np.isfinite(sig)]
        if sig.size == 0:
            continue
        residual.append(float(lines.rms[t]) / speed)
        expected.append(float(np.median(sig)))
    if len(residual) < 3:
        return None
    return LineResiduals(lines.plane_name, float(np.median(residual)), float(np.median(expected)), len(residual))


def unmodelled_time_scatter(residuals: list[LineResiduals | None]) -> float:
    """Per-pixel time scatter (frames, 1σ) that the noise model does not explain, from an edge's planes'
    line residuals: each plane's ``sqrt(max(0, residual² − expected²))``, the smallest over the planes
    (a plane that is not flat or not bare adds its own residual; the capture's scatter is what all share);
    0 without residuals.

    The lines' residual is the scatter of single bare-plane pixels' times about a line fitted to hundreds
    of them: every per-pixel time error, where the noise model (σ_I over the slope, edge sampling) knows
    only the sensor's noise. On a compressed, denoised video the rest (codec blocks and motion
    compensation, a ragged edge) is 10-20 times larger than the noise (1080p phone captures: 0.12-0.36
    frame against 0.01-0.02)."""
    excess = [float(np.sqrt(max(0.0, r.residual_frames ** 2 - r.expected_frames ** 2)))
              for r in residuals if r is not None]
    return min(excess) if excess else 0.0


@dataclass(frozen=True)
class LightEstimate:
    """A point light located from its shadow planes (camera frame, world units).

    ``conditioning``: the smallest over the largest singular value of the
    planes' unit normals (1 = directions all round, 0 = all planes contain one
    direction). When it is below ``MIN_LAMP_CONDITIONING`` the planes fix the
    light only along a line: ``direction`` is that line's unit direction
    through ``point`` (the least-squares point, arbitrary along the line) and
    ``degenerate`` is True; else ``direction`` is None.
    """

    point: np.ndarray
    plane_rms: float
    conditioning: float
    direction: np.ndarray | None

    @property
    def degenerate(self) -> bool:
        return self.direction is not None


def light_point_or_line(planes: np.ndarray, min_conditioning: float = MIN_LAMP_CONDITIONING) -> LightEstimate:
    """The point closest to every valid shadow plane ``[nx, ny, nz, d]`` (``n·X = d``), or the line
    it is confined to when the planes share one direction. Needs ≥ 3 valid planes (ValueError)."""
    valid = planes[np.all(np.isfinite(planes), axis=1)]
    if len(valid) < 3:
        raise ValueError("need at least three shadow planes to locate the light")
    norms = np.linalg.norm(valid[:, :3], axis=1, keepdims=True)
    n, d = valid[:, :3] / norms, valid[:, 3] / norms[:, 0]
    _, sv, vt = np.linalg.svd(n, full_matrices=False)
    conditioning = float(sv[-1] / sv[0])
    # Minimum-norm least squares: along a degenerate direction it picks the point nearest the origin.
    point, *_ = np.linalg.lstsq(n, d, rcond=min_conditioning if conditioning < min_conditioning else None)
    rms = float(np.sqrt(np.mean((n @ point - d) ** 2)))
    direction = vt[-1] / np.linalg.norm(vt[-1]) if conditioning < min_conditioning else None
    return LightEstimate(point, rms, conditioning, direction)

