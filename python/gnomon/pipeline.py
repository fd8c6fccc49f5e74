"""`gnomon scan`: one field log in, points, mesh, maps, report and recording out.

Data flow (docs/architecture.md): field log → :class:`~gnomon.scan_setup.ScanSetup`
(plain values and a light model, :mod:`gnomon.light`) → streaming tracker
(:func:`gnomon.tracking.track_source`, the kernel) → shadow-time maps
(entering and leaving edge) → per edge: shadow planes from the light model →
triangulation (kernel) and σZ → fusion of the edges → outlier rejection →
mesh → outputs + recording.

:func:`scan` reconstructs in memory; :func:`run_scan` also writes the outputs,
first into a staging folder on the output folder's filesystem, published as a
whole only when the scan has succeeded (:mod:`gnomon.publish`): a failed or
interrupted scan leaves no outputs behind, and a reader never sees the
previous scan's files mixed with the new ones.
"""

from __future__ import annotations

import dataclasses
import json
import queue
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from gnomon import __version__, _kernel, atomic, ply
from gnomon.calibration import camera_to_table
from gnomon.camera import Pose
from gnomon.crop import crop_mask
from gnomon.deblock import block_grid, deblock_times
from gnomon.errors import FrameError
from gnomon.fieldlog import DEFAULT_MESH_FORMATS, load_field_log
from gnomon.frames import Frame, FrameSource, sha256_file
from gnomon.fusion import beyond_trust
from gnomon.light import EdgePlanes, EdgeTimes, ReferenceGeometry
from gnomon.light.base import LightModel, Screening
from gnomon.meshing import (
    GridMesh,
    grid_mesh,
    grid_normals,
    remove_small_components,
    write_obj,
    write_stl,
    write_texture,
)
from gnomon.preview import coverage_map, write_preview
from gnomon.publish import OUTPUT_FILES, staged_outputs
from gnomon.recording import ScanRecording, playable_video, warm_rerun_import
from gnomon.reference_lines import ReferenceLines
from gnomon.retiming import ACROSS_HALF_ROWS, retime_with_sigma
from gnomon.scan_setup import ScanSetup, frame_source, resolve_scan
from gnomon.texture import LitColour, sample_indices
from gnomon.tracking import ShadowTimes, TrackedSequence, contrast_floor, linear, track_source, track_widening
from gnomon.triangulation import triangulate_depth
from gnomon.uncertainty import (
    completion_depth_sigma,
    depth_sigma,
    interpolation_time_sigma,
    linear_noise_at_threshold,
    undersampled,
)
from gnomon.validity import (
    LINE_RESIDUAL_MAX_FRAMES,
    LINE_RESIDUAL_WARN_RATIO,
    MIN_CONTRAST_SIGMAS,
    reference_line_residuals,
    unmodelled_time_scatter,
)

# Quality gates: share of the sweep's frames with a measured shadow plane (error below / warning
# below), and the longest gap (frames) to a plane over which a pixel's depth may be interpolated.
MIN_PLANE_SHARE_ERROR = 0.2
MIN_PLANE_SHARE_WARN = 0.5
MAX_PLANE_GAP = 3.0
# An edge is re-timed between its isochrones when more than this share of its timed pixels is
# under-sampled (a fast sweep: the tracker's temporal interpolation gives a staircase). On the
# simulated captures, whose sweeps are slower, re-timing the few fast pixels is not better.
RETIME_UNDERSAMPLED_SHARE = 0.5

__all__ = ["OUTPUT_FILES", "EdgeResult", "PointsReady", "RecordingWorker", "ScanOptions", "ScanResult", "Surface",
           "SurfacePoints", "build_surface", "edge_time_maps", "mesh_surface", "reconstruct", "run_scan", "scan",
           "staged_outputs", "surface_points", "write_scan", "write_surface"]

@dataclass
class ScanOptions:
    rrd: bool = True
    rrd_path: Path | None = None  # default: OUT/scan.rrd
    view: bool = False  # stream to a viewer
    progress: bool = True
    frame_stride: int = 10  # frames kept in the recording
    # The mesh's files (gnomon.fieldlog.MESH_FORMATS, mesh.ply always); None: the field log's
    # [output] mesh_formats (default mesh.ply only).
    mesh_formats: tuple[str, ...] | None = None
    # The pass over the frames: gnomon.tracking.track_source, or a drop-in with its signature
    # (gnomon.tiles.TiledTracker tracks image tiles on a Dask cluster).
    track: Callable[..., TrackedSequence] | None = None


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
    # time σ before σZ was propagated (gnomon.validity.unmodelled_time_scatter)
    unmodelled_sigma_t: float = 0.0


def ray_plane_angles(ray_map: np.ndarray, times: np.ndarray, planes: np.ndarray,
                     where: np.ndarray) -> np.ndarray:
    """Angle (degrees) between each pixel's ray and the shadow plane it was triangulated on, at ``where``.

    ``times``: (H, W) in rows of ``planes`` (N, 4) (the plane interpolated at the pixel's time, as the
    kernel does); ``ray_map``: (H, W, 3) camera-frame rays. Returns the angles of the pixels of ``where``
    (row-major), NaN where a plane is missing. The kernel computes them (``_kernel.ray_plane_angles``, the
    same f64 arithmetic); :func:`_ray_plane_angles_numpy` is the definition in numpy."""
    if len(planes) == 0:
        return _ray_plane_angles_numpy(ray_map, times, planes, where)
    return _kernel.ray_plane_angles(np.ascontiguousarray(ray_map, dtype=np.float64),
                                    np.ascontiguousarray(times, dtype=np.float64),
                                    np.ascontiguousarray(planes, dtype=np.float64),
                                    np.ascontiguousarray(where, dtype=np.uint8))


def _ray_plane_angles_numpy(ray_map: np.ndarray, times: np.ndarray, planes: np.ndarray,
                            where: np.ndarray) -> np.ndarray:
    """:func:`ray_plane_angles` in numpy (the kernel's ``ray_plane_angles`` gives the same)."""
    t = times[where].astype(np.float64)
    i = np.clip(np.floor(t).astype(np.int64), 0, len(planes) - 1)
    j = np.minimum(i + 1, len(planes) - 1)
    f = (t - i)[:, None]
    n = (1.0 - f) * planes[i, :3] + f * planes[j, :3]
    r = ray_map[where].astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        sine = np.abs(np.sum(n * r, axis=1)) / (np.linalg.norm(n, axis=1) * np.linalg.norm(r, axis=1))
    return np.degrees(np.arcsin(np.clip(sine, 0.0, 1.0)))


@dataclass
class ScanResult:
    """Everything a scan produced, in memory (the files hold the same)."""

    setup: ScanSetup
    times: ShadowTimes
    edges: list[EdgeResult]
    shadow_time: np.ndarray  # (H, W) capture frames (the fused edges' mean), NaN = none
    depth: np.ndarray  # (H, W) camera Z after fusion and outlier rejection, NaN = none
    sigma: np.ndarray  # (H, W) σZ, NaN = none
    valid: np.ndarray  # (H, W)
    undersampled: np.ndarray  # (H, W) bool
    surface: Surface
    report: dict[str, Any]
    warnings: list[str] = field(default_factory=list)
    out_dir: Path | None = None
    coverage: np.ndarray | None = None  # (H, W) uint8 classes (gnomon.preview.COVERAGE_CLASSES)

    @property
    def points_world(self) -> np.ndarray:
        """(N, 3) float32 points, world frame, row-major over valid pixels."""
        return self.surface.points_world

    @property
    def colors(self) -> np.ndarray:
        """(N, 3) uint8 RGB of each point."""
        return self.surface.colors

    @property
    def mesh(self) -> GridMesh:
        return self.surface.mesh

    @property
    def planes(self) -> np.ndarray:
        """The first edge's shadow planes (camera frame)."""
        return self.edges[0].planes

    @property
    def lines(self) -> list[ReferenceLines]:
        return self.edges[0].lines


@contextmanager
def _timed(timings: dict[str, float], key: str, cpu: dict[str, float] | None = None,
           clock: Callable[[], float] = time.process_time) -> Iterator[None]:
    """Wall time of the block into ``timings[key]``; with ``cpu``, its CPU time into ``cpu[key]``
    (``clock``: the process's, all threads, or ``time.thread_time`` for one thread's)."""
    t, c = time.perf_counter(), clock()
    yield
    timings[key] = time.perf_counter() - t
    if cpu is not None:
        cpu[key] = clock() - c


# Colour frames kept during tracking for the scan's colours (gnomon.texture).
COLOUR_SAMPLES = 5


def _colors(first_color: np.ndarray | None, first_grey: np.ndarray) -> np.ndarray:
    """Per-pixel RGB uint8 (H, W, 3) from the first frame (when no other frame was kept)."""
    rgb = first_color[:, :, ::-1] if first_color is not None else np.repeat(first_grey[:, :, None], 3, axis=2)
    if rgb.dtype == np.uint16:
        rgb = (rgb >> 8).astype(np.uint8)
    return np.ascontiguousarray(rgb, dtype=np.uint8)


class _Levels:
    """Per-pixel levels of the tracked dips in linear irradiance, each computed once per scan (both
    edges, the screening and the fusion use them)."""

    def __init__(self, tracked: TrackedSequence):
        self.tracked = tracked

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
        return _relative_depth(self.tracked, self.imax, self.imin)


def _pixel_time_sigma(slope: np.ndarray, tracked: TrackedSequence, levels: _Levels | None = None) -> np.ndarray:
    """σ of each pixel's shadow time (frames): image noise over the slope, and edge sampling."""
    levels = levels or _Levels(tracked)
    sigma_lin = levels.sigma_at_threshold
    contrast_lin = 2.0 * (levels.imax - tracked.times.threshold)
    with np.errstate(invalid="ignore", divide="ignore"):
        sigma_t_noise = np.where(slope > 0, sigma_lin / slope, np.nan)
    return np.hypot(sigma_t_noise, interpolation_time_sigma(contrast_lin, slope))


def _edge_time(name: str, times: np.ndarray, slope: np.ndarray, tracked: TrackedSequence,
               levels: _Levels | None = None, across: int = ACROSS_HALF_ROWS) -> EdgeTimes:
    """One edge's times and σ; a fast sweep's (most pixels crossed within two frames) re-timed between
    the isochrones (:mod:`gnomon.retiming`), each re-timed σ from the σ of the pixels its crossings
    were interpolated between, and the re-timed times averaged across the sweep over ±``across`` rows
    (:func:`gnomon.retiming.average_across_sweep`)."""
    levels = levels or _Levels(tracked)
    sigma = _pixel_time_sigma(slope, tracked, levels)
    grid = block_grid(times)
    if grid is not None:  # compressed video: times constant over the codec's blocks (gnomon.deblock)
        times = deblock_times(times, grid)
    fast = undersampled(slope, levels.imax, levels.imin)
    timed = np.isfinite(times)
    if timed.any() and fast[timed].mean() > RETIME_UNDERSAMPLED_SHARE:
        retimed, retimed_sigma = retime_with_sigma(times, tracked.n_frames, sigma, across=across)
        return EdgeTimes(name, retimed, slope, retimed_sigma)
    return EdgeTimes(name, times, slope, sigma)


def _edge_times(tracked: TrackedSequence, levels: _Levels | None = None,
                across: int = ACROSS_HALF_ROWS) -> tuple[EdgeTimes, EdgeTimes]:
    t, levels = tracked.times, levels or _Levels(tracked)
    return (_edge_time("enter", t.enter, t.enter_slope, tracked, levels, across),
            _edge_time("leave", t.leave, t.leave_slope, tracked, levels, across))


def edge_time_maps(tracked: TrackedSequence, edge: str = "both") -> list[np.ndarray]:
    """The shadow-time maps (H, W, frames, NaN = none) the scan measures its lines and depths on.

    The tracker's entering and leaving times after the same corrections as the
    scan's: a compressed video's block times interpolated (:mod:`gnomon.deblock`)
    and a fast sweep's times re-timed between the isochrones
    (:mod:`gnomon.retiming`). ``edge``: ``"both"`` (entering, leaving),
    ``"enter"`` or ``"leave"``. ``gnomon regions`` judges its regions on these,
    so that a staircase of under-sampled times (±0.5 frame) does not hide an
    isochrone that bends off the plane; without the scan's averaging of the
    re-timed times across the sweep (:func:`gnomon.retiming.average_across_sweep`),
    which runs along the isochrones and would smooth the very bends the regions
    look for.
    """
    enter, leave = _edge_times(tracked, across=0)
    if edge == "both":
        return [enter.times, leave.times]
    return [enter.times if edge == "enter" else leave.times]


def _with_typical_sigma(depth: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """A depth whose σ could not be propagated (no neighbouring plane for the
    derivative, no measured slope) keeps its point with the typical σ."""
    good = np.isfinite(sigma) & (sigma > 0)
    missing = np.isfinite(depth) & ~good
    if missing.any():
        typical = np.nanmedian(sigma[good]) if good.any() else 1.0
        sigma = np.where(missing, np.float32(typical), sigma)
    return sigma


def _reconstruct_edge(edge: EdgeTimes, planes: EdgePlanes, ray_map: np.ndarray, setup: ScanSetup,
                      tracked: TrackedSequence, levels: _Levels | None = None) -> EdgeResult:
    """Triangulate one edge against its shadow planes (keeping the points the light accepts), with σZ."""
    scaled = (edge.times * planes.time_scale).astype(np.float32)
    depth = triangulate_depth(ray_map, scaled, planes.planes)  # triangulate(...).depth, without the points
    if type(setup.light).screen is LightModel.screen:
        screening = Screening()  # the default keeps every point: its inputs are not computed
    else:
        screening = setup.light.screen(edge, points_from_depth(ray_map, depth), tracked.times,
                                       tracked.n_frames, *(levels or _Levels(tracked)).relative_depth,
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
                      _with_typical_sigma(depth, sigma_z), planes.degenerate, edge.slope, planes.measured,
                      screening.rejected, screening.notes, spread, grazing)


def _reconstruct_edge_checked(edge: EdgeTimes, planes: EdgePlanes, ray_map: np.ndarray, setup: ScanSetup,
                              tracked: TrackedSequence, levels: _Levels) -> tuple[EdgeResult, list[Any]]:
    """:func:`_reconstruct_edge` and its lines' residuals (:func:`_check_line_residuals` judges them), on the
    edge's own thread. The time scatter the lines show beyond the noise model
    (:func:`~gnomon.validity.unmodelled_time_scatter`) is added to every pixel's time σ first, so that σZ
    (and the fusion, the edges' agreement and ``max_sigma``, which read it) carries it."""
    residuals = [reference_line_residuals(lines, edge.sigma_t) for lines in planes.lines]
    excess = unmodelled_time_scatter(residuals)
    if excess > 0:
        edge = dataclasses.replace(edge, sigma_t=np.hypot(edge.sigma_t, np.float32(excess)).astype(np.float32))
    result = _reconstruct_edge(edge, planes, ray_map, setup, tracked, levels)
    result.unmodelled_sigma_t = excess
    return result, residuals


def _relative_depth(tracked: TrackedSequence, hi: np.ndarray, lo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) each dip's depth over its lit level, ``r = (Imax − Imin)/Imax`` in linear irradiance
    (``hi``, ``lo``: the levels Imax, Imin), and its 1σ from the image noise at both levels."""
    s_hi = linear_noise_at_threshold(tracked.noise_dn, hi, tracked.lut)
    s_lo = linear_noise_at_threshold(tracked.noise_dn, lo, tracked.lut)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(hi > 0, (hi - lo) / hi, np.nan)
        sigma = np.where(hi > 0, np.hypot(s_lo / hi, lo * s_hi / hi**2), np.nan)
    return r.astype(np.float32), sigma.astype(np.float32)


def _check_contrast(times: ShadowTimes, noise_dn: float, min_contrast: float | None, name: str) -> None:
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


def _min_contrast_dn(min_contrast: float | None, noise_dn: float) -> float:
    """The contrast floor in force (DN of the input), as the tracker applied it (:func:`contrast_floor`)."""
    return contrast_floor(min_contrast, noise_dn)


def _check_plane_coverage(edges: list[EdgeResult], path: Path, warnings: list[str]) -> None:
    """The measured shadow planes must cover the frames in which the pixels saw the shadow.

    A pixel's depth comes from the planes of the frames around its shadow
    time; where no plane was measured for many frames (the shadow missed the
    reference regions) the depth is interpolated over the gap and is
    meaningless. Points whose time falls in a gap longer than ``MAX_PLANE_GAP``
    frames are dropped; when the planes cover less than half of the sweep a
    warning says so, and below a fifth the scan is an error.
    """
    for e in edges:
        have = np.isfinite(e.planes[:, 0])
        t = e.times[np.isfinite(e.times)]
        if not e.measured or t.size == 0 or not have.any():
            continue
        lo, hi = np.percentile(t, [2, 98])
        span = np.arange(max(int(np.floor(lo)), 0), min(int(np.ceil(hi)) + 1, len(have)))
        if span.size == 0:
            continue
        share = float(have[span].mean())
        far = _far_from_planes(e.times, e.depth, have)
        if far.any():
            e.depth[far] = np.nan
            warnings.append(f"{e.name} edge: {int(far.sum())} points dropped: their shadow time is more than "
                            f"{MAX_PLANE_GAP:g} frames from any measured shadow plane")
        msg = (f"{e.name} edge: shadow planes were measured in {int(have[span].sum())} of the {span.size} frames "
               f"of the sweep ({100 * share:.0f} %); the shadow rarely crossed the [[planes]] regions")
        if share < MIN_PLANE_SHARE_ERROR:
            raise FrameError(f"{path}: {msg}: too few to scan (check the regions are bare and swept)")
        if share < MIN_PLANE_SHARE_WARN:
            warnings.append(msg)


def _plane_gap(times: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """Distance (frames) from each time to the nearest of ``frames`` (sorted, non-empty), NaN for NaN."""
    k = np.clip(np.searchsorted(frames, times), 1, max(len(frames) - 1, 1))
    with np.errstate(invalid="ignore"):
        return np.fmin(np.abs(times - frames[np.clip(k - 1, 0, len(frames) - 1)]),
                       np.abs(times - frames[np.clip(k, 0, len(frames) - 1)]))


def _far_from_planes(times: np.ndarray, depth: np.ndarray, have: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels with a depth whose time (frames) is not within ``MAX_PLANE_GAP`` frames of a
    frame with a plane (``have`` (N,) bool per frame, at least one).

    The gap is measured (:func:`_plane_gap`) only where it may exceed the bound: a time ``t`` in ``[i, i + 1)``
    is at most ``t − i < 1`` frame farther from the nearest plane than the integer frame ``i``, so the frames
    ``i`` within ``MAX_PLANE_GAP − 1`` of a plane clear all of their times at once (a few comparisons per pixel
    instead of a search).
    """
    frames = np.flatnonzero(have)
    ints = np.arange(len(have), dtype=np.float64)
    clear = _plane_gap(ints, frames) <= MAX_PLANE_GAP - 1.0
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
        far[check] = ~(_plane_gap(times[check], frames) <= MAX_PLANE_GAP)
    return far


def _check_line_residuals(edge: EdgeResult, residuals: list[Any], path: Path, warnings: list[str]) -> None:
    """The shadow lines must fit their crossings about as well as the pixel times' noise allows.

    ``residuals``: :func:`~gnomon.validity.reference_line_residuals` of each of ``edge.lines`` (with the
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


def _reconstruct_edges(setup: ScanSetup, tracked: TrackedSequence, ray_map: np.ndarray,
                       warnings: list[str], levels: _Levels | None = None) -> list[EdgeResult]:
    geometry = ReferenceGeometry(setup.camera, setup.planes, tracked.n_frames)
    levels = levels or _Levels(tracked)
    levels.imax, levels.imin, levels.sigma_at_threshold  # noqa: B018 - computed once, before the threads share them
    # The edges are independent until they are fused: one thread each (numpy and the kernel release
    # the GIL; the other core is idle once the frames are decoded). Results and errors in edge order.
    st = tracked.times
    with ThreadPoolExecutor(max_workers=2, thread_name_prefix="gnomon-edge") as pool:
        enter = pool.submit(_edge_time, "enter", st.enter, st.enter_slope, tracked, levels)
        leave = pool.submit(_edge_time, "leave", st.leave, st.leave_slope, tracked, levels)
        times = setup.light.edges(enter.result(), leave.result(), setup.edge)
        done = list(pool.map(lambda e: _reconstruct_edge_checked(e, setup.light.shadow_planes(e, geometry), ray_map,
                                                                 setup, tracked, levels), times))
    edges = [e for e, _ in done]
    for e, residuals in done:
        _check_line_residuals(e, residuals, setup.inputs.field_log, warnings)
    for e in edges:
        if e.degenerate:
            warnings.append(f"{e.name} edge: {e.degenerate} frames dropped as degenerate shadow planes")
        warnings.extend(f"{e.name} edge: {note}" for note in e.notes)
    _check_plane_coverage(edges, setup.inputs.field_log, warnings)
    n_planes = max(int(np.isfinite(e.planes[:, 0]).sum()) for e in edges)
    if n_planes < 2:
        raise FrameError(
            f"{setup.inputs.field_log}: the shadow line was found on the reference regions in {n_planes} of "
            f"{tracked.n_frames} frames; check [[planes]] regions (bare, swept by the shadow) "
            f"and [scan] min_contrast"
        )
    return edges


@dataclass
class _Fused:
    depth: np.ndarray
    sigma: np.ndarray
    keep: np.ndarray
    conflict: np.ndarray
    shadow_time: np.ndarray
    undersampled: np.ndarray
    unsupported: np.ndarray  # (H, W) a fused depth no neighbour shares (dropped)
    untrusted: np.ndarray  # (H, W) a kept point whose σ the depth-jump test cannot vouch for (counted, kept)


def _fuse(edges: list[EdgeResult], tracked: TrackedSequence, max_depth_jump: float,
          levels: _Levels | None = None) -> _Fused:
    """Fuse the edges, drop unsupported points, flag those whose σ is beyond the depth-jump test
    (:func:`gnomon.fusion.beyond_trust`), shadow time in capture frames, under-sampled points."""
    # fuse_depths then supported_by_neighbours, per pixel in the kernel (rows in parallel)
    depth, sigma, code = _kernel.fuse_supported(np.stack([e.depth for e in edges]).astype(np.float32, copy=False),
                                                np.stack([e.sigma for e in edges]).astype(np.float32, copy=False),
                                                float(max_depth_jump))
    keep, conflict, unsupported = code == 1, code == 2, code == 3
    untrusted = keep & beyond_trust(depth, sigma, max_depth_jump)
    shadow_time = _mean_ignoring_nan([e.times for e in edges])
    used = tracked.used
    if len(used) and not np.array_equal(used, np.arange(len(used))):
        # frames were skipped (clouds, night): report times as the capture's frame indices
        finite = np.isfinite(shadow_time)
        shadow_time[finite] = np.interp(shadow_time[finite], np.arange(len(used)), used)
    levels = levels or _Levels(tracked)
    imax, imin = levels.imax, levels.imin
    under = np.zeros(keep.shape, dtype=bool)
    for e in edges:
        under |= undersampled(e.slope, imax, imin) & keep
    return _Fused(depth, sigma, keep, conflict, shadow_time, under, unsupported, untrusted)


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


def _fusion_warnings(fused: _Fused) -> list[str]:
    warnings = []
    under, keep = fused.undersampled, fused.keep
    if under.mean() > 0.2 * max(keep.mean(), 1e-9):
        warnings.append(
            f"{int(under.sum())} points ({100 * under.sum() / max(keep.sum(), 1):.0f} %) are under-sampled: "
            "the shadow edge crossed them in fewer than 2 frames; sweep more slowly or film faster"
        )
    return warnings


def _frame_hook(colour: LitColour, record: Any) -> Any:
    """on_frame for the tracker: keep the colour samples, and record the frame."""
    def on_frame(frame: Frame) -> None:
        if colour.wants(frame.index):
            colour.add(frame.index, frame.color[:, :, ::-1] if frame.color is not None else frame.grey)
        if record is not None:
            record(frame)
    return on_frame


def _lit_colours(colour: LitColour, tracked: TrackedSequence) -> np.ndarray:
    """(H, W, 3) uint8: each pixel's colour from the kept frames it is lit in."""
    if not colour.indices.size or not colour.wants(int(colour.indices[0])):
        return _colors(tracked.first_color, tracked.first_grey)
    used = tracked.used
    try:
        return colour.finish(_capture_frames(tracked.times.enter, used), _capture_frames(tracked.times.leave, used))
    except ValueError:  # no kept frame arrived (a video shorter than announced)
        return _colors(tracked.first_color, tracked.first_grey)


def _capture_frames(times: np.ndarray, used: np.ndarray) -> np.ndarray:
    """(H, W) float64 capture frame of each time in kept frames (NaN = none): linear between the kept
    frames' capture indices ``used`` (``np.interp``, clamped at both ends). With no frame skipped that is
    the time itself within ``[0, n − 1]`` (``np.interp`` is exact on the identity), without a search per pixel."""
    used = np.asarray(used).astype(np.float64)
    n = len(used)
    if n and np.array_equal(used, np.arange(n)):
        return np.where(np.isfinite(times), np.clip(np.asarray(times, dtype=np.float64), 0.0, n - 1.0), np.nan)
    steps = np.arange(n, dtype=np.float64)
    return np.where(np.isfinite(times), np.interp(np.nan_to_num(times), steps, used), np.nan)


def _crop(fused: _Fused, setup: ScanSetup, ray_map: np.ndarray) -> np.ndarray:
    """Apply ``[output]``'s crop and ``max_sigma`` to the fused maps in place; returns the (H, W) pixels they
    removed."""
    cropped = np.zeros(fused.keep.shape, dtype=bool)
    if setup.crop is None:
        return cropped
    points = points_from_depth(ray_map, fused.depth)[fused.keep].astype(np.float64)
    inside = crop_mask(setup.pose.camera_to_world(points), setup.crop, setup.pose.camera_centre_world,
                       fused.sigma[fused.keep])
    cropped[fused.keep] = ~inside
    fused.keep &= ~cropped
    fused.depth[cropped] = np.nan
    fused.sigma[cropped] = np.nan
    fused.undersampled &= fused.keep
    return cropped


def scan(setup: ScanSetup, source: FrameSource, recorder: ScanRecording | RecordingWorker | None = None, *,
         progress: bool = False, frame_stride: int = 10,
         track: Callable[..., TrackedSequence] = track_source) -> ScanResult:
    """Reconstruct a surface from a capture, in memory (nothing is written but the recording).

    ``track``: the pass over the frames (:func:`~gnomon.tracking.track_source`, or a drop-in such
    as :class:`gnomon.tiles.TiledTracker`)."""
    result, record = reconstruct(setup, source, recorder, progress=progress, frame_stride=frame_stride,
                                 track=track)
    if record is not None:
        t0 = time.perf_counter() - result.report["timings_s"]["total_s"]
        _on_recorder(recorder, record)
        if isinstance(recorder, RecordingWorker):
            recorder.finish()
        result.report["timings_s"]["total_s"] = time.perf_counter() - t0
    return result


def reconstruct(setup: ScanSetup, source: FrameSource, recorder: ScanRecording | RecordingWorker | None = None, *,
                progress: bool = False, frame_stride: int = 10,
                track: Callable[..., TrackedSequence] = track_source,
                on_points: Callable[[PointsReady], None] | None = None,
                ) -> tuple[ScanResult, Callable[[ScanRecording], None] | None]:
    """:func:`scan` without its last step: the result, and the call that logs it to a recorder
    (None without ``recorder``), so that a caller can record while it writes the outputs.

    The frames are recorded as they stream by (on the :class:`RecordingWorker`'s thread when
    ``recorder`` is one); the ray map is computed on a worker thread while the frames are tracked
    (OpenCV releases the GIL). ``on_points``: called with the surface's points and maps as soon as
    they are final, before the mesh is built (:class:`PointsReady`: e.g. to start writing them);
    the returned call then logs only what its ``record`` did not.
    """
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    cpu: dict[str, float] = {}  # CPU seconds of the process (all threads) during each stage
    warnings = list(setup.warnings) + (list(recorder.notes) if recorder is not None else [])
    _on_recorder(recorder, lambda rec: _record_setup(rec, setup, source))
    skip = setup.light.skipped_frames(source.count)
    colour = LitColour(sample_indices(np.flatnonzero(~skip), COLOUR_SAMPLES))
    source.color_frames = source.color_frames | frozenset(int(i) for i in colour.indices)
    on_frame = _frame_hook(colour, None if recorder is None else _frame_logger(recorder, setup, frame_stride))
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="gnomon-ray-map") as pool:
        rays = pool.submit(setup.camera.ray_map)
        with _timed(timings, "tracking_s", cpu):
            tracked, tracker, notes = track_widening(track, source, setup.tracker,
                                                     (setup.camera.height, setup.camera.width),
                                                     dip_width=setup.dip_width, skip=skip, on_frame=on_frame,
                                                     progress=progress, where=f"{setup.inputs.field_log}: [camera]")
        setup = dataclasses.replace(setup, tracker=tracker)  # the dip width tracked with
        warnings += notes
        with _timed(timings, "ray_map_s"):  # what is left of it after tracking
            ray_map = rays.result()
    _check_contrast(tracked.times, tracked.noise_dn, setup.tracker.min_contrast, source.name)
    warnings += setup.light.after_tracking(tracked.used, tracked.skipped_dips)
    if tracked.levelled:
        more = " …" if len(tracked.levelled) > 8 else ""
        warnings.append(f"{len(tracked.levelled)} frames of sudden illumination dips (clouds) levelled pixel by "
                        f"pixel and tracked (frames {tracked.levelled[:8]}{more})")
    warnings += setup.light.choose_dips(tracked, ray_map, setup.planes, setup.max_depth_jump,
                                        _min_contrast_dn(setup.tracker.min_contrast, tracked.noise_dn))
    # The colours need only the tracked times (final from here on): combined on a thread meanwhile.
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="gnomon-colour") as colour_pool:
        colours = colour_pool.submit(_lit_colours, colour, tracked)
        with _timed(timings, "planes_and_triangulation_s", cpu):
            levels = _Levels(tracked)
            edges = _reconstruct_edges(setup, tracked, ray_map, warnings, levels)
        with _timed(timings, "fusion_and_mesh_s", cpu):
            fused = _fuse(edges, tracked, setup.max_depth_jump, levels)
            cropped = _crop(fused, setup, ray_map)
            points = surface_points(ray_map, setup.pose, fused.depth, fused.sigma, fused.keep, colours.result(),
                                    setup.max_depth_jump)
            coverage = coverage_map(tracked.times.valid, fused.keep, fused.undersampled, cropped,
                                    ambiguous=tracked.times.ambiguous, conflict=fused.conflict,
                                    unsupported=fused.unsupported)
            if on_points is not None:
                on_points(PointsReady(points, fused.shadow_time, fused.undersampled, coverage, None if recorder is None
                                      else _record_points_part(timings, setup, edges, points, fused, frame_stride,
                                                               tracked.used, coverage)))
            surface = mesh_surface(points, setup.max_depth_jump)
    warnings += _fusion_warnings(fused) + grazing_warnings(edges)
    timings["total_s"] = time.perf_counter() - t0
    report = _report(setup, source, tracked, edges, fused, surface.mesh, timings, warnings)
    _report_outputs(report, setup, cropped, cpu, warnings)
    result = ScanResult(setup, tracked.times, edges, fused.shadow_time, fused.depth, fused.sigma, fused.keep,
                        fused.undersampled, surface, report, warnings, coverage=coverage)
    if recorder is None:
        return result, None

    def record(recorder: ScanRecording) -> None:
        with _timed(timings, "recording_s", cpu, time.thread_time):  # this thread's CPU
            if on_points is None:
                _record(recorder, setup, edges, surface, fused.shadow_time, warnings, report, frame_stride,
                        tracked.used, coverage)
            else:  # the points' part was logged when they were ready
                record_mesh_part(recorder, surface, warnings,
                                 {"coverage": report["coverage"], "noise": report["noise"]})

    return result, record


@dataclass
class PointsReady:
    """What :func:`reconstruct` hands ``on_points`` before it builds the mesh: the final points and maps,
    and (with a recorder) the call that logs their part of the recording."""

    points: SurfacePoints
    shadow_time: np.ndarray  # (H, W) capture frames, NaN = none
    undersampled: np.ndarray  # (H, W) bool
    coverage: np.ndarray  # (H, W) uint8 classes
    record: Callable[[ScanRecording], None] | None


def _record_points_part(timings: dict[str, float], setup: ScanSetup, edges: list[EdgeResult], points: SurfacePoints,
                        fused: _Fused, stride: int, used: np.ndarray, coverage: np.ndarray
                        ) -> Callable[[ScanRecording], None]:
    """The recording's part that needs no mesh (its time in ``timings["recording_points_s"]``)."""
    def record(recorder: ScanRecording) -> None:
        with _timed(timings, "recording_points_s"):
            _record_scene(recorder, setup, edges, points.points_world, stride, used)
            record_points_part(recorder, points, fused.shadow_time, coverage)
    return record


def _report_outputs(report: dict[str, Any], setup: ScanSetup, cropped: np.ndarray, cpu: dict[str, float],
                    warnings: list[str]) -> None:
    """The crop, where the light knows it the site (georeferencing), the stages' CPU seconds and the warnings
    in the report."""
    report["cpu_timings_s"] = cpu
    report["warnings"] = warnings
    if setup.crop is not None:
        report["output"] = {"crop": setup.crop.to_report(), "cropped_points": int(cropped.sum())}
        report["coverage"]["cropped"] = int(cropped.sum())
    site = setup.light.georeference(setup.units)
    if site is not None:
        report["site"] = site


def write_scan(folder: Path, result: ScanResult, started: float | None = None,
               before_report: Callable[[], None] | None = None) -> None:
    """The scan's files (points, mesh, maps, report.json) into ``folder``, each atomically.

    ``started``: the ``time.perf_counter()`` when the run began, for the report's total;
    ``before_report``: called before report.json is written (e.g. to wait for the recording,
    whose timing the report gives).
    """
    t, c = time.perf_counter(), time.process_time()
    setup, surface = result.setup, result.surface
    with _Writers() as writers:
        write_surface(folder, surface, setup.units, writers, setup.mesh_formats)
        _write_maps(folder, surface, result.shadow_time, result.undersampled, result.coverage, result.report["camera"],
                    result.report.get("site"), setup.units, writers)
    _write_report(folder, result, t, c, started, before_report)


def _write_maps(folder: Path, surface: Surface | SurfacePoints, shadow_time: np.ndarray, undersampled: np.ndarray,
                coverage: np.ndarray | None, camera: dict[str, Any], site: dict[str, Any] | None, units: str,
                writers: _Writers) -> None:
    """undersampled.npy, coverage.npy, shadow_time.npy, depth.npz, preview.png, points_enu.ply (with a site)."""
    writers.add(atomic.save_npy, folder / "undersampled.npy", undersampled)
    if coverage is not None:
        writers.add(atomic.save_npy, folder / "coverage.npy", coverage)
    writers.add(atomic.save_npy, folder / "shadow_time.npy", shadow_time.astype(np.float32))
    writers.add(write_depth_npz, folder / "depth.npz", surface.depth, surface.sigma, camera, units)
    if coverage is not None:
        writers.add(write_preview, folder / "preview.png", surface.rgb, surface.depth, surface.sigma, coverage,
                    units=units)
    if site is not None:
        writers.add(write_enu_points, folder / "points_enu.ply", surface, site)


def _write_report(folder: Path, result: ScanResult, t: float, c: float, started: float | None,
                  before_report: Callable[[], None] | None) -> None:
    """report.json, once the output files (whose wait since ``t``, CPU clock ``c``, it gives) and, with
    ``before_report``, the recording are done."""
    timings, cpu = result.report["timings_s"], result.report.setdefault("cpu_timings_s", {})
    timings["outputs_s"] = time.perf_counter() - t
    cpu["outputs_s"] = time.process_time() - c
    if before_report is not None:
        with _timed(timings, "recording_wait_s"):  # the recording still being logged or encoded
            before_report()
    if started is not None:
        timings["total_s"] = time.perf_counter() - started
    atomic.write_text(folder / "report.json", json.dumps(result.report, indent=2, default=_json_default))


@dataclass
class Surface:
    """A reconstructed surface on the pixel grid: what `scan` and `merge` write."""

    depth: np.ndarray  # (H, W) camera Z, NaN = none
    sigma: np.ndarray  # (H, W) σZ, NaN = none
    valid: np.ndarray  # (H, W)
    points_world: np.ndarray  # (N, 3) float32, row-major over valid pixels
    colors: np.ndarray  # (N, 3) uint8
    uv: np.ndarray  # (N, 2) float32 pixel of each point
    mesh: GridMesh
    vertex_rgb: np.ndarray  # (V, 3) uint8
    normals: np.ndarray  # (N, 3) float32 unit normals (world frame, towards the camera)
    rgb: np.ndarray  # (H, W, 3) uint8 colour image (the mesh's texture)


@dataclass
class SurfacePoints:
    """A surface's points on the pixel grid before its mesh (:func:`surface_points`): :class:`Surface`'s
    fields but the mesh's, and the grids the mesh is built from."""

    depth: np.ndarray  # (H, W) camera Z, NaN = none
    sigma: np.ndarray  # (H, W) σZ, NaN = none
    valid: np.ndarray  # (H, W)
    points_world: np.ndarray  # (N, 3) float32, row-major over valid pixels
    colors: np.ndarray  # (N, 3) uint8
    uv: np.ndarray  # (N, 2) float32 pixel of each point
    normals: np.ndarray  # (N, 3) float32 unit normals (world frame, towards the camera)
    rgb: np.ndarray  # (H, W, 3) uint8 colour image
    world_grid: np.ndarray  # (H, W, 3) float32 world points, NaN off the surface
    normal_grid: np.ndarray  # (H, W, 3) float32 unit normals, NaN off the surface


def surface_points(ray_map: np.ndarray, pose: Pose, depth: np.ndarray, sigma: np.ndarray, valid: np.ndarray,
                   rgb: np.ndarray, max_relative_jump: float) -> SurfacePoints:
    """Points (world frame), colours and normals of the valid pixels (the mesh: :func:`mesh_surface`);
    a neighbour beyond ``max_relative_jump`` of a pixel's depth takes no part in its normal."""
    depth = np.where(valid, depth, np.nan).astype(np.float32)
    sigma = np.where(valid, sigma, np.nan).astype(np.float32)
    # points_from_depth, then pose.camera_to_world, per pixel in the kernel (rows in parallel)
    world_grid = _kernel.world_points(np.ascontiguousarray(ray_map, dtype=np.float64), depth,
                                      np.ascontiguousarray(valid, dtype=np.uint8), pose.R, pose.t)
    normals = grid_normals(world_grid, depth, valid, pose.camera_centre_world, max_relative_jump)
    index = np.flatnonzero(valid)  # the valid pixels, row-major: one gather (np.take) per array
    v, u = np.divmod(index, valid.shape[1])
    uv = np.stack([u, v], axis=1).astype(np.float32)
    return SurfacePoints(depth, sigma, valid, np.take(world_grid.reshape(-1, 3), index, axis=0),
                         np.take(rgb.reshape(-1, 3), index, axis=0), uv, np.take(normals.reshape(-1, 3), index, axis=0),
                         rgb, world_grid, normals)


def mesh_surface(points: SurfacePoints, max_relative_jump: float) -> Surface:
    """The cut grid mesh of a surface's points (:func:`gnomon.meshing.grid_mesh`, small pieces removed)."""
    mesh = remove_small_components(grid_mesh(points.world_grid, points.depth, points.valid, max_relative_jump,
                                             sigma=points.sigma, normals=points.normal_grid))
    return Surface(points.depth, points.sigma, points.valid, points.points_world, points.colors, points.uv, mesh,
                   np.take(points.rgb.reshape(-1, 3), mesh.pixel_index, axis=0), points.normals, points.rgb)


def build_surface(ray_map: np.ndarray, pose: Pose, depth: np.ndarray, sigma: np.ndarray, valid: np.ndarray,
                  rgb: np.ndarray, max_relative_jump: float) -> Surface:
    """Points (world frame), colours and the cut grid mesh of the valid pixels."""
    return mesh_surface(surface_points(ray_map, pose, depth, sigma, valid, rgb, max_relative_jump), max_relative_jump)


class _Writers:
    """Output files written on a few worker threads (numpy, the kernel, zlib and the file
    system release the GIL); leaving the ``with`` block waits for every one and re-raises the
    first failure, in the order they were added."""

    WORKERS = 3

    def __init__(self) -> None:
        self._pool = ThreadPoolExecutor(max_workers=self.WORKERS, thread_name_prefix="gnomon-writer")
        self._jobs: list[Any] = []

    def add(self, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> None:
        self._jobs.append(self._pool.submit(fn, *args, **kwargs))

    def __enter__(self) -> _Writers:
        return self

    def __exit__(self, *exc: object) -> None:
        self._pool.shutdown(wait=True)
        if exc[0] is None:
            for job in self._jobs:
                job.result()


def write_surface(folder: Path, surface: Surface, units: str, writers: _Writers | None = None,
                  mesh_formats: tuple[str, ...] = DEFAULT_MESH_FORMATS) -> None:
    """points.ply, mesh.ply, mesh.png (the colour image), depth.npy, sigma.npy and, in ``mesh_formats``,
    mesh.obj (+ .mtl) and mesh.stl (each atomically).

    ``writers``: write on its threads (waited for by its owner), else here, concurrently."""
    if writers is None:
        with _Writers() as own:
            write_surface(folder, surface, units, own, mesh_formats)
        return
    _write_mesh_files(folder, surface, units, writers, mesh_formats)  # the longest first
    _write_point_files(folder, surface, units, writers, texture="obj" not in mesh_formats)


def _write_point_files(folder: Path, points: Surface | SurfacePoints, units: str, writers: _Writers, *,
                       texture: bool) -> None:
    """points.ply, depth.npy, sigma.npy and, with ``texture``, mesh.png (else write_obj writes it)."""
    comments = [f"gnomon {__version__}", ply.units_comment(units), "frame world"]
    if texture:  # the colour image alone (load_scan's and merge's colours)
        writers.add(write_texture, folder / "mesh.png", points.rgb)
    writers.add(ply.write_points_ply, folder / "points.ply", points.points_world, points.colors,
                points.sigma[points.valid], points.uv, comments=comments, normals=points.normals)
    writers.add(atomic.save_npy, folder / "depth.npy", points.depth)
    writers.add(atomic.save_npy, folder / "sigma.npy", points.sigma)


def _write_mesh_files(folder: Path, surface: Surface, units: str, writers: _Writers,
                      mesh_formats: tuple[str, ...]) -> None:
    """mesh.ply and, in ``mesh_formats``, mesh.obj (+ .mtl, .png) and mesh.stl."""
    comments = [f"gnomon {__version__}", ply.units_comment(units), "frame world"]
    mesh = surface.mesh
    h, w = surface.valid.shape
    if "obj" in mesh_formats:
        tex_uv = (mesh.pixel_uv(w) + 0.5) / np.array([w, h], dtype=np.float32)
        tex_uv[:, 1] = 1.0 - tex_uv[:, 1]  # OBJ: v up from the image's bottom
        writers.add(write_obj, folder / "mesh.obj", mesh.vertices, mesh.faces, normals=mesh.normals, uv=tex_uv,
                    texture=surface.rgb, comment=f"gnomon {__version__}, units {units}, frame world")
    if "stl" in mesh_formats:
        writers.add(write_stl, folder / "mesh.stl", mesh.vertices, mesh.faces,
                    header=f"gnomon {__version__} mesh, units {units}")
    writers.add(ply.write_mesh_ply, folder / "mesh.ply", mesh.vertices, mesh.faces, surface.vertex_rgb,
                comments=comments, normals=mesh.normals)


def write_depth_npz(path: Path, depth: np.ndarray, sigma: np.ndarray, camera: dict[str, Any], units: str) -> None:
    """depth.npz: the depth and σ maps with the camera that makes them usable.

    ``depth``, ``sigma`` (H, W) float32 camera Z and its σ (world units, NaN =
    none); ``K`` (3, 3) and ``dist`` (k1 k2 p1 p2 k3; OpenCV; the pinhole part
    and zeros for a Tsai camera, whose own parameters are in ``camera_toml``);
    ``R`` (3, 3), ``t`` (3,) and ``rvec`` world → camera (``X_cam = R·X_world +
    t``); ``image_size`` (width, height); ``units`` the world units;
    ``camera_toml`` the camera table as report.json gives it (JSON text).
    """
    rvec = np.asarray(camera["pose"]["rvec"], dtype=np.float64)
    if "fx" in camera:
        K = np.array([[camera["fx"], 0.0, camera["cx"]], [0.0, camera["fy"], camera["cy"]], [0.0, 0.0, 1.0]])
        dist = np.asarray(camera.get("dist", [0.0] * 5), dtype=np.float64)
    else:
        K, dist = np.full((3, 3), np.nan), np.zeros(5)
    with atomic.atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, depth=depth.astype(np.float32), sigma=sigma.astype(np.float32), K=K, dist=dist,
                     R=cv2.Rodrigues(rvec)[0], t=np.asarray(camera["pose"]["tvec"], dtype=np.float64), rvec=rvec,
                     image_size=np.array(depth.shape[::-1], dtype=np.int64), units=np.array(units),
                     camera_toml=np.array(json.dumps(camera, default=_json_default)))


def write_enu_points(path: Path, surface: Surface | SurfacePoints, site: dict[str, Any]) -> None:
    """points_enu.ply: the cloud in East-North-Up metres from the site (report.json's ``site``)."""
    m = np.asarray(site["world_to_enu"], dtype=np.float64)
    enu = surface.points_world.astype(np.float64) @ m[:3, :3].T + m[:3, 3]
    comments = [f"gnomon {__version__}", ply.units_comment("m"), "frame ENU",
                f"origin latitude {site['latitude_deg']!r} longitude {site['longitude_deg']!r} "
                f"altitude {site['altitude_m']!r} (WGS84)"]
    scale = float(np.linalg.norm(m[0, :3]))  # metres per world unit
    # float32 keeps ~0.1 mm at 1 km from the site
    ply.write_points_ply(path, enu.astype(np.float32), surface.colors, surface.sigma[surface.valid] * scale,
                         surface.uv, comments=comments, normals=surface.normals @ (m[:3, :3] / scale).T)


def record_surface(recorder, surface: Surface, shadow_time: np.ndarray | None, warnings: list[str],
                   metrics: dict, coverage: np.ndarray | None = None) -> None:
    """A surface's entities in a recording: :func:`record_points_part` then :func:`record_mesh_part`."""
    record_points_part(recorder, surface, shadow_time, coverage)
    record_mesh_part(recorder, surface, warnings, metrics)


def record_points_part(recorder, surface: Surface | SurfacePoints, shadow_time: np.ndarray | None,
                       coverage: np.ndarray | None = None) -> None:
    """The depth under the camera, the coverage, the points and the maps."""
    recorder.log_camera_depth(surface.depth)
    if coverage is not None:
        recorder.log_coverage(coverage)
    recorder.log_points(surface.points_world, surface.colors, surface.sigma[surface.valid], uv=surface.uv)
    recorder.log_maps(shadow_time if shadow_time is not None else np.full(surface.depth.shape, np.nan, np.float32),
                      surface.depth, surface.sigma)


def record_mesh_part(recorder, surface: Surface, warnings: list[str], metrics: dict) -> None:
    """The mesh, the warnings and the metrics."""
    recorder.log_mesh(surface.mesh.vertices, surface.mesh.faces, surface.vertex_rgb)
    for w in warnings:
        recorder.log_warning(w)
    recorder.log_metrics(metrics)


def _mean_ignoring_nan(maps: list[np.ndarray]) -> np.ndarray:
    stack = np.stack(maps)
    n = np.isfinite(stack).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, np.nansum(stack, axis=0) / np.maximum(n, 1), np.nan).astype(np.float32)


def points_from_depth(ray_map: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """Camera-frame points (H, W, 3) on each pixel's ray at camera Z = depth."""
    return (ray_map * (depth / ray_map[..., 2])[..., None]).astype(np.float32)


def run_scan(field_log: str | Path, out_dir: str | Path, options: ScanOptions | None = None) -> ScanResult:
    """Run a scan end to end and write its outputs into ``out_dir`` (nothing there unless it succeeds).

    The recording lives on its own thread (:class:`RecordingWorker`): it is opened there (importing
    rerun) while the frames are decoded and tracked, logs and encodes the frames as they go by, and
    logs and encodes the result while the outputs are written.
    """
    opts = options or ScanOptions()
    t0 = time.perf_counter()
    if opts.rrd or opts.view:
        warm_rerun_import()
    log = load_field_log(field_log)
    source = frame_source(log)
    setup = resolve_scan(log, source)
    if opts.mesh_formats is not None:
        setup = dataclasses.replace(setup, mesh_formats=opts.mesh_formats)
    with staged_outputs(Path(out_dir), opts.rrd_path) as staging:
        full = source.video is not None and (opts.rrd or opts.view) and playable_video(source.video)
        with _recording(staging, opts, f"scan {log.path.name}", image_scale=1.0 if full else 0.5) as recorder:
            # The points' files and recording start as soon as the points are final, while the mesh is built.
            with _Writers() as writers:
                result, record = reconstruct(setup, source, recorder, progress=opts.progress,
                                             frame_stride=opts.frame_stride, track=opts.track or track_source,
                                             on_points=_point_outputs(staging, setup, writers, recorder))
                if recorder is not None and record is not None:
                    recorder.submit(record)
                    recorder.close_soon()  # encoded and written while the mesh files are
                t, c = time.perf_counter(), time.process_time()
                _write_mesh_files(staging, result.surface, setup.units, writers, setup.mesh_formats)
            _write_report(staging, result, t, c, t0, None if recorder is None else recorder.finish)
    result.out_dir = Path(out_dir)
    return result


def _point_outputs(folder: Path, setup: ScanSetup, writers: _Writers,
                   recorder: RecordingWorker | None) -> Callable[[PointsReady], None]:
    """reconstruct's ``on_points`` for run_scan: the points' part of the recording queued, the files
    that need no mesh (all but mesh.ply/.obj/.stl and report.json) handed to ``writers``."""
    def start(ready: PointsReady) -> None:
        if recorder is not None and ready.record is not None:
            recorder.submit(ready.record)
        _write_point_files(folder, ready.points, setup.units, writers, texture="obj" not in setup.mesh_formats)
        _write_maps(folder, ready.points, ready.shadow_time, ready.undersampled, ready.coverage, _camera_report(setup),
                    setup.light.georeference(setup.units), setup.units, writers)
    return start


class RecordingWorker:
    """A scan's recording on its own thread: opened there, then fed calls in order.

    ``open_recorder`` builds the :class:`~gnomon.recording.ScanRecording` (importing rerun, ≈ 1 s)
    on the worker thread, so the frames are decoded and tracked meanwhile; :meth:`submit` queues a
    call ``fn(recorder)`` (frames to log, the result to log), run in order on that thread (rerun's
    time is per thread: every log of the recording comes from this one). :meth:`finish` closes the
    recorder there (encodes and writes the file), waits, and re-raises the first failure in the
    caller's thread; :meth:`abort` waits and removes the unfinished file. After a failure the
    remaining calls are skipped. ``notes`` are the recorder's (a viewer that did not start): an
    already opened recorder can be given instead (its notes are then known at once).
    """

    def __init__(self, open_recorder: Callable[[], ScanRecording | None] | ScanRecording) -> None:
        self._queue: queue.SimpleQueue[Callable[[ScanRecording], object] | None] = queue.SimpleQueue()
        self._error: BaseException | None = None
        self._recorder: ScanRecording | None = None
        self.notes: list[str] = []
        if isinstance(open_recorder, ScanRecording):
            self._recorder = open_recorder
            self.notes = list(open_recorder.notes)
            opener = None
        else:
            opener = open_recorder
        self._done = False
        self._thread = threading.Thread(target=self._run, args=(opener,), name="gnomon-recording", daemon=True)
        self._thread.start()

    def _run(self, opener: Callable[[], ScanRecording | None] | None) -> None:
        try:
            if opener is not None:
                self._recorder = opener()
        except BaseException as exc:  # re-raised by finish, in the caller's thread
            self._error = exc
        while (task := self._queue.get()) is not None:
            if self._error is None and self._recorder is not None:
                try:
                    task(self._recorder)
                except BaseException as exc:
                    self._error = exc

    def submit(self, fn: Callable[[ScanRecording], object]) -> None:
        """Queue ``fn(recorder)`` (skipped once a call has failed)."""
        if not self._done:
            self._queue.put(fn)

    def _stop(self) -> None:
        if not self._done:
            self._done = True
            self._queue.put(None)
        self._thread.join()

    def close_soon(self) -> None:
        """Queue the recording's close after the calls queued so far: it encodes and writes the file
        on the worker thread while the caller goes on (nothing may be logged after it). rerun's
        in-memory sink encodes the whole recording only then (≈ 0.3 s of CPU for 50 MB), so a caller
        with other work left (the mesh files) saves that much of :meth:`finish`'s wait."""
        self.submit(lambda rec: rec.close())

    def finish(self) -> None:
        """Close the recording (encode and write its file), wait, re-raise the first failure."""
        if not self._done:
            self.close_soon()
        self._stop()
        if self._error is not None:
            error, self._error = self._error, None
            if self._recorder is not None:
                self._recorder.abort()
            raise error

    def abort(self) -> None:
        """Wait for the thread and drop the unfinished recording (its file is removed)."""
        self._stop()
        if self._recorder is not None:
            self._recorder.abort()


def open_recorder(staging: Path, opts: ScanOptions, name: str, filename: str = "scan.rrd", *,
                  image_scale: float = 0.5) -> ScanRecording | None:
    """The run's recording (into ``staging``), or None when neither a file nor a viewer is wanted.

    ``image_scale`` 1 when the input video is stored as it is (its frames keep their size).
    """
    if not (opts.rrd or opts.view):
        return None
    return ScanRecording(staging / filename if opts.rrd else None, recording_name=name,
                         spawn_viewer=opts.view, frame_stride=opts.frame_stride, image_scale=image_scale,
                         log_notes=False)  # the scan's warnings report them


@contextmanager
def _recording(staging: Path, opts: ScanOptions, name: str, *,
               image_scale: float = 0.5) -> Iterator[RecordingWorker | None]:
    """open_recorder on a :class:`RecordingWorker` (a viewer's recorder is opened here, for its notes),
    finished on success and aborted on failure."""
    if not (opts.rrd or opts.view):
        yield None
        return
    if opts.view:
        recorder = open_recorder(staging, opts, name, image_scale=image_scale)
        worker = RecordingWorker(recorder) if recorder is not None else None
    else:
        worker = RecordingWorker(lambda: open_recorder(staging, opts, name, image_scale=image_scale))
    try:
        yield worker
    except BaseException:
        if worker is not None:
            worker.abort()
        raise
    if worker is not None:
        worker.finish()


def _on_recorder(recorder: ScanRecording | RecordingWorker | None, fn: Callable[[ScanRecording], object]) -> None:
    """``fn(recorder)`` now, or queued on the recording's worker thread."""
    if isinstance(recorder, RecordingWorker):
        recorder.submit(fn)
    elif recorder is not None:
        fn(recorder)


def _record_setup(recorder: ScanRecording | None, setup: ScanSetup, source: FrameSource) -> None:
    if recorder is None:
        return
    cam, pose = setup.camera, setup.pose
    recorder.log_camera(cam.K, cam.width, cam.height, pose.R, pose.t, setup.units)
    if source.video is not None:
        recorder.log_video(source.video, source.count)
    setup.light.record_setup(recorder)


def _frame_logger(recorder: ScanRecording | RecordingWorker, setup: ScanSetup, stride: int) -> Any:
    """on_frame's recording part: the frame's time, and its image every ``stride`` frames (only those
    are kept until the worker has logged them)."""
    def log(frame: Frame) -> None:
        index, when = frame.index, setup.light.frame_time(frame.index)
        image = frame.grey if index % stride == 0 else None
        _on_recorder(recorder, lambda rec: rec.log_frame(index, image, when))
    return log


def _report(setup: ScanSetup, source: FrameSource, tracked: TrackedSequence, edges: list[EdgeResult],
            fused: _Fused, mesh: GridMesh, timings: dict[str, float], warnings: list[str]) -> dict[str, Any]:
    cam, inputs, tr = setup.camera, setup.inputs, setup.tracker
    times, keep, sigma = tracked.times, fused.keep, fused.sigma
    return {
        "gnomon_version": __version__,
        "field_log": str(inputs.field_log),
        "units": setup.units,
        "inputs": {
            "field_log_sha256": sha256_file(inputs.field_log),
            "frames_sha256": source.frames_digest(),
            "camera_file_sha256": sha256_file(inputs.camera_file) if inputs.camera_file else None,
            "frames": tracked.n_frames,
            "image_size": [cam.width, cam.height],
            # capture frames of sudden illumination dips (clouds) tracked levelled pixel by pixel
            "levelled_frames": [int(i) for i in tracked.levelled],
        },
        "camera": _camera_report(setup),
        "calibration": inputs.calibration,
        **setup.light.report([e.planes for e in edges], warnings),
        "settings": {
            "min_contrast_dn": _min_contrast_dn(tr.min_contrast, tracked.noise_dn),
            "min_contrast_from": ("field log" if tr.min_contrast is not None
                                  and tr.min_contrast >= MIN_CONTRAST_SIGMAS * tracked.noise_dn else "image noise"),
            "window": tr.window, "max_dip_frames": tr.max_width,
            "max_dip_frames_from": setup.dip_width, "edge": setup.edge,
            "max_depth_jump": setup.max_depth_jump, "gamma": tr.gamma,
        },
        "noise": {"image_noise_dn": tracked.noise_dn,
                  "median_sigma_z": float(np.nanmedian(sigma)) if np.isfinite(sigma).any() else None},
        "edges": _edges_report(edges, keep),
        "coverage": {
            "pixels": cam.width * cam.height,
            "contrast_ok": int(times.valid.sum()),
            "points": int(keep.sum()),
            "fraction_of_image": float(keep.mean()),
            "fraction_of_contrast_ok": float(keep.sum() / max(int(times.valid.sum()), 1)),
            "edge_conflicts": int(fused.conflict.sum()),
            # points (kept) whose σZ exceeds max_depth_jump·Z / (5·√2) (gnomon.fusion.beyond_trust)
            "sigma_beyond_jump": int(fused.untrusted.sum()),
            "undersampled": int(fused.undersampled.sum()),
            # pixels whose lit level is at the input's full scale (clipped: the shadow's edges
            # look steeper and its width narrower there)
            "saturated": int((times.imax >= len(tracked.lut) - 1).sum()),
            # pixels with two comparable dips (no point), and with clipped samples
            "ambiguous": int(np.count_nonzero(
                times.ambiguous & (times.contrast >= _min_contrast_dn(tr.min_contrast, tracked.noise_dn)))),
            "clipped": int(np.count_nonzero(times.clipped)),
            "mesh_vertices": int(len(mesh.vertices)),
            "mesh_faces": int(len(mesh.faces)),
        },
        "timings_s": timings,
        "reference_planes": inputs.reference_planes,
        **({"tracking": tracked.info} if tracked.info else {}),
    }


def _camera_report(setup: ScanSetup) -> dict[str, Any]:
    """report.json's camera: the camera table and its pose (world → camera)."""
    pose = setup.pose
    return {**camera_to_table(setup.camera), "pose": {"rvec": pose.rvec.tolist(), "tvec": pose.t.tolist()}}


def _edges_report(edges: list[EdgeResult], keep: np.ndarray) -> dict[str, Any]:
    report: dict[str, Any] = {}
    for e in edges:
        report[e.name] = {
            "shadow_planes": int(np.isfinite(e.planes[:, 0]).sum()),
            "degenerate_frames": e.degenerate,
            "rejected": e.rejected,
            "triangulated": int(np.isfinite(e.depth).sum()),
            "ray_plane_angle_deg": (None if e.ray_plane_angle_deg is None
                                    else dict(zip(("p10", "p50", "p90"), e.ray_plane_angle_deg, strict=True))),
            "grazing_share": None if e.grazing is None else e.grazing[0],  # under GRAZING_DEG
            "unmodelled_sigma_t_frames": e.unmodelled_sigma_t,
            "reference_lines": [
                {"plane": ln.plane_name, "frames_with_line": int(ln.found.sum()),
                 "extrapolated": int(ln.extrapolated.sum()),
                 "median_rms": float(np.nanmedian(ln.rms)) if ln.found.any() else None}
                for ln in e.lines
            ],
        }
    if len(edges) == 2:
        # Over the pixels where both edges were fused into an output point: a
        # pair in conflict (beyond max_depth_jump) is an outlier, not noise, and
        # is counted apart (its squared σ-distance would swamp the statistic).
        measured = np.isfinite(edges[0].depth) & np.isfinite(edges[1].depth)
        both = measured & keep
        diff = (edges[0].depth - edges[1].depth)[both]
        comb = np.sqrt(edges[0].sigma ** 2 + edges[1].sigma ** 2)[both]
        if diff.size:
            report["disagreement"] = {
                "pixels": int(both.sum()),
                "not_fused": int((measured & ~keep).sum()),
                "mean": float(np.mean(diff)),
                "rms": float(np.sqrt(np.mean(diff**2))),
                "median_abs": float(np.median(np.abs(diff))),
                "rms_in_sigmas": float(np.sqrt(np.nanmean((diff / comb) ** 2))),
            }
    return report


def _record(recorder: ScanRecording, setup: ScanSetup, edges: list[EdgeResult], surface: Surface,
            shadow_time: np.ndarray, warnings: list[str], report: dict[str, Any], stride: int,
            used: np.ndarray, coverage: np.ndarray | None = None) -> None:
    _record_scene(recorder, setup, edges, surface.points_world, stride, used)
    record_surface(recorder, surface, shadow_time, warnings, {"coverage": report["coverage"], "noise": report["noise"]},
                   coverage)


def _record_scene(recorder: ScanRecording, setup: ScanSetup, edges: list[EdgeResult], points_world: np.ndarray,
                  stride: int, used: np.ndarray) -> None:
    """The reference planes, the shadow's lines and planes every ``stride`` frames, the light's entities."""
    pose, camera, light = setup.pose, setup.camera, setup.light
    for ref in setup.planes:
        for i, (u0, v0, u1, v1) in enumerate(ref.regions):
            pix = np.array([[u0, v0], [u1, v0], [u1, v1], [u0, v1]], dtype=np.float64)
            c = ref.plane.intersect(camera.rays(pix))
            if np.all(np.isfinite(c)):
                recorder.log_reference_plane(f"{ref.name}_{i}", pose.camera_to_world(c))
    lines = edges[0].lines
    n_frames = len(lines[0].point) if lines else 0
    for t in range(0, n_frames, max(stride, 1)):
        frame = int(used[t])  # the capture's frame index (sun scans skip frames)
        when = light.frame_time(frame)
        polylines = [ln.pixels[t] for ln in lines if len(ln.pixels[t]) >= 2]
        if polylines:
            recorder.log_edges(frame, polylines, when)
        ends = [pose.camera_to_world(p) for p in (ln.plane.intersect(camera.rays(ln.pixels[t][[0, -1]]))
                                                   for ln in lines if len(ln.pixels[t]) >= 2)
                if np.all(np.isfinite(p))]
        polygon = light.shadow_plane_polygon(ends)
        if polygon is not None:
            recorder.log_shadow_plane(frame, polygon, when)
    light.record(recorder, points_world, stride)


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
