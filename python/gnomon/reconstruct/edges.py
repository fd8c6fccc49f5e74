"""Each shadow edge from its times to its depths: σ of the times, shadow planes, triangulation, checks.

The tracker gives each pixel an entering and a leaving time (:mod:`gnomon.capture.tracking`). Per
edge, :func:`edge_time` adds each time's σ and re-times a fast sweep between its isochrones
(:mod:`gnomon.reconstruct.retiming`); the light model gives the shadow planes
(:meth:`gnomon.light.LightModel.shadow_planes`); :func:`reconstruct_edge` triangulates against them
(the kernel) with σZ; :func:`reconstruct_edges` runs both edges on a thread each and checks what the
scan must refuse or warn about (too few planes, lines that do not fit, grazing rays).
"""

from __future__ import annotations

import dataclasses
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from gnomon.capture.deblock import block_grid, deblock_times
from gnomon.capture.tracking import (
    MIN_CONTRAST_SIGMAS,
    ShadowTimes,
    TrackedSequence,
    contrast_floor,
    linear,
)
from gnomon.config.setup import ScanSetup
from gnomon.errors import FrameError, FrameNote
from gnomon.geometry.reference_lines import LineMemo, ReferenceLines
from gnomon.geometry.surface import points_from_depth, ray_plane_angles
from gnomon.geometry.triangulation import triangulate_depth
from gnomon.geometry.uncertainty import (
    completion_depth_sigma,
    depth_sigma,
    interpolation_time_sigma,
    linear_noise_at_threshold,
    undersampled,
)
from gnomon.geometry.validity import (
    LINE_RESIDUAL_MAX_FRAMES,
    LINE_RESIDUAL_WARN_RATIO,
    reference_line_residuals,
    unmodelled_time_scatter,
)
from gnomon.light import EdgePlanes, EdgeTimes, ReferenceGeometry
from gnomon.light.base import LightModel, Screening
from gnomon.reconstruct.retiming import ACROSS_HALF_ROWS, RowRetiming, average_across_sweep, retime_rows

# Quality gates: share of the sweep's frames with a measured shadow plane (error below / warning
# below), and the longest gap (frames) to a plane over which a pixel's depth may be interpolated.
MIN_PLANE_SHARE_ERROR = 0.2


MIN_PLANE_SHARE_WARN = 0.5


MAX_PLANE_GAP = 3.0


# An edge is re-timed between its isochrones when more than this share of its timed pixels is
# under-sampled (a fast sweep: the tracker's temporal interpolation gives a staircase). On the
# simulated captures, whose sweeps are slower, re-timing the few fast pixels is not better.
RETIME_UNDERSAMPLED_SHARE = 0.5


@dataclass
class EdgeResult:
    """One shadow edge's reconstruction (camera frame, world units)."""

    name: str  # "enter" | "leave" | "centre"
    times: np.ndarray  # (H, W) tracker frames, NaN = none
    lines: list[ReferenceLines]
    planes: np.ndarray  # (N, 4); row k is the plane at tracker time k / time_scale
    depth: np.ndarray  # (H, W) camera Z, NaN = none
    sigma: np.ndarray  # (H, W) σZ
    degenerate: int
    slope: np.ndarray  # (H, W) linear irradiance per frame at the crossing
    measured: bool = True  # planes measured per frame from the reference lines (else computed by the light)
    rejected: dict[str, int] = field(default_factory=dict)  # points refused, by reason
    notes: list[str] = field(default_factory=list)  # warnings about this edge
    # 10th, 50th and 90th percentiles over the triangulated pixels of the angle (degrees) between a pixel's
    # ray and its shadow plane: a depth moves by an error of the plane (or of the time, times the shadow's
    # speed) over the sine of this angle (docs/method.md §4)
    ray_plane_angle_deg: tuple[float, float, float] | None = None
    # (share of the triangulated pixels whose ray meets its shadow plane under GRAZING_DEG, their count)
    grazing: tuple[float, int] | None = None
    # frames of per-pixel time σ the reference lines showed beyond the noise model, added to every pixel's
    # time σ before σZ was propagated (gnomon.geometry.validity.unmodelled_time_scatter)
    unmodelled_sigma_t: float = 0.0


@dataclass(frozen=True)
class PreparedEdge:
    """One edge's times before its averaging across the sweep (:meth:`Levels.edge`): ``times`` (H, W,
    frames; a compressed video's de-blocked) and their σ ``sigma``; for a fast sweep also its re-timing
    (:func:`~gnomon.reconstruct.retiming.retime_rows`), else None."""

    times: np.ndarray
    sigma: np.ndarray
    retiming: RowRetiming | None


class Levels:
    """Per-pixel levels of the tracked dips in linear irradiance, each computed once per scan (both
    edges, the screening and the fusion use them), and each edge's times as :func:`edge_time` prepares
    them before its averaging across the sweep (the regions' maps and the edges share them).

    For the tracked times as they are: a light that rewrites them (``choose_dips``) needs a new one.
    ``lines``: the reference lines measured on those times (the regions' last, which the edges reuse)."""

    def __init__(self, tracked: TrackedSequence):
        self.tracked = tracked
        self._edges: dict[str, PreparedEdge] = {}
        self.lines = LineMemo()

    def edge(self, name: str, times: np.ndarray, slope: np.ndarray) -> PreparedEdge:
        """The edge ``name``'s :class:`PreparedEdge` (``times`` and ``slope`` (H, W) the tracker's), computed
        once per edge."""
        if name not in self._edges:
            self._edges[name] = _prepared_edge(times, slope, self.tracked, self)
        return self._edges[name]

    @cached_property
    def imax(self) -> np.ndarray:
        return linear(self.tracked.times.imax, self.tracked.lut)

    @cached_property
    def imin(self) -> np.ndarray:
        return linear(self.tracked.times.imin, self.tracked.lut)

    @cached_property
    def sigma_at_threshold(self) -> np.ndarray:
        """The image noise carried to irradiance at each pixel's threshold."""
        t = self.tracked
        # The noise is measured in the input's DN: carry it to irradiance through the input's decoding.
        return linear_noise_at_threshold(t.noise_dn, t.times.threshold, t.lut)

    @cached_property
    def relative_depth(self) -> tuple[np.ndarray, np.ndarray]:
        return relative_depth(self.tracked, self.imax, self.imin)


def pixel_time_sigma(slope: np.ndarray, tracked: TrackedSequence, levels: Levels | None = None) -> np.ndarray:
    """σ of each pixel's shadow time (frames): image noise over the slope, and edge sampling."""
    levels = levels or Levels(tracked)
    sigma_lin = levels.sigma_at_threshold
    contrast_lin = levels.imax - tracked.times.threshold
    np.multiply(2.0, contrast_lin, out=contrast_lin)  # 2·(Imax − threshold), in its own new array
    with np.errstate(invalid="ignore", divide="ignore"):
        sigma_t_noise = np.divide(sigma_lin, slope)  # np.where(slope > 0, σ / slope, NaN), in place
        np.copyto(sigma_t_noise, np.nan, where=~(slope > 0))
    return np.hypot(sigma_t_noise, interpolation_time_sigma(contrast_lin, slope), out=sigma_t_noise)


def edge_time(name: str, times: np.ndarray, slope: np.ndarray, tracked: TrackedSequence,
               levels: Levels | None = None, across: int = ACROSS_HALF_ROWS) -> EdgeTimes:
    """One edge's times and σ; a fast sweep's (most pixels crossed within two frames) re-timed between
    the isochrones (:mod:`gnomon.reconstruct.retiming`), each re-timed σ from the σ of the pixels its crossings
    were interpolated between, and the re-timed times averaged across the sweep over ±``across`` rows
    (:func:`gnomon.reconstruct.retiming.average_across_sweep`)."""
    prepared = (levels or Levels(tracked)).edge(name, times, slope)
    r = prepared.retiming
    if r is None:
        return EdgeTimes(name, prepared.times, slope, prepared.sigma)
    retimed = r.times if across <= 0 or r.retimed is None else average_across_sweep(r.times, r.retimed,
                                                                                  r.along_rows, across)
    return EdgeTimes(name, retimed, slope, r.sigma)


def _prepared_edge(times: np.ndarray, slope: np.ndarray, tracked: TrackedSequence, levels: Levels) -> PreparedEdge:
    """:meth:`Levels.edge`: the times' σ, a compressed video's times de-blocked, a fast sweep re-timed."""
    sigma = pixel_time_sigma(slope, tracked, levels)
    grid = block_grid(times)
    if grid is not None:  # compressed video: times constant over the codec's blocks (gnomon.capture.deblock)
        times = deblock_times(times, grid)
    fast = undersampled(slope, levels.imax, levels.imin)
    timed = np.isfinite(times)
    retiming = None
    if timed.any() and fast[timed].mean() > RETIME_UNDERSAMPLED_SHARE:
        retiming = retime_rows(times, tracked.n_frames, sigma)
    return PreparedEdge(times, sigma, retiming)


def edge_times(tracked: TrackedSequence, levels: Levels | None = None,
                across: int = ACROSS_HALF_ROWS) -> tuple[EdgeTimes, EdgeTimes]:
    t, levels = tracked.times, levels or Levels(tracked)
    levels.imax, levels.imin, levels.sigma_at_threshold  # noqa: B018 - computed once, before the threads share them
    # the two edges on a thread each (numpy and the kernel release the GIL)
    with ThreadPoolExecutor(max_workers=2, thread_name_prefix="gnomon-edge") as pool:
        enter = pool.submit(edge_time, "enter", t.enter, t.enter_slope, tracked, levels, across)
        leave = pool.submit(edge_time, "leave", t.leave, t.leave_slope, tracked, levels, across)
        return enter.result(), leave.result()


def edge_time_maps(tracked: TrackedSequence, edge: str = "both", levels: Levels | None = None) -> list[np.ndarray]:
    """The shadow-time maps (H, W, frames, NaN = none) the scan measures its lines and depths on.

    The tracker's entering and leaving times after the same corrections as the
    scan's: a compressed video's block times interpolated (:mod:`gnomon.capture.deblock`)
    and a fast sweep's times re-timed between the isochrones
    (:mod:`gnomon.reconstruct.retiming`). ``edge``: ``"both"`` (entering, leaving),
    ``"enter"`` or ``"leave"``. ``gnomon regions`` judges its regions on these,
    so that a staircase of under-sampled times (±0.5 frame) does not hide an
    isochrone that bends off the plane; without the scan's averaging of the
    re-timed times across the sweep (:func:`gnomon.reconstruct.retiming.average_across_sweep`),
    which runs along the isochrones and would smooth the very bends the regions
    look for. ``levels``: the scan's :class:`Levels`, whose edges' times the scan then reuses.
    """
    enter, leave = edge_times(tracked, levels, across=0)
    if edge == "both":
        return [enter.times, leave.times]
    return [enter.times if edge == "enter" else leave.times]


def with_typical_sigma(depth: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """A depth whose σ could not be propagated (no neighbouring plane for the
    derivative, no measured slope) keeps its point with the typical σ."""
    good = np.isfinite(sigma) & (sigma > 0)
    missing = np.isfinite(depth) & ~good
    if missing.any():
        typical = np.nanmedian(sigma[good]) if good.any() else 1.0
        sigma = np.where(missing, np.float32(typical), sigma)
    return sigma


def reconstruct_edge(edge: EdgeTimes, planes: EdgePlanes, ray_map: np.ndarray, setup: ScanSetup,
                      tracked: TrackedSequence, levels: Levels | None = None) -> EdgeResult:
    """Triangulate one edge against its shadow planes (keeping the points the light accepts), with σZ."""
    scaled = (edge.times * planes.time_scale).astype(np.float32)
    depth = triangulate_depth(ray_map, scaled, planes.planes)  # triangulate(...).depth, without the points
    if type(setup.light).screen is LightModel.screen:
        screening = Screening()  # the default keeps every point: its inputs are not computed
    else:
        screening = setup.light.screen(edge, points_from_depth(ray_map, depth), tracked.times,
                                       tracked.n_frames, *(levels or Levels(tracked)).relative_depth,
                                       levelled=tracked.levelled_frames)
    if screening.keep is not None:
        depth[~screening.keep] = np.nan
    unc = depth_sigma(ray_map, scaled, planes.planes, depth, edge.sigma_t * planes.time_scale,
                      planes.sigma_t_line)
    sigma_z = unc.sigma_z
    if planes.completion is not None:  # rows completed from one line: their plane's own error
        c = planes.completion
        sigma_z = np.hypot(sigma_z, completion_depth_sigma(ray_map, scaled, depth, planes.planes,
                                                           c.line_point, c.line_direction, c.sigma_rad))
    angles = ray_plane_angles(ray_map, scaled, planes.planes, np.isfinite(depth))
    angles = angles[np.isfinite(angles)]
    spread = grazing = None
    if angles.size:
        p10, p50, p90 = (float(a) for a in np.percentile(angles, [10, 50, 90]))
        spread = (p10, p50, p90)
        grazing = (float(np.mean(angles < GRAZING_DEG)), int(angles.size))
    return EdgeResult(edge.name, edge.times, planes.lines, planes.planes, depth,
                      with_typical_sigma(depth, sigma_z), planes.degenerate, edge.slope, planes.measured,
                      screening.rejected, screening.notes, spread, grazing)


def reconstruct_edge_checked(edge: EdgeTimes, planes: EdgePlanes, ray_map: np.ndarray, setup: ScanSetup,
                              tracked: TrackedSequence, levels: Levels) -> tuple[EdgeResult, list[Any]]:
    """:func:`reconstruct_edge` and its lines' residuals (:func:`check_line_residuals` judges them), on the
    edge's own thread. The time scatter the lines show beyond the noise model
    (:func:`~gnomon.geometry.validity.unmodelled_time_scatter`) is added to every pixel's time σ first, so that σZ
    (and the fusion, the edges' agreement and ``max_sigma``, which read it) carries it."""
    residuals = [reference_line_residuals(lines, edge.sigma_t) for lines in planes.lines]
    excess = unmodelled_time_scatter(residuals)
    if excess > 0:
        edge = dataclasses.replace(edge, sigma_t=np.hypot(edge.sigma_t, np.float32(excess)).astype(np.float32))
    result = reconstruct_edge(edge, planes, ray_map, setup, tracked, levels)
    result.unmodelled_sigma_t = excess
    return result, residuals


def relative_depth(tracked: TrackedSequence, hi: np.ndarray, lo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) each dip's depth over its lit level, ``r = (Imax − Imin)/Imax`` in linear irradiance
    (``hi``, ``lo``: the levels Imax, Imin), and its 1σ from the image noise at both levels."""
    s_hi = linear_noise_at_threshold(tracked.noise_dn, hi, tracked.lut)
    s_lo = linear_noise_at_threshold(tracked.noise_dn, lo, tracked.lut)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(hi > 0, (hi - lo) / hi, np.nan)
        sigma = np.where(hi > 0, np.hypot(s_lo / hi, lo * s_hi / hi**2), np.nan)
    return r.astype(np.float32), sigma.astype(np.float32)


def check_contrast(times: ShadowTimes, noise_dn: float, min_contrast: float | None, name: str) -> None:
    """Too few events (dips above the contrast floor, which the tracker applied) is an error that
    says why: random frames have a large ``imax − imin`` everywhere but never many σ of their
    own noise; identical frames have no contrast at all.
    """
    n_pixels = times.valid.size
    if times.valid.sum() <= 0.001 * n_pixels:
        largest = float(np.nanmax(times.contrast)) if np.isfinite(times.contrast).any() else 0.0
        floor = min_contrast if min_contrast is not None else MIN_CONTRAST_SIGMAS * noise_dn
        if largest < floor or largest <= 0:
            what = (f"min_contrast = {min_contrast:g} DN" if min_contrast is not None
                    else f"{MIN_CONTRAST_SIGMAS:g} σ of the image noise ({floor:.1f} DN)")
            why = (f"no pixel changes by {what} (largest change {largest:.1f} DN): "
                   "the frames are (nearly) identical, or the shadow never crossed the view")
        else:
            why = (f"the image noise is {noise_dn:.1f} DN between frames, so no pixel's dip stands "
                   f"{MIN_CONTRAST_SIGMAS:g} σ out of it: the frames look like noise, not a shadow sweep")
        raise FrameError(f"{name}: {why}")


def min_contrast_dn(min_contrast: float | None, noise_dn: float) -> float:
    """The contrast floor in force (DN of the input), as the tracker applied it (:func:`contrast_floor`)."""
    return contrast_floor(min_contrast, noise_dn)


@dataclass(frozen=True)
class PlaneCoverage:
    """How an edge's measured shadow planes cover its sweep (:func:`plane_coverage`): ``measured`` of the
    sweep's ``frames`` have a plane (``share`` of them), ``dropped`` points were too far from any."""

    measured: int
    frames: int
    share: float
    dropped: int


def plane_coverage(e: EdgeResult) -> PlaneCoverage | None:
    """The planes' coverage of the frames the edge's pixels saw the shadow in (the 2nd to 98th percentile of
    their times), its points whose time is more than ``MAX_PLANE_GAP`` frames from any measured plane
    dropped from ``e.depth`` (NaN); None when there is nothing to check (no plane or time, planes given)."""
    have = np.isfinite(e.planes[:, 0])
    t = e.times[np.isfinite(e.times)]
    if not e.measured or t.size == 0 or not have.any():
        return None
    lo, hi = np.percentile(t, [2, 98])
    span = np.arange(max(int(np.floor(lo)), 0), min(int(np.ceil(hi)) + 1, len(have)))
    if span.size == 0:
        return None
    far = far_from_planes(e.times, e.depth, have)
    if far.any():
        e.depth[far] = np.nan
    return PlaneCoverage(int(have[span].sum()), span.size, float(have[span].mean()), int(far.sum()))


def check_plane_coverage(edges: list[EdgeResult], path: Path, warnings: list[str],
                         coverage: list[PlaneCoverage | None] | None = None) -> None:
    """The measured shadow planes must cover the frames in which the pixels saw the shadow.

    A pixel's depth comes from the planes of the frames around its shadow
    time; where no plane was measured for many frames (the shadow missed the
    reference regions) the depth is interpolated over the gap and is
    meaningless. Points whose time falls in a gap longer than ``MAX_PLANE_GAP``
    frames are dropped; when the planes cover less than half of the sweep a
    warning says so, and below a fifth the scan is an error. ``coverage``: each edge's
    :func:`plane_coverage`, already taken (on the edges' threads); else taken here, edge by edge.
    """
    for k, e in enumerate(edges):
        c = coverage[k] if coverage is not None else plane_coverage(e)
        if c is None:
            continue
        if c.dropped:
            warnings.append(f"{e.name} edge: {c.dropped} points dropped: their shadow time is more than "
                            f"{MAX_PLANE_GAP:g} frames from any measured shadow plane")
        msg = (f"{e.name} edge: shadow planes were measured in {c.measured} of the {c.frames} frames "
               f"of the sweep ({100 * c.share:.0f} %); the shadow rarely crossed the [[planes]] regions")
        if c.share < MIN_PLANE_SHARE_ERROR:
            raise FrameError(f"{path}: {msg}: too few to scan (check the regions are bare and swept)")
        if c.share < MIN_PLANE_SHARE_WARN:
            warnings.append(msg)


def plane_gap(times: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """Distance (frames) from each time to the nearest of ``frames`` (sorted, non-empty), NaN for NaN."""
    k = np.clip(np.searchsorted(frames, times), 1, max(len(frames) - 1, 1))
    with np.errstate(invalid="ignore"):
        return np.fmin(np.abs(times - frames[np.clip(k - 1, 0, len(frames) - 1)]),
                       np.abs(times - frames[np.clip(k, 0, len(frames) - 1)]))


def far_from_planes(times: np.ndarray, depth: np.ndarray, have: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels with a depth whose time (frames) is not within ``MAX_PLANE_GAP`` frames of a
    frame with a plane (``have`` (N,) bool per frame, at least one).

    The gap is measured (:func:`plane_gap`) only where it may exceed the bound: a time ``t`` in ``[i, i + 1)``
    is at most ``t − i < 1`` frame farther from the nearest plane than the integer frame ``i``, so the frames
    ``i`` within ``MAX_PLANE_GAP − 1`` of a plane clear all of their times at once (a few comparisons per pixel
    instead of a search).
    """
    frames = np.flatnonzero(have)
    ints = np.arange(len(have), dtype=np.float64)
    clear = plane_gap(ints, frames) <= MAX_PLANE_GAP - 1.0
    # runs [a, b) of integer frames that do not clear their times
    edges = np.flatnonzero(np.diff(np.concatenate([[True], clear, [True]]).astype(np.int8)))
    runs = edges.reshape(-1, 2)
    check = np.isfinite(depth)
    if len(runs) <= 8:
        with np.errstate(invalid="ignore"):
            cleared = (times >= 0) & (times < len(have))  # NaN: not cleared
            for a, b in runs:
                cleared &= ~((times >= a) & (times < b))
        check &= ~cleared
    far = np.zeros(np.shape(depth), dtype=bool)
    if check.any():
        far[check] = ~(plane_gap(times[check], frames) <= MAX_PLANE_GAP)
    return far


def check_line_residuals(edge: EdgeResult, residuals: list[Any], path: Path, warnings: list[str]) -> None:
    """The shadow lines must fit their crossings about as well as the pixel times' noise allows.

    ``residuals``: :func:`~gnomon.geometry.validity.reference_line_residuals` of each of ``edge.lines`` (with the
    edge's time σ). Far worse (a region that is not bare or not flat, a wrong plane, several
    shadows on it) is a warning with the numbers; lines scattered by more than
    the shadow moves in a frame locate nothing, and the scan is an error.
    """
    for r in residuals:
        if r is None:
            continue
        what = (f"{edge.name} edge: the shadow lines on [[planes]] '{r.plane}' fit their pixels with a median "
                f"residual of {r.residual_frames:.2f} frames of shadow motion, {r.ratio:.1f} times what the pixels' "
                f"time noise ({r.expected_frames:.2f} frames) explains ({r.frames} lines)")
        if r.residual_frames > LINE_RESIDUAL_MAX_FRAMES:
            raise FrameError(f"{path}: {what}: the lines are meaningless (check the regions are bare, flat and on "
                             "that plane)")
        if r.ratio > LINE_RESIDUAL_WARN_RATIO:
            warnings.append(f"{what}; check the regions are bare, flat and on that plane")


def reconstruct_edges(setup: ScanSetup, tracked: TrackedSequence, ray_map: np.ndarray,
                       warnings: list[str], levels: Levels | None = None) -> list[EdgeResult]:
    levels = levels or Levels(tracked)
    geometry = ReferenceGeometry(setup.camera, setup.planes, tracked.n_frames, levels.lines)
    levels.imax, levels.imin, levels.sigma_at_threshold  # noqa: B018 - computed once, before the threads share them
    # The edges are independent until they are fused: one thread each (numpy and the kernel release
    # the GIL; the other core is idle once the frames are decoded). Results and errors in edge order.
    st = tracked.times
    with ThreadPoolExecutor(max_workers=2, thread_name_prefix="gnomon-edge") as pool:
        enter = pool.submit(edge_time, "enter", st.enter, st.enter_slope, tracked, levels)
        leave = pool.submit(edge_time, "leave", st.leave, st.leave_slope, tracked, levels)
        times = setup.light.edges(enter.result(), leave.result(), setup.edge)

        def one(e: EdgeTimes) -> tuple[EdgeResult, list[Any], PlaneCoverage | None]:
            result, residuals = reconstruct_edge_checked(e, setup.light.shadow_planes(e, geometry), ray_map, setup,
                                                         tracked, levels)
            return result, residuals, plane_coverage(result)  # said below, in edge order

        done = list(pool.map(one, times))
    edges = [e for e, _, _ in done]
    for e, residuals, _ in done:
        check_line_residuals(e, residuals, setup.inputs.field_log, warnings)
    for e in edges:
        if e.degenerate:
            warnings.append(f"{e.name} edge: {e.degenerate} frames dropped as degenerate shadow planes")
        for note in e.notes:  # a FrameNote keeps its kind and frames
            text = f"{e.name} edge: {note}"
            warnings.append(note.reworded(text) if isinstance(note, FrameNote) else text)
    check_plane_coverage(edges, setup.inputs.field_log, warnings, [c for _, _, c in done])
    n_planes = max(int(np.isfinite(e.planes[:, 0]).sum()) for e in edges)
    if n_planes < 2:
        raise FrameError(
            f"{setup.inputs.field_log}: the shadow line was found on the reference regions in {n_planes} of "
            f"{tracked.n_frames} frames; check [[planes]] regions (bare, swept by the shadow) "
            f"and [scan] min_contrast"
        )
    return edges


# A ray meeting its shadow plane under GRAZING_DEG degrees turns a time error (or a plane's) into a depth
# error over 1 / sin(2°) ≈ 29 times what a ray square to the plane gets (docs/method.md §4); a scan warns
# when more than GRAZING_SHARE of its triangulated pixels are such rays: the shadow planes pass close to
# the camera, i.e. the light stands nearly in line with it as seen from the scene.
GRAZING_DEG = 2.0


GRAZING_SHARE = 0.10


def grazing_warnings(edges: list[EdgeResult]) -> list[str]:
    """The warning for a capture whose rays graze its shadow planes (``GRAZING_SHARE`` of the
    triangulated pixels under ``GRAZING_DEG``, over all edges), or none."""
    counted = [e.grazing for e in edges if e.grazing is not None and e.grazing[1] > 0]
    total = sum(n for _, n in counted)
    if not total:
        return []
    share = sum(f * n for f, n in counted) / total
    if share <= GRAZING_SHARE:
        return []
    return [f"{100 * share:.0f} % of the triangulated pixels see their shadow plane at under {GRAZING_DEG:g}°: "
            "the shadow planes pass close to the camera (the light stands nearly in line with it, seen from "
            f"the scene), so their depth errs over {1 / np.sin(np.radians(GRAZING_DEG)):.0f} times more than "
            "square to the plane; light the scene from farther to the side of the camera (sigma.npy gives "
            "each point's σ, [output] max_sigma drops the worst)"]
