"""`gnomon scan`: one field log in, points, mesh, maps, report and recording out.

Data flow (DESIGN.md): frames → streaming tracker (kernel) → shadow-time maps
(entering and leaving edge) → per edge: shadow lines on the reference planes
→ shadow planes from the light → triangulation (kernel) and σZ → fusion of
the two edges → outlier rejection → mesh → outputs + recording.

All outputs are first written into a staging folder on the output folder's
filesystem and published as a whole only when the scan has succeeded
(:mod:`gnomon.publish`): a failed or interrupted scan leaves no outputs behind,
and a reader never sees the previous scan's files mixed with the new ones.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gnomon import __version__, _kernel, atomic, ply
from gnomon.calibration import camera_to_table
from gnomon.camera import Pose
from gnomon.errors import FieldLogError, FrameError, GnomonError
from gnomon.fieldlog import FieldLog, check_geometry, load_field_log
from gnomon.frames import FrameSource, sha256_file
from gnomon.fusion import fuse_depths
from gnomon.meshing import GridMesh, grid_mesh, grid_normals, remove_small_components, write_obj, write_stl
from gnomon.progress import Progress
from gnomon.publish import OUTPUT_FILES, staged_outputs  # noqa: F401  (re-exported for merge)
from gnomon.reference_lines import PlaneInCamera, ReferenceLines, measure_reference_lines
from gnomon.shadow_planes import (
    lamp_shadow_planes,
    sun_shadow_planes,
    two_plane_shadow_planes,
)
from gnomon.tracking import ShadowTimes, decoding_lut
from gnomon.triangulation import supported_by_neighbours, triangulate
from gnomon.uncertainty import (
    depth_sigma,
    image_noise_dn,
    interpolation_time_sigma,
    line_time_sigma,
    linear_noise_at_threshold,
    undersampled,
)

# Quality gates: share of the sweep's frames with a measured shadow plane (error below / warning
# below), and the longest gap (frames) to a plane over which a pixel's depth may be interpolated.
MIN_PLANE_SHARE_ERROR = 0.2
MIN_PLANE_SHARE_WARN = 0.5
MAX_PLANE_GAP = 3.0


@dataclass
class ScanOptions:
    rrd: bool = True
    rrd_path: Path | None = None  # default: OUT/scan.rrd
    view: bool = False  # stream to a viewer
    progress: bool = True
    frame_stride: int = 10  # frames kept in the recording


@dataclass
class EdgeResult:
    """One shadow edge's reconstruction (camera frame, world units)."""

    name: str  # "enter" | "leave"
    times: np.ndarray  # (H, W) frames, NaN = none
    lines: list[ReferenceLines]
    planes: np.ndarray  # (N, 4)
    depth: np.ndarray  # (H, W) camera Z, NaN = none
    sigma: np.ndarray  # (H, W) σZ
    degenerate: int
    rejected: dict[str, int] = field(default_factory=dict)  # points refused, by reason
    notes: list[str] = field(default_factory=list)  # warnings about this edge


@dataclass
class ScanResult:
    """Everything a scan produced, in memory (the files hold the same)."""

    field_log: FieldLog
    times: ShadowTimes
    edges: list[EdgeResult]
    shadow_time: np.ndarray  # (H, W) frames (the fused edges' mean), NaN = none
    depth: np.ndarray  # (H, W) camera Z after fusion and outlier rejection, NaN = none
    sigma: np.ndarray  # (H, W) σZ, NaN = none
    valid: np.ndarray  # (H, W)
    points_world: np.ndarray  # (N, 3) float32, row-major over valid pixels
    colors: np.ndarray  # (N, 3) uint8 RGB
    mesh: GridMesh
    report: dict
    warnings: list[str] = field(default_factory=list)
    out_dir: Path | None = None

    @property
    def planes(self) -> np.ndarray:
        """The first edge's shadow planes (camera frame)."""
        return self.edges[0].planes

    @property
    def lines(self) -> list[ReferenceLines]:
        return self.edges[0].lines


@dataclass
class _Tracked:
    times: ShadowTimes
    n_frames: int  # frames fed to the tracker
    first_grey: np.ndarray
    first_color: np.ndarray | None
    noise_dn: float
    lut: np.ndarray  # the tracker's decoding table (DN → linear)
    used: np.ndarray  # capture index of each tracked frame
    input_lut: np.ndarray  # the capture's decoding table, for contrast in input DN
    skipped_dips: list[int]  # capture frames skipped as illumination dips


@dataclass
class _SunContext:
    site: object
    times: object  # pd.DatetimeIndex of every capture frame
    heading_deg: float
    heading_source: str
    heading_sigma_deg: float | None
    night: np.ndarray  # bool per capture frame
    timeline: object = None  # outdoor.SunTimeline, after tracking
    gnomon_estimate: object = None  # outdoor.HeadingEstimate, when a [gnomon] is given


def _colors(first_color: np.ndarray | None, first_grey: np.ndarray) -> np.ndarray:
    """Per-pixel RGB uint8 (H, W, 3) from the first (fully lit) frame."""
    rgb = first_color[:, :, ::-1] if first_color is not None else np.repeat(first_grey[:, :, None], 3, axis=2)
    if rgb.dtype == np.uint16:
        rgb = (rgb >> 8).astype(np.uint8)
    return np.ascontiguousarray(rgb, dtype=np.uint8)


def _track(log: FieldLog, source: FrameSource, recorder, progress: bool, sun: _SunContext | None = None) -> _Tracked:
    """One streaming pass over the frames: the kernel tracker, plus recording of a subsample.

    With ``[scan] normalize_illumination`` the tracker is fed normalised linear
    irradiance (uint16) and frames in a sudden dip (a cloud, a flicker) are
    skipped; sun scans also skip frames with the sun below the horizon.
    """
    from gnomon.outdoor import LINEAR_SCALE, IlluminationNormalizer

    cam = log.camera
    normalize = log.scan.normalize_illumination
    tracker = normalizer = None
    first_grey = first_color = previous = None
    input_lut = None
    noise_samples: list[float] = []
    used: list[int] = []
    skipped_cloud: list[int] = []
    with Progress("tracking", source.count, enabled=progress) as bar:
        for frame in source:
            g = frame.grey
            if first_grey is None:
                if g.shape != (cam.height, cam.width):
                    raise FrameError(
                        f"frame 0 ({frame.name}): size {g.shape[1]}x{g.shape[0]} differs from the "
                        f"camera's {cam.width}x{cam.height} ({log.path}: [camera])"
                    )
                first_grey, first_color = g, frame.color
                input_lut = decoding_lut(log.capture.gamma, g.dtype)
                if normalize:
                    normalizer = IlluminationNormalizer(input_lut)
                dtype = "uint16" if (normalize or g.dtype != np.uint8) else "uint8"
                tracker = _kernel.TemporalTracker(g.shape[0], g.shape[1], dtype=dtype, window=log.scan.window)
            # Image noise from the first few frame pairs (cheap, and before any
            # illumination drift has accumulated).
            if previous is not None and len(noise_samples) < 4:
                noise_samples.append(image_noise_dn(previous, g))
            previous = g
            if recorder is not None:
                recorder.log_frame(frame.index, g, sun.times[frame.index] if sun is not None else None)
            bar.update(frame.index + 1)
            if sun is not None and sun.night[frame.index]:
                continue
            if normalize:
                g = normalizer.normalize(g)
                if g is None:
                    skipped_cloud.append(frame.index)
                    continue
            tracker.update(g)
            used.append(frame.index)
    assert tracker is not None and first_grey is not None and input_lut is not None
    n = source.count if source.video is None else len(used) + len(skipped_cloud)
    if source.expected_count is not None and n < source.expected_count:
        raise FrameError(f"{source.name}: only {n} frames, expected {source.expected_count}")
    if len(used) < 2:
        raise FrameError(f"{source.name}: fewer than two usable frames (sun below the horizon or clouds)")
    if normalize:
        lut = (np.arange(65536, dtype=np.float64) / LINEAR_SCALE).astype(np.float32)
        times = ShadowTimes.from_kernel(tracker.finish(0.0, lut))
        # The contrast test stays in the input's DN: back through the encoding.
        code = lambda lin: np.searchsorted(input_lut, lin.astype(np.float32))  # noqa: E731
        contrast_dn = (code(times.imax / LINEAR_SCALE) - code(times.imin / LINEAR_SCALE)).astype(np.float32)
        valid = contrast_dn >= log.scan.min_contrast
        times.enter[~valid] = np.nan
        times.leave[~valid] = np.nan
        times.valid = valid
        times.contrast = contrast_dn
    else:
        lut = input_lut
        times = ShadowTimes.from_kernel(tracker.finish(log.scan.min_contrast, lut))
    if sun is not None:
        from gnomon.outdoor import SunTimeline

        sun.timeline = SunTimeline(sun.times, np.asarray(used), skipped_cloud, list(np.flatnonzero(sun.night)))
    noise = float(np.median(noise_samples)) if noise_samples else 1.0
    _check_contrast(times, noise, log.scan.min_contrast, source.name)
    return _Tracked(times, len(used), first_grey, first_color, noise, lut, np.asarray(used), input_lut,
                    skipped_cloud)


def _check_contrast(times: ShadowTimes, noise_dn: float, min_contrast: float, name: str) -> None:
    """Only pixels whose dip stands out of the image noise are events; none at all is an error.

    Random frames have a large ``imax − imin`` everywhere but never many σ of
    their own noise; identical frames have no contrast at all.
    """
    from gnomon.validity import MIN_CONTRAST_SIGMAS, contrast_above_noise

    loud = contrast_above_noise(times.contrast, noise_dn)
    drop = times.valid & ~loud
    if drop.any():
        times.valid = times.valid & loud
        times.enter[drop] = np.nan
        times.leave[drop] = np.nan
    n_pixels = times.valid.size
    if times.valid.sum() <= 0.001 * n_pixels:
        largest = float(np.nanmax(times.contrast)) if np.isfinite(times.contrast).any() else 0.0
        if largest < min_contrast:
            why = (f"no pixel changes by min_contrast = {min_contrast:g} DN (largest change {largest:.1f} DN): "
                   "the frames are (nearly) identical, or the shadow never crossed the view")
        else:
            why = (f"the image noise is {noise_dn:.1f} DN between frames, so no pixel's dip stands "
                   f"{MIN_CONTRAST_SIGMAS:g} σ out of it: the frames look like noise, not a shadow sweep")
        raise FrameError(f"{name}: {why}")


def _check_plane_coverage(edges: list[EdgeResult], n_frames: int, path: Path, warnings: list[str]) -> None:
    """The shadow planes must cover the frames in which the pixels saw the shadow.

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
        if t.size == 0 or not have.any():
            continue
        lo, hi = np.percentile(t, [2, 98])
        span = np.arange(max(int(np.floor(lo)), 0), min(int(np.ceil(hi)) + 1, len(have)))
        if span.size == 0:
            continue
        share = float(have[span].mean())
        frames = np.flatnonzero(have)
        # distance (frames) from each pixel time to the nearest frame with a plane
        k = np.clip(np.searchsorted(frames, e.times), 1, max(len(frames) - 1, 1))
        with np.errstate(invalid="ignore"):
            gap = np.fmin(np.abs(e.times - frames[np.clip(k - 1, 0, len(frames) - 1)]),
                          np.abs(e.times - frames[np.clip(k, 0, len(frames) - 1)]))
            far = np.isfinite(e.depth) & ~(gap <= MAX_PLANE_GAP)
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


def _dn_index(values_dn: np.ndarray, lut: np.ndarray) -> np.ndarray:
    """Integer LUT indices of per-pixel DN values (NaN → 0)."""
    return np.clip(np.nan_to_num(values_dn), 0, len(lut) - 1).astype(np.int64)


def _planes_for(log: FieldLog, lines: list[ReferenceLines], pose: Pose,
                sun: _SunContext | None = None) -> tuple[np.ndarray, int]:
    """Shadow planes (camera frame) from the light model of the field log."""
    if log.light.kind == "sun":
        from gnomon.outdoor import sun_directions_camera

        assert sun is not None and sun.timeline is not None
        return sun_shadow_planes(lines, sun_directions_camera(sun.timeline, sun.site, sun.heading_deg, pose))
    if log.light.kind == "lamp":
        return lamp_shadow_planes(lines, pose.world_to_camera(log.light.position))
    if log.light.kind == "two-plane":
        return two_plane_shadow_planes(lines)
    raise GnomonError(f"{log.path}: [light] kind {log.light.kind!r} is not supported by this version")


def _pixel_time_sigma(slope: np.ndarray, tracked: _Tracked) -> np.ndarray:
    """σ of each pixel's shadow time (frames): image noise over the slope, and edge sampling."""
    times = tracked.times
    # The noise is measured in the input's DN: carry it to irradiance through the input's decoding.
    sigma_lin = linear_noise_at_threshold(tracked.noise_dn, times.threshold, tracked.input_lut)
    contrast_lin = 2.0 * (tracked.lut[_dn_index(times.imax, tracked.lut)] - times.threshold)
    with np.errstate(invalid="ignore", divide="ignore"):
        sigma_t_noise = np.where(slope > 0, sigma_lin / slope, np.nan)
    return np.hypot(sigma_t_noise, interpolation_time_sigma(contrast_lin, slope))


def _with_typical_sigma(depth: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """A depth whose σ could not be propagated (no neighbouring plane for the
    derivative, no measured slope) keeps its point with the typical σ."""
    good = np.isfinite(sigma) & (sigma > 0)
    missing = np.isfinite(depth) & ~good
    if missing.any():
        typical = np.nanmedian(sigma[good]) if good.any() else 1.0
        sigma = np.where(missing, np.float32(typical), sigma)
    return sigma


def _reconstruct_pole(tracked: _Tracked, log: FieldLog, ray_map: np.ndarray, sun: _SunContext) -> EdgeResult:
    """Sun + pole: each pixel's ray against the plane of the pole's axis and the sun at its own time."""
    from gnomon.outdoor import SUBSTEPS, pole_plane_table

    times = tracked.times
    centre = ((times.enter + times.leave) / 2).astype(np.float32)  # the shadow's centre line: the axis plane
    assert log.pole is not None and sun.timeline is not None
    table = pole_plane_table(log.pole.base, log.pole.top, sun.timeline, sun.site, sun.heading_deg, log.pose)
    scaled = (centre * SUBSTEPS).astype(np.float32)
    tri = triangulate(ray_map, scaled, table)
    # Only points where the pole's shadow can fall, lasting as long as it lasts there.
    from gnomon.outdoor import sun_directions_camera
    from gnomon.validity import (
        contrast_like_neighbours,
        event_order,
        global_event_frames,
        inside_sequence,
        not_in_global_event,
        pole_shadow_consistency,
    )

    pose = log.pose
    check = pole_shadow_consistency(points_from_depth(ray_map, tri.depth), times.enter, times.leave,
                                    sun_directions_camera(sun.timeline, sun.site, sun.heading_deg, pose),
                                    pose.world_to_camera(log.pole.base), pose.world_to_camera(log.pole.top),
                                    log.pole.radius)
    spikes = np.union1d(global_event_frames(times.enter, tracked.n_frames),
                        global_event_frames(times.leave, tracked.n_frames))
    ordered = event_order(times.enter, times.leave) & inside_sequence(times.enter, times.leave, tracked.n_frames)
    calm = not_in_global_event(times.enter, spikes) & not_in_global_event(times.leave, spikes)
    had = np.isfinite(tri.depth)
    rejected = {
        "leave_before_enter_or_at_the_ends": int((had & ~ordered).sum()),
        "global_darkening": int((had & ordered & ~calm).sum()),
        "not_on_the_pole_shadow_side": int((had & ordered & calm & ~check.shadow_side).sum()),
        "dip_duration_unlike_the_pole_shadow": int((had & ordered & calm & check.shadow_side & ~check.duration).sum()),
    }
    sound = ordered & calm & check.ok
    deep = contrast_like_neighbours(times.contrast, sound)
    rejected["dip_shallower_than_its_neighbours"] = int((had & sound & ~deep).sum())
    sound &= deep
    tri.depth[~sound] = np.nan
    notes = []
    if len(spikes):
        notes.append(f"{rejected['global_darkening']} pixels had their shadow event in frames "
                     f"{[int(f) for f in spikes[:8]]} where most of the image darkened at once (a cloud, not the "
                     "pole's shadow): no points there")
    n_had = max(int(had.sum()), 1)
    refused = n_had - int(sound.sum())
    if refused > 0.5 * n_had:
        notes.append(f"{refused} of {n_had} pixels ({100 * refused / n_had:.0f} %) were refused as not the pole's "
                     f"shadow ({', '.join(f'{k}: {v}' for k, v in rejected.items() if v)})")
    st = 0.5 * np.hypot(_pixel_time_sigma(times.enter_slope, tracked), _pixel_time_sigma(times.leave_slope, tracked))
    unc = depth_sigma(ray_map, scaled, table, tri.depth, st * SUBSTEPS, np.zeros(len(table)))
    return EdgeResult("centre", centre, [], table, tri.depth, _with_typical_sigma(tri.depth, unc.sigma_z), 0,
                      rejected, notes)


def _reconstruct_edge(name: str, times_map: np.ndarray, slope: np.ndarray, log: FieldLog, tracked: _Tracked,
                      ray_map: np.ndarray, sun: _SunContext | None = None) -> EdgeResult:
    cam, pose = log.camera, log.pose
    lines = [measure_reference_lines(times_map, tracked.n_frames, p, cam, pose, p.region_mask(times_map.shape))
             for p in log.planes]
    planes, degenerate = _planes_for(log, lines, pose, sun)
    tri = triangulate(ray_map, times_map, planes)
    sigma_t_pixel = _pixel_time_sigma(slope, tracked)
    per_plane = np.stack([line_time_sigma(ln) for ln in lines])
    with np.errstate(invalid="ignore"):
        # Several planes constrain the same shadow plane: the best-measured line dominates.
        sigma_t_line = np.nanmin(np.where(np.isfinite(per_plane), per_plane, np.inf), axis=0)
    sigma_t_line[~np.isfinite(sigma_t_line)] = np.nan
    unc = depth_sigma(ray_map, times_map, planes, tri.depth, sigma_t_pixel, sigma_t_line)
    return EdgeResult(name, times_map, lines, planes, tri.depth, _with_typical_sigma(tri.depth, unc.sigma_z),
                      degenerate)


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


def build_surface(ray_map: np.ndarray, pose: Pose, depth: np.ndarray, sigma: np.ndarray, valid: np.ndarray,
                  rgb: np.ndarray, max_relative_jump: float) -> Surface:
    """Points (world frame), colours and the cut grid mesh of the valid pixels."""
    depth = np.where(valid, depth, np.nan).astype(np.float32)
    sigma = np.where(valid, sigma, np.nan).astype(np.float32)
    points_cam = points_from_depth(ray_map, depth)
    world_grid = np.full(points_cam.shape, np.nan, dtype=np.float32)
    world_grid[valid] = pose.camera_to_world(points_cam[valid].astype(np.float64))
    normals = grid_normals(world_grid, depth, valid, pose.camera_centre_world, max_relative_jump)
    mesh = remove_small_components(grid_mesh(world_grid, depth, valid, max_relative_jump, sigma=sigma,
                                             normals=normals))
    v, u = np.nonzero(valid)
    uv = np.stack([u, v], axis=1).astype(np.float32)
    return Surface(depth, sigma, valid, world_grid[valid], rgb[valid], uv, mesh,
                   rgb.reshape(-1, 3)[mesh.pixel_index], normals[valid], rgb)


def write_surface(folder: Path, surface: Surface, units: str) -> None:
    """points.ply, mesh.ply, mesh.obj (+ .mtl, .png texture), mesh.stl, depth.npy, sigma.npy (each atomically)."""
    comments = [f"gnomon {__version__}", ply.units_comment(units), "frame world"]
    ply.write_points_ply(folder / "points.ply", surface.points_world, surface.colors,
                         surface.sigma[surface.valid], surface.uv, comments=comments, normals=surface.normals)
    mesh = surface.mesh
    ply.write_mesh_ply(folder / "mesh.ply", mesh.vertices, mesh.faces, surface.vertex_rgb,
                       comments=comments, normals=mesh.normals)
    h, w = surface.valid.shape
    tex_uv = (mesh.pixel_uv(w) + 0.5) / np.array([w, h], dtype=np.float32)
    tex_uv[:, 1] = 1.0 - tex_uv[:, 1]  # OBJ: v up from the image's bottom
    write_obj(folder / "mesh.obj", mesh.vertices, mesh.faces, normals=mesh.normals, uv=tex_uv,
              texture=surface.rgb, comment=f"gnomon {__version__}, units {units}, frame world")
    write_stl(folder / "mesh.stl", mesh.vertices, mesh.faces, header=f"gnomon {__version__} mesh, units {units}")
    atomic.save_npy(folder / "depth.npy", surface.depth)
    atomic.save_npy(folder / "sigma.npy", surface.sigma)


def record_surface(recorder, surface: Surface, shadow_time: np.ndarray | None, warnings: list[str],
                   metrics: dict) -> None:
    recorder.log_points(surface.points_world, surface.colors, surface.sigma[surface.valid], uv=surface.uv)
    recorder.log_mesh(surface.mesh.vertices, surface.mesh.faces, surface.vertex_rgb)
    recorder.log_maps(shadow_time if shadow_time is not None else np.full(surface.depth.shape, np.nan, np.float32),
                      surface.depth, surface.sigma)
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
    """Run a scan end to end and write its outputs into ``out_dir``."""
    opts = options or ScanOptions()
    t0 = time.perf_counter()
    log = load_field_log(field_log)
    for plane in log.planes:
        if not plane.has_regions:
            raise FieldLogError(f"{log.path}: [[planes]] {plane.name}: no 'regions' or 'mask' (where the plane is "
                                f"bare and swept); `gnomon regions {log.path}` proposes them")
    source = FrameSource(log.capture.image_files, log.capture.video, log.capture.frame_count)
    log, planes_report = resolve_reference_planes(log, source)
    with staged_outputs(Path(out_dir), opts.rrd_path) as staging:
        result = _scan_into(log, source, staging, opts, t0, planes_report)
    result.out_dir = Path(out_dir)
    return result


def _first_frame(source: FrameSource) -> np.ndarray:
    for frame in source:
        return frame.color if frame.color is not None else frame.grey
    raise FrameError(f"{source.name}: no frames")


def _plane_pose_from_aruco(log: FieldLog, plane, image: np.ndarray, camera, where: str):
    """A plane's pose from its ArUco markers or ChArUco board, in the world frame (no pixel hints)."""
    from gnomon.aruco import plane_pose_from_aruco, plane_pose_from_charuco
    from gnomon.frames import to_grey

    grey = to_grey(image)
    if plane.aruco is not None:
        linear = decoding_lut(log.capture.gamma, grey.dtype)[grey] if grey.dtype in (np.uint8, np.uint16) else None
        return plane_pose_from_aruco(
            grey, camera, dict(plane.aruco.markers), plane.aruco.dictionary, plane.aruco.size,
            linear=linear, to_world=plane.plane_to_world, source=where,
        )
    c = plane.charuco
    return plane_pose_from_charuco(
        grey, camera, c.dictionary, c.squares, c.square, c.marker, origin=c.origin, to_world=plane.plane_to_world, source=where,
    )


def resolve_reference_planes(log: FieldLog, source: FrameSource) -> tuple[FieldLog, list[dict]]:
    """Measure the planes that carry markers or a chessboard, each from its own.

    A plane's markers are known in its own 2-D frame (``plane_xy``, placed in
    3-D by the plane's ``point``, ``normal`` and ``x_axis``), so finding them
    in the image gives that frame's pose in the camera; a chessboard gives its
    own frame's pose. The photo is the plane's ``image`` or the capture's
    first frame. Without a ``[camera.pose]`` the first such plane's frame is
    the world frame and every other measured plane is placed in it from its
    own pose (its declared ``point``/``normal`` then only define its own
    frame); no relative pose needs typing. With a ``[camera.pose]`` the planes
    check it (residuals and the angle between measured and declared planes go
    into report.json).
    """
    from gnomon.calibration import fit_camera_to_frames, read_grey
    from gnomon.markers import fit_plane_pose, plane_pose_from_chessboard, plane_pose_from_markers

    measured_planes = [p for p in log.planes if p.markers or p.chessboard or p.aruco or p.charuco]
    if not measured_planes:
        return log, []
    first = None
    measured = []
    for plane in measured_planes:
        if plane.image is not None:
            image, name = read_grey(plane.image), plane.image.name
        else:
            first = _first_frame(source) if first is None else first
            image = first
            name = log.capture.image_files[0].name if log.capture.image_files else f"{log.capture.video} frame 0"
        where = f"{log.path}: [[planes]] {plane.name}: {name}"
        # A plane's own photo may be a still at another resolution of the same sensor.
        camera, _ = fit_camera_to_frames(log.camera, image.shape[1], image.shape[0], f"{log.path}: [camera]", name)
        if plane.aruco is not None or plane.charuco is not None:
            pp = _plane_pose_from_aruco(log, plane, image, camera, where)
        elif plane.markers:
            names = [f"{plane.name} marker {m.id}" for m in plane.markers]
            pixels = np.array([m.pixel_hint for m in plane.markers])
            if all(m.exact for m in plane.markers):
                pp = fit_plane_pose(camera, plane.marker_world(), pixels, names=names, method="pixels",
                                    source=where)
            else:
                exact = np.array([m.exact for m in plane.markers])
                pp = plane_pose_from_markers(image, camera, plane.marker_world(), pixels, names=names,
                                             source=where, exact=exact)
        else:
            pp = plane_pose_from_chessboard(image, camera, plane.chessboard, plane.square, source=where)
        measured.append((plane, pp))
    declared = log.pose is not None
    pose = log.pose if declared else measured[0][1].pose
    report = []
    placed = {}
    for plane, pp in measured:
        entry = {"plane": plane.name, **pp.to_report(), "pixels": pp.pixels.tolist()}
        if declared:
            declared_cam = pose.R @ plane.normal
            cosang = abs(float(declared_cam @ pp.normal_cam))
            entry["angle_to_declared_deg"] = float(np.degrees(np.arccos(min(1.0, cosang))))
        else:
            # The plane in the world frame, from its own pose: its frame's origin and normal.
            origin_cam = pp.pose.world_to_camera(plane.point)
            normal_cam = pp.pose.R @ plane.normal
            placed[plane.name] = (pose.camera_to_world(origin_cam), pose.R.T @ normal_cam,
                                  None if plane.x_axis is None else pose.R.T @ (pp.pose.R @ plane.x_axis))
            entry["world_point"] = placed[plane.name][0].tolist()
            entry["world_normal"] = placed[plane.name][1].tolist()
        report.append(entry)
    if not declared:
        planes = []
        for p in log.planes:
            if p.name in placed and (p.markers or p.chessboard or p.aruco or p.charuco):
                point, normal, x_axis = placed[p.name]
                p = dataclasses.replace(p, point=point, normal=normal / np.linalg.norm(normal), x_axis=x_axis)
            planes.append(p)
        log = dataclasses.replace(log, pose=pose, planes=tuple(planes))
        check_geometry(log, pose)
        if len(measured) >= 2:
            a, b = measured[0][1], measured[1][1]
            report[1]["angle_to_first_deg"] = float(np.degrees(np.arccos(min(1.0, abs(float(a.normal_cam @ b.normal_cam))))))
    return log, report


def open_recorder(staging: Path, opts: ScanOptions, name: str, filename: str = "scan.rrd"):
    if not (opts.rrd or opts.view):
        return None
    from gnomon.recording import ScanRecording

    return ScanRecording(staging / filename if opts.rrd else None, recording_name=name,
                         spawn_viewer=opts.view, frame_stride=opts.frame_stride)


def _sun_context(log: FieldLog, source: FrameSource, warnings: list[str]) -> _SunContext:
    """Frame times, the heading of the world frame, and the frames with the sun up."""
    from gnomon.outdoor import below_horizon, capture_times, heading_from_gnomon, site_of

    site = site_of(log)
    times = capture_times(log, source.count)
    if len(times) != source.count:
        raise FrameError(f"{log.path}: {len(times)} timestamps for {source.count} frames")
    night = below_horizon(times, site)
    if night.all():
        raise GnomonError(f"{log.path}: the sun is below the horizon at every frame "
                          f"({times[0].isoformat()} … {times[-1].isoformat()}); check [site] and the timestamps")
    heading, source_name, sigma = log.site.heading_deg, "[site] heading_deg", None
    if log.gnomon is not None:
        est = heading_from_gnomon(log, log.pose, times, site)
        if heading is None:
            heading, source_name, sigma = est.heading_deg, f"gnomon in {est.frame}", est.sigma_deg
        else:
            diff = (est.heading_deg - heading + 180.0) % 360.0 - 180.0
            if abs(diff) > max(3 * est.sigma_deg, 0.5):
                warnings.append(f"the gnomon gives a heading of {est.heading_deg:.2f}° ± {est.sigma_deg:.2f}°, "
                                f"[site] heading_deg says {heading:.2f}°")
        return _SunContext(site, times, float(heading), source_name, sigma, night, gnomon_estimate=est)
    return _SunContext(site, times, float(heading), source_name, None, night)


def _note_skipped_frames(sun: _SunContext, warnings: list[str]) -> None:
    tl = sun.timeline
    if tl.skipped_night:
        warnings.append(f"{len(tl.skipped_night)} frames skipped: the sun is below the horizon "
                        f"(first {sun.times[tl.skipped_night[0]].isoformat()})")
    if tl.skipped_cloud:
        warnings.append(f"{len(tl.skipped_cloud)} frames skipped as cloud dips (frames {tl.skipped_cloud[:8]}"
                        f"{' …' if len(tl.skipped_cloud) > 8 else ''})")


def _scan_into(log: FieldLog, source: FrameSource, staging: Path, opts: ScanOptions, t0: float,
               planes_report: list[dict]) -> ScanResult:
    timings: dict[str, float] = {}
    warnings: list[str] = []
    cam, pose = log.camera, log.pose
    recorder = open_recorder(staging, opts, f"scan {log.path.name}")
    try:
        if recorder is not None:
            recorder.log_camera(cam.K, cam.width, cam.height, pose.R, pose.t, log.capture.units)
            if log.light.position is not None:
                recorder.log_lamp(log.light.position)

        sun = _sun_context(log, source, warnings) if log.light.kind == "sun" else None
        t = time.perf_counter()
        tracked = _track(log, source, recorder, opts.progress, sun)
        times = tracked.times
        timings["tracking_s"] = time.perf_counter() - t
        if sun is not None:
            _note_skipped_frames(sun, warnings)
        elif tracked.skipped_dips:
            warnings.append(f"{len(tracked.skipped_dips)} frames skipped as sudden illumination dips "
                            f"(frames {tracked.skipped_dips[:8]}{' …' if len(tracked.skipped_dips) > 8 else ''})")

        t = time.perf_counter()
        ray_map = cam.ray_map()
        timings["ray_map_s"] = time.perf_counter() - t

        t = time.perf_counter()
        edges = []
        if sun is not None and log.pole is not None:
            edges.append(_reconstruct_pole(tracked, log, ray_map, sun))
        else:
            wanted = ("enter", "leave") if log.scan.edge == "both" else (log.scan.edge,)
            for name in wanted:
                tmap, slope = (times.enter, times.enter_slope) if name == "enter" else (times.leave, times.leave_slope)
                edges.append(_reconstruct_edge(name, tmap, slope, log, tracked, ray_map, sun))
        timings["planes_and_triangulation_s"] = time.perf_counter() - t
        for e in edges:
            if e.degenerate:
                warnings.append(f"{e.name} edge: {e.degenerate} frames dropped as degenerate shadow planes")
            warnings.extend(f"{e.name} edge: {note}" for note in e.notes)
        n_planes = max(int(np.isfinite(e.planes[:, 0]).sum()) for e in edges)
        if not (sun is not None and log.pole is not None):
            _check_plane_coverage(edges, tracked.n_frames, log.path, warnings)
        if n_planes < 2:
            raise FrameError(
                f"{log.path}: the shadow line was found on the reference regions in {n_planes} of "
                f"{tracked.n_frames} frames; check [[planes]] regions (bare, swept by the shadow) "
                f"and [scan] min_contrast"
            )

        t = time.perf_counter()
        depth, sigma, conflict = fuse_depths([e.depth for e in edges], [e.sigma for e in edges],
                                             log.scan.max_depth_jump)
        keep = supported_by_neighbours(depth, log.scan.max_depth_jump)
        depth = np.where(keep, depth, np.nan).astype(np.float32)
        sigma = np.where(keep, sigma, np.nan).astype(np.float32)
        shadow_time = _mean_ignoring_nan([e.times for e in edges])
        if len(tracked.used) and not np.array_equal(tracked.used, np.arange(len(tracked.used))):
            # frames were skipped (clouds, night): report times as the capture's frame indices
            finite = np.isfinite(shadow_time)
            shadow_time[finite] = np.interp(shadow_time[finite], np.arange(len(tracked.used)), tracked.used)
        rgb = _colors(tracked.first_color, tracked.first_grey)
        surface = build_surface(ray_map, pose, depth, sigma, keep, rgb, log.scan.max_depth_jump)
        timings["fusion_and_mesh_s"] = time.perf_counter() - t

        lut = tracked.lut
        under = np.zeros(keep.shape, dtype=bool)
        for e in edges:
            slope = times.enter_slope if e.name == "enter" else times.leave_slope
            imax, imin = lut[_dn_index(times.imax, lut)], lut[_dn_index(times.imin, lut)]
            under |= undersampled(slope, imax, imin) & keep
        report = _report(log, source, tracked, edges, depth, sigma, keep, conflict, under, surface.mesh, timings,
                         warnings)
        report["reference_planes"] = planes_report
        if sun is not None:
            est = sun.gnomon_estimate
            report["sun"] = {
                "heading_deg": sun.heading_deg, "heading_source": sun.heading_source,
                "heading_sigma_deg": sun.heading_sigma_deg,
                "gnomon_heading_deg": est.heading_deg if est else None,
                "gnomon_heading_sigma_deg": est.sigma_deg if est else None,
                "frames_used": int(len(tracked.used)),
                "skipped_cloud": [int(i) for i in sun.timeline.skipped_cloud],
                "skipped_night": [int(i) for i in sun.timeline.skipped_night],
                "first_frame_utc": sun.times[0].isoformat(), "last_frame_utc": sun.times[-1].isoformat(),
                "mode": "pole" if log.pole is not None else "reference lines",
            }
        if under.mean() > 0.2 * max(keep.mean(), 1e-9):
            warnings.append(
                f"{int(under.sum())} points ({100 * under.sum() / max(keep.sum(), 1):.0f} %) are under-sampled: "
                "the shadow edge crossed them in fewer than 2 frames; sweep more slowly or film faster"
            )

        t = time.perf_counter()
        write_surface(staging, surface, log.capture.units)
        atomic.save_npy(staging / "undersampled.npy", under)
        atomic.save_npy(staging / "shadow_time.npy", shadow_time.astype(np.float32))
        if recorder is not None:
            _record(recorder, log, edges, surface, shadow_time, warnings, report, opts.frame_stride, tracked.used,
                    sun)
        timings["outputs_s"] = time.perf_counter() - t
        timings["total_s"] = time.perf_counter() - t0
        report["warnings"] = warnings
        atomic.write_text(staging / "report.json", json.dumps(report, indent=2, default=_json_default))
        if recorder is not None:
            recorder.close()
            recorder = None
    finally:
        if recorder is not None:
            recorder.abort()

    return ScanResult(log, times, edges, shadow_time, depth, sigma, keep, surface.points_world, surface.colors,
                      surface.mesh, report, warnings)


def _count(mask, within=None) -> int | None:
    if mask is None:
        return None
    return int(np.count_nonzero(mask if within is None else (mask & within)))


def _report(log: FieldLog, source: FrameSource, tracked: _Tracked, edges: list[EdgeResult], depth: np.ndarray,
            sigma: np.ndarray, keep: np.ndarray, conflict: np.ndarray, under: np.ndarray, mesh: GridMesh,
            timings: dict, warnings: list[str]) -> dict:
    cam, pose = log.camera, log.pose
    times = tracked.times
    report: dict = {
        "gnomon_version": __version__,
        "field_log": str(log.path),
        "units": log.capture.units,
        "inputs": {
            "field_log_sha256": sha256_file(log.path),
            "frames_sha256": source.frames_digest(),
            "camera_file_sha256": sha256_file(log.camera_file) if log.camera_file else None,
            "frames": tracked.n_frames,
            "image_size": [cam.width, cam.height],
        },
        "camera": {**camera_to_table(cam), "pose": {"rvec": pose.rvec.tolist(), "tvec": pose.t.tolist()}},
        "calibration": log.calibration,
        "light": {"kind": log.light.kind,
                  "position": None if log.light.position is None else log.light.position.tolist()},
        "settings": {
            "min_contrast_dn": log.scan.min_contrast, "window": log.scan.window, "edge": log.scan.edge,
            "max_depth_jump": log.scan.max_depth_jump, "gamma": log.capture.gamma,
        },
        "noise": {"image_noise_dn": tracked.noise_dn,
                  "median_sigma_z": float(np.nanmedian(sigma)) if np.isfinite(sigma).any() else None},
        "edges": {},
        "coverage": {
            "pixels": cam.width * cam.height,
            "contrast_ok": int(times.valid.sum()),
            "points": int(keep.sum()),
            "fraction_of_image": float(keep.mean()),
            "fraction_of_contrast_ok": float(keep.sum() / max(int(times.valid.sum()), 1)),
            "edge_conflicts": int(conflict.sum()),
            "undersampled": int(under.sum()),
            # pixels whose brightest sample is at the input's full scale (clipped: the shadow's
            # edges look steeper and its width narrower there); None when the tracker saw
            # normalised irradiance instead of the input's DN
            "saturated": (int((times.imax >= len(tracked.input_lut) - 1).sum())
                          if not log.scan.normalize_illumination else None),
            # pixels with two comparable dips (no point), and with clipped samples, when the
            # tracker reports them
            "ambiguous": _count(getattr(times, "ambiguous", None), times.contrast >= log.scan.min_contrast),
            "clipped": _count(getattr(times, "clipped", None)),
            "mesh_vertices": int(len(mesh.vertices)),
            "mesh_faces": int(len(mesh.faces)),
        },
        "timings_s": timings,
    }
    for e in edges:
        report["edges"][e.name] = {
            "shadow_planes": int(np.isfinite(e.planes[:, 0]).sum()),
            "degenerate_frames": e.degenerate,
            "rejected": e.rejected,
            "triangulated": int(np.isfinite(e.depth).sum()),
            "reference_lines": [
                {"plane": ln.plane_name, "frames_with_line": int(ln.found.sum()),
                 "extrapolated": int(ln.extrapolated.sum()),
                 "median_rms": float(np.nanmedian(ln.rms)) if ln.found.any() else None}
                for ln in e.lines
            ],
        }
    if log.light.kind == "two-plane":
        # Every shadow plane of a point source, of either edge, passes through it.
        planes = np.concatenate([e.planes for e in edges])
        if np.isfinite(planes[:, 0]).sum() >= 3:
            from gnomon.validity import MIN_LAMP_CONDITIONING, light_point_or_line

            est = light_point_or_line(planes)
            report["light"]["estimated_position_conditioning"] = est.conditioning
            if est.degenerate:
                # The planes share one direction (a stick moved parallel to itself): they fix the
                # lamp only along a line through the least-squares point, along that direction.
                report["light"]["estimated_position"] = None
                report["light"]["estimated_line"] = {
                    "point": pose.camera_to_world(est.point).tolist(),
                    "direction": (pose.R.T @ est.direction).tolist(),
                    "reason": (f"the shadow planes all contain nearly one direction (singular-value ratio "
                               f"{est.conditioning:.4f} < {MIN_LAMP_CONDITIONING}): the lamp lies on a line, "
                               "not at a point"),
                }
                warnings.append(f"lamp estimate is degenerate: the shadow planes share one direction (ratio "
                                f"{est.conditioning:.4f}); report.json gives the line the lamp lies on, not a point")
            else:
                report["light"]["estimated_position"] = pose.camera_to_world(est.point).tolist()
                report["light"]["estimated_position_plane_rms"] = est.plane_rms
    if len(edges) == 2:
        # Over the pixels where both edges were fused into an output point: a
        # pair in conflict (beyond max_depth_jump) is an outlier, not noise, and
        # is counted apart (its squared σ-distance would swamp the statistic).
        measured = np.isfinite(edges[0].depth) & np.isfinite(edges[1].depth)
        both = measured & keep
        diff = (edges[0].depth - edges[1].depth)[both]
        comb = np.sqrt(edges[0].sigma ** 2 + edges[1].sigma ** 2)[both]
        if diff.size:
            report["edges"]["disagreement"] = {
                "pixels": int(both.sum()),
                "not_fused": int((measured & ~keep).sum()),
                "mean": float(np.mean(diff)),
                "rms": float(np.sqrt(np.mean(diff**2))),
                "median_abs": float(np.median(np.abs(diff))),
                "rms_in_sigmas": float(np.sqrt(np.nanmean((diff / comb) ** 2))),
            }
    return report


def _record(recorder, log: FieldLog, edges: list[EdgeResult], surface: "Surface", shadow_time: np.ndarray,
            warnings: list[str], report: dict, stride: int, used: np.ndarray,
            sun: _SunContext | None = None) -> None:
    pose = log.pose
    first = edges[0]
    for spec in log.planes:
        plane = PlaneInCamera.from_world(spec.point, spec.normal, pose)
        for i, (u0, v0, u1, v1) in enumerate(spec.regions):
            pix = np.array([[u0, v0], [u1, v0], [u1, v1], [u0, v1]], dtype=np.float64)
            c = plane.intersect(log.camera.rays(pix))
            if np.all(np.isfinite(c)):
                recorder.log_reference_plane(f"{spec.name}_{i}", pose.camera_to_world(c))
    n_frames = len(first.lines[0].point) if first.lines else 0
    for t in range(0, n_frames, max(stride, 1)):
        frame = int(used[t])  # the capture's frame index (sun scans skip frames)
        when = sun.times[frame] if sun is not None else None
        polylines = [ln.pixels[t] for ln in first.lines if len(ln.pixels[t]) >= 2]
        if polylines:
            recorder.log_edges(frame, polylines, when)
        ends = []
        for ln in first.lines:
            if len(ln.pixels[t]) >= 2:
                p = ln.plane.intersect(log.camera.rays(ln.pixels[t][[0, -1]]))
                if np.all(np.isfinite(p)):
                    ends.append(pose.camera_to_world(p))
        if ends and log.light.position is not None:
            a, b = ends[0]
            s = log.light.position
            recorder.log_shadow_plane(frame, np.array([a, b, b + 0.6 * (s - b), a + 0.6 * (s - a)]), when)
        elif len(ends) >= 2:
            recorder.log_shadow_plane(frame, np.array([ends[0][0], ends[0][1], ends[1][1], ends[1][0]]), when)
    if sun is not None:
        from gnomon.outdoor import sun_world

        anchor = log.pole.base if log.pole is not None else np.nanmean(surface.points_world, axis=0)
        extent = float(np.nanmax(np.ptp(surface.points_world, axis=0))) if len(surface.points_world) else 1.0
        for k in range(0, len(sun.times), max(stride, 1)):
            d = sun_world(sun.times[k:k + 1], sun.site, sun.heading_deg)[0]
            recorder.log_sun(k, d, anchor, 0.5 * extent, sun.times[k])
    record_surface(recorder, surface, shadow_time, warnings, {"coverage": report["coverage"], "noise": report["noise"]})


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
