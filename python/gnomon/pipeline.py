"""`gnomon scan`: one field log in, points, mesh, maps, report and recording out.

Data flow (DESIGN.md): frames → streaming tracker (kernel) → shadow-time map →
per-frame shadow lines on the reference planes → shadow planes from the light
→ triangulation (kernel) → outlier rejection → mesh → outputs + recording.

All outputs are first written into a staging folder beside the output folder
and moved into place only when the whole scan has succeeded, each by an atomic
rename: a failed or interrupted scan leaves no outputs behind.
"""

from __future__ import annotations

import json
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gnomon import __version__, atomic, ply
from gnomon.errors import FrameError
from gnomon.fieldlog import FieldLog, load_field_log
from gnomon.frames import FrameSource, sha256_file
from gnomon.meshing import GridMesh, grid_mesh
from gnomon.progress import Progress
from gnomon.reference_lines import ReferenceLines, measure_reference_lines
from gnomon.shadow_planes import lamp_shadow_planes
from gnomon.tracking import ShadowTimes, decoding_lut
from gnomon import _kernel
from gnomon.triangulation import Triangulation, supported_by_neighbours, triangulate

OUTPUT_FILES = ("points.ply", "mesh.ply", "depth.npy", "shadow_time.npy", "report.json", "scan.rrd")


@dataclass
class ScanOptions:
    rrd: bool = True
    rrd_path: Path | None = None  # default: OUT/scan.rrd
    view: bool = False  # stream to a viewer
    progress: bool = True
    frame_stride: int = 10  # frames kept in the recording


@dataclass
class ScanResult:
    """Everything a scan produced, in memory (the files hold the same)."""

    field_log: FieldLog
    times: ShadowTimes
    shadow_time: np.ndarray  # (H, W) frames of the edge used, NaN = none
    lines: list[ReferenceLines]
    planes: np.ndarray  # (N, 4) camera frame
    triangulation: Triangulation
    depth: np.ndarray  # (H, W) camera Z after outlier rejection, NaN = none
    valid: np.ndarray  # (H, W)
    points_world: np.ndarray  # (N, 3) float32, row-major over valid pixels
    colors: np.ndarray  # (N, 3) uint8 RGB
    mesh: GridMesh
    report: dict
    warnings: list[str] = field(default_factory=list)
    out_dir: Path | None = None


def _colors(first_color: np.ndarray | None, first_grey: np.ndarray) -> np.ndarray:
    """Per-pixel RGB uint8 (H, W, 3) from the first (fully lit) frame."""
    if first_color is not None:
        rgb = first_color[:, :, ::-1]
    else:
        rgb = np.repeat(first_grey[:, :, None], 3, axis=2)
    if rgb.dtype == np.uint16:
        rgb = (rgb >> 8).astype(np.uint8)
    return np.ascontiguousarray(rgb, dtype=np.uint8)


def _track(log: FieldLog, source: FrameSource, recorder, progress: bool):
    """One streaming pass over the frames: the kernel tracker, plus recording of a subsample."""
    cam = log.camera
    tracker = None
    first_grey = first_color = None
    with Progress("tracking", source.count, enabled=progress) as bar:
        for frame in source:
            g = frame.grey
            if tracker is None:
                if g.shape != (cam.height, cam.width):
                    raise FrameError(
                        f"frame 0 ({frame.name}): size {g.shape[1]}x{g.shape[0]} differs from the "
                        f"camera's {cam.width}x{cam.height} ({log.path}: [camera])"
                    )
                dtype = "uint8" if g.dtype == np.uint8 else "uint16"
                tracker = _kernel.TemporalTracker(g.shape[0], g.shape[1], dtype=dtype, window=log.scan.window)
                first_grey, first_color = g, frame.color
            tracker.update(g)
            if recorder is not None:
                recorder.log_frame(frame.index, g)
            bar.update(frame.index + 1)
    assert tracker is not None and first_grey is not None
    n = tracker.frames_seen
    if source.expected_count is not None and n < source.expected_count:
        raise FrameError(f"{source.name}: only {n} frames, expected {source.expected_count}")
    lut = decoding_lut(log.capture.gamma, first_grey.dtype)
    times = ShadowTimes.from_kernel(tracker.finish(log.scan.min_contrast, lut))
    return times, n, first_grey, first_color


def run_scan(field_log: str | Path, out_dir: str | Path, options: ScanOptions | None = None) -> ScanResult:
    """Run a scan end to end and write its outputs into ``out_dir``."""
    opts = options or ScanOptions()
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    log = load_field_log(field_log)
    out = Path(out_dir)
    source = FrameSource(log.capture.image_files, log.capture.video, log.capture.frame_count)

    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
    try:
        result = _scan_into(log, source, staging, opts, timings, t0)
        out.mkdir(parents=True, exist_ok=True)
        for name in OUTPUT_FILES:
            if (staging / name).exists():
                target = opts.rrd_path if (name == "scan.rrd" and opts.rrd_path) else out / name
                Path(target).parent.mkdir(parents=True, exist_ok=True)
                (staging / name).replace(target)
        result.out_dir = out
        return result
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _open_recorder(log: FieldLog, staging: Path, opts: ScanOptions):
    if not (opts.rrd or opts.view):
        return None
    from gnomon.recording import ScanRecording

    return ScanRecording(
        staging / "scan.rrd" if opts.rrd else None,
        recording_name=f"scan {log.path.name}",
        spawn_viewer=opts.view,
        frame_stride=opts.frame_stride,
    )


def _scan_into(log: FieldLog, source: FrameSource, staging: Path, opts: ScanOptions,
               timings: dict[str, float], t0: float) -> ScanResult:
    warnings: list[str] = []
    cam, pose = log.camera, log.pose
    recorder = _open_recorder(log, staging, opts)
    try:
        if recorder is not None:
            recorder.log_camera(cam.K, cam.width, cam.height, pose.R, pose.t, log.capture.units)
            if log.light.position is not None:
                recorder.log_lamp(log.light.position)

        t = time.perf_counter()
        times, n_frames, first_grey, first_color = _track(log, source, recorder, opts.progress)
        timings["tracking_s"] = time.perf_counter() - t
        shadow_time = times.enter if log.scan.edge == "enter" else times.leave

        t = time.perf_counter()
        ray_map = cam.ray_map()
        timings["ray_map_s"] = time.perf_counter() - t

        t = time.perf_counter()
        lines = [measure_reference_lines(shadow_time, n_frames, p, cam, pose) for p in log.planes]
        lamp_cam = pose.world_to_camera(log.light.position)
        planes, degenerate = lamp_shadow_planes(lines, lamp_cam)
        timings["planes_s"] = time.perf_counter() - t
        n_planes = int(np.isfinite(planes[:, 0]).sum())
        if degenerate:
            warnings.append(f"{degenerate} frames dropped: the lamp is nearly on the shadow line's axis")
        if n_planes < 2:
            raise FrameError(
                f"{log.path}: the shadow line was found on the reference regions in {n_planes} of "
                f"{n_frames} frames; check [[planes]] regions (bare, swept by the shadow) and [scan] min_contrast"
            )

        t = time.perf_counter()
        tri = triangulate(ray_map, shadow_time, planes)
        keep = supported_by_neighbours(tri.depth, log.scan.max_depth_jump)
        depth = np.where(keep, tri.depth, np.nan).astype(np.float32)
        points_cam = tri.points_cam
        points_world = pose.camera_to_world(points_cam[keep].astype(np.float64)).astype(np.float32)
        rgb = _colors(first_color, first_grey)
        colors = rgb[keep]
        world_grid = np.full(points_cam.shape, np.nan, dtype=np.float32)
        world_grid[keep] = points_world
        mesh = grid_mesh(world_grid, depth, keep, log.scan.max_depth_jump)
        timings["triangulation_s"] = time.perf_counter() - t

        dropped_spikes = int(tri.valid.sum() - keep.sum())
        contrast_ok = int(times.valid.sum())
        found_lines = [int(ln.found.sum()) for ln in lines]
        line_rms = [float(np.nanmedian(ln.rms)) if ln.found.any() else None for ln in lines]
        report = {
            "gnomon_version": __version__,
            "field_log": str(log.path),
            "units": log.capture.units,
            "inputs": {
                "field_log_sha256": sha256_file(log.path),
                "frames_sha256": source.frames_digest(),
                "camera_file_sha256": sha256_file(log.camera_file) if log.camera_file else None,
                "frames": n_frames,
                "image_size": [cam.width, cam.height],
            },
            "calibration": log.calibration,
            "light": {"kind": log.light.kind, "position": log.light.position.tolist()},
            "settings": {
                "min_contrast_dn": log.scan.min_contrast,
                "window": log.scan.window,
                "edge": log.scan.edge,
                "max_depth_jump": log.scan.max_depth_jump,
                "gamma": log.capture.gamma,
            },
            "reference_lines": [
                {"plane": ln.plane_name, "frames_with_line": f, "median_rms": r}
                for ln, f, r in zip(lines, found_lines, line_rms)
            ],
            "coverage": {
                "pixels": cam.width * cam.height,
                "contrast_ok": contrast_ok,
                "with_shadow_time": int(np.isfinite(shadow_time).sum()),
                "triangulated": int(tri.valid.sum()),
                "rejected_as_spikes": dropped_spikes,
                "points": int(keep.sum()),
                "fraction_of_image": float(keep.mean()),
                "fraction_of_contrast_ok": float(keep.sum() / max(contrast_ok, 1)),
                "shadow_planes": n_planes,
                "mesh_faces": int(len(mesh.faces)),
            },
            "timings_s": timings,
            "warnings": warnings,
        }

        t = time.perf_counter()
        uv = np.stack(np.nonzero(keep)[::-1], axis=1).astype(np.float32)
        ply.write_points_ply(
            staging / "points.ply", points_world, colors, None, uv,
            comments=[f"gnomon {__version__}", f"units {log.capture.units}", "frame world"],
        )
        ply.write_mesh_ply(staging / "mesh.ply", mesh.vertices, mesh.faces, rgb.reshape(-1, 3)[mesh.pixel_index])
        atomic.save_npy(staging / "depth.npy", depth)
        atomic.save_npy(staging / "shadow_time.npy", shadow_time.astype(np.float32))
        if recorder is not None:
            for ln in lines:
                for i in np.flatnonzero(ln.found):
                    if i % max(opts.frame_stride, 1) == 0:
                        recorder.log_edges(int(i), [ln.pixels[i]])
            recorder.log_points(points_world, colors, None)
            recorder.log_mesh(mesh.vertices, mesh.faces, rgb.reshape(-1, 3)[mesh.pixel_index])
            recorder.log_maps(shadow_time, depth, None)
            for w in warnings:
                recorder.log_warning(w)
            recorder.log_metrics({k: float(v) for k, v in report["coverage"].items()})
        timings["outputs_s"] = time.perf_counter() - t
        timings["total_s"] = time.perf_counter() - t0
        atomic.write_text(staging / "report.json", json.dumps(report, indent=2, default=_json_default))
        if recorder is not None:
            recorder.close()
            recorder = None
    finally:
        if recorder is not None:
            recorder.abort() if hasattr(recorder, "abort") else None

    return ScanResult(log, times, shadow_time, lines, planes, tri, depth, keep, points_world, colors, mesh,
                      report, warnings)


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
