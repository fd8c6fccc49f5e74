"""What a scan logs into its recording: the set-up, the frames, the scene's lines and planes, the surface.

Each function takes a :class:`~gnomon.recording.recorder.ScanRecording` and plain values; the scan hands
them to its recorder (:class:`~gnomon.recording.worker.RecordingWorker` runs them on its thread).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from gnomon.capture.frames import Frame, FrameSource
from gnomon.capture.registration import Registration
from gnomon.config.setup import ScanSetup
from gnomon.errors import Remark
from gnomon.geometry.surface import Surface, SurfacePoints
from gnomon.reconstruct.edges import EdgeResult
from gnomon.reconstruct.fused import FusedMaps
from gnomon.recording.recorder import ScanRecording
from gnomon.recording.worker import Recorder
from gnomon.util.timing import timed


def record_setup(recorder: ScanRecording | None, setup: ScanSetup, source: FrameSource) -> None:
    if recorder is None:
        return
    cam, pose = setup.camera, setup.pose
    recorder.log_camera(cam.K, cam.width, cam.height, pose.R, pose.t, setup.units)
    if source.video is not None:
        recorder.log_video(source.video, source.count)
    setup.light.record_setup(recorder)


def frame_logger(recorder: Recorder, setup: ScanSetup, stride: int) -> Any:
    """on_frame's recording part: the frame's time, and its image every ``stride`` frames (only those
    are kept until the worker has logged them)."""
    def log(frame: Frame) -> None:
        index, when = frame.index, setup.light.frame_time(frame.index)
        image = frame.grey if index % stride == 0 else None
        recorder.submit(lambda rec: rec.log_frame(index, image, when))
    return log


def record_registration(recorder: ScanRecording, registration: Registration) -> None:
    """Each measured frame's motion against the reference frame, on the frame timeline:
    ``metrics/registration/{dx_px, dy_px, sigma_px, non_translation_px}``."""
    r = registration
    for i in map(int, np.flatnonzero(r.measured)):
        recorder.log_metrics({"registration": {"dx_px": float(r.motion_px[i, 0]), "dy_px": float(r.motion_px[i, 1]),
                                               "sigma_px": float(r.sigma_px[i]),
                                               "non_translation_px": float(r.non_translation_px[i])}}, index=i)


def points_part_recorder(timings: dict[str, float], setup: ScanSetup, edges: list[EdgeResult], points: SurfacePoints,
                        fused: FusedMaps, stride: int, used: np.ndarray, coverage: np.ndarray
                        ) -> Callable[[ScanRecording], None]:
    """The recording's part that needs no mesh (its time in ``timings["recording_points_s"]``)."""
    def record(recorder: ScanRecording) -> None:
        with timed(timings, "recording_points_s"):
            record_scene(recorder, setup, edges, points.points_world, stride, used)
            record_points_part(recorder, points, fused.shadow_time, coverage)
    return record


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
    """The mesh (a ``full`` recording's: :meth:`~gnomon.recording.recorder.ScanRecording.log_mesh`), the
    warnings and the metrics."""
    recorder.log_mesh(surface.mesh.vertices, surface.mesh.faces, surface.vertex_rgb)
    for w in warnings:  # a Remark (a fact, nothing to do) as information, the others as warnings
        recorder.log_warning(w, level="INFO" if isinstance(w, Remark) else "WARN")
    recorder.log_metrics(metrics)


def record_scan(recorder: ScanRecording, setup: ScanSetup, edges: list[EdgeResult], surface: Surface,
            shadow_time: np.ndarray, warnings: list[str], report: dict[str, Any], stride: int,
            used: np.ndarray, coverage: np.ndarray | None = None) -> None:
    record_scene(recorder, setup, edges, surface.points_world, stride, used)
    record_surface(recorder, surface, shadow_time, warnings, {"coverage": report["coverage"], "noise": report["noise"]},
                   coverage)


def record_scene(recorder: ScanRecording, setup: ScanSetup, edges: list[EdgeResult], points_world: np.ndarray,
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
