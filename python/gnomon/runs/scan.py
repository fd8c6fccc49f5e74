"""`gnomon scan`: one field log in, points, mesh, maps, report and recording out.

Data flow (docs/architecture.md): field log → :class:`~gnomon.config.setup.ScanSetup`
(plain values and a light model, :mod:`gnomon.light`) → streaming tracker
(:func:`gnomon.capture.tracking.track_source`, the kernel) → shadow-time maps
(entering and leaving edge) → per edge: shadow planes from the light model →
triangulation (kernel) and σZ → fusion of the edges → outlier rejection →
mesh → outputs + recording.

:func:`scan` reconstructs in memory; :func:`run_scan` also writes the outputs,
first into a staging folder on the output folder's filesystem, published as a
whole only when the scan has succeeded (:mod:`gnomon.outputs.publish`): a failed or
interrupted scan leaves no outputs behind, and a reader never sees the
previous scan's files mixed with the new ones.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gnomon.capture.colours import COLOUR_SAMPLES, frame_hook, lit_colours
from gnomon.capture.frames import FrameSource, dropped_frames_warning
from gnomon.capture.texture import LitColour, sample_indices
from gnomon.capture.tracking import ShadowTimes, TrackedSequence, track_source, track_widening
from gnomon.config.fieldlog import load_field_log
from gnomon.config.setup import ScanSetup, frame_source, resolve_scan
from gnomon.config.specs import FieldLog
from gnomon.errors import GnomonError, Remark
from gnomon.geometry.meshing import GridMesh
from gnomon.geometry.reference_lines import ReferenceLines
from gnomon.geometry.surface import Surface, SurfacePoints, mesh_faces, mesh_surface, surface_points
from gnomon.outputs.formats import OutputContext
from gnomon.outputs.images import coverage_map
from gnomon.outputs.publish import staged_outputs
from gnomon.outputs.scan_files import (
    write_maps,
    write_mesh_files,
    write_point_files,
    write_report,
    write_surface,
    writes_texture,
)
from gnomon.outputs.writers import Writers
from gnomon.reconstruct.bare import hold_regions
from gnomon.reconstruct.corners import tie_planes
from gnomon.reconstruct.edges import (
    EdgeResult,
    Levels,
    check_contrast,
    edge_time_maps,
    grazing_warnings,
    min_contrast_dn,
    reconstruct_edges,
)
from gnomon.reconstruct.fused import crop_fused, fuse_edges, fusion_warnings, screen_direct_light
from gnomon.reconstruct.report import camera_report, report_outputs, scan_report
from gnomon.recording.recorder import ScanRecording, playable_video, warm_rerun_import
from gnomon.recording.scan_log import (
    frame_logger,
    points_part_recorder,
    record_mesh_part,
    record_registration,
    record_scan,
    record_setup,
)
from gnomon.recording.worker import Recorder, RecordingWorker, recording
from gnomon.util.progress import Stages
from gnomon.util.timing import timed

__all__ = ["PointsReady", "ScanOptions", "ScanResult", "prepare_scan", "reconstruct", "run_scan", "scan", "write_scan"]


@dataclass
class ScanOptions:
    rrd: bool = True
    rrd_path: Path | None = None  # default: OUT/scan.rrd
    view: bool = False  # stream to a viewer
    progress: bool = True
    frame_stride: int = 10  # frames kept in the recording
    # The recording also holds the mesh and the maps at full size (by default: the points at full size, the
    # maps at the stored frames' size, no mesh; mesh.ply and the .npy files hold them).
    rrd_full: bool = False
    # The mesh's files (gnomon.outputs.formats, mesh.ply always); None: the field log's
    # [output] mesh_formats (default mesh.ply only).
    mesh_formats: tuple[str, ...] | None = None
    # The cloud's survey files (las, laz); None: the field log's [output] cloud_formats (default: LAZ for a
    # georeferenced scan, none for a desk scan). crs: theirs (None: the field log's [output] crs, else UTM).
    cloud_formats: tuple[str, ...] | None = None
    crs: str | None = None
    # The pass over the frames: gnomon.capture.tracking.track_source, or a drop-in with its signature
    # (gnomon.capture.tiles.TiledTracker tracks image tiles on a Dask cluster).
    track: Callable[..., TrackedSequence] | None = None


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
    coverage: np.ndarray | None = None  # (H, W) uint8 classes (gnomon.outputs.images.COVERAGE_CLASSES)
    notes: list[str] = field(default_factory=list)  # facts worth knowing with nothing to do (gnomon.errors.Remark)

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


def scan(setup: ScanSetup, source: FrameSource, recorder: Recorder | None = None, *,
         progress: bool = False, frame_stride: int = 10,
         track: Callable[..., TrackedSequence] = track_source) -> ScanResult:
    """Reconstruct a surface from a capture, in memory (nothing is written but the recording).

    ``track``: the pass over the frames (:func:`~gnomon.capture.tracking.track_source`, or a drop-in such
    as :class:`gnomon.capture.tiles.TiledTracker`)."""
    result, record = reconstruct(setup, source, recorder, progress=progress, frame_stride=frame_stride,
                                 track=track)
    if record is not None:
        t0 = time.perf_counter() - result.report["timings_s"]["total_s"]
        assert recorder is not None  # a record call exists only with a recorder
        recorder.submit(record)
        recorder.scan_done()
        result.report["timings_s"]["total_s"] = time.perf_counter() - t0
    return result


def reconstruct(setup: ScanSetup, source: FrameSource, recorder: Recorder | None = None, *,
                progress: bool = False, frame_stride: int = 10,
                track: Callable[..., TrackedSequence] = track_source,
                on_points: Callable[[PointsReady], None] | None = None,
                on_mesh: Callable[[Surface], None] | None = None,
                ) -> tuple[ScanResult, Callable[[ScanRecording], None] | None]:
    """:func:`scan` without its last step: the result, and the call that logs it to a recorder
    (None without ``recorder``), so that a caller can record while it writes the outputs.

    The frames are recorded as they stream by (on the :class:`RecordingWorker`'s thread when
    ``recorder`` is one); the ray map is computed on a worker thread while the frames are tracked
    (OpenCV releases the GIL). ``on_points``: called with the surface's points and maps as soon as
    they are final, before the mesh is built (:class:`PointsReady`: e.g. to start writing them);
    the returned call then logs only what its ``record`` did not. ``on_mesh``: called with the
    surface as soon as its mesh is built, before the report (e.g. to start writing the mesh's files).
    """
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    cpu: dict[str, float] = {}  # CPU seconds of the process (all threads) during each stage
    stage = Stages("scan", enabled=progress)  # tracking has its own bar
    warnings = list(setup.warnings) + (list(recorder.notes) if recorder is not None else [])
    if recorder is not None:
        recorder.submit(lambda rec: record_setup(rec, setup, source))
    skip = setup.light.skipped_frames(source.count)
    colour = LitColour(sample_indices(np.flatnonzero(~skip), COLOUR_SAMPLES))
    source.color_frames = source.color_frames | frozenset(int(i) for i in colour.indices)
    on_frame = frame_hook(colour, None if recorder is None else frame_logger(recorder, setup, frame_stride))
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="gnomon-ray-map") as pool:
        rays = pool.submit(setup.camera.ray_map)
        with timed(timings, "tracking_s", cpu):
            tracked, tracker, notes = track_widening(track, source, setup.tracker,
                                                     (setup.camera.height, setup.camera.width),
                                                     dip_width=setup.dip_width, skip=skip, on_frame=on_frame,
                                                     progress=progress, where=f"{setup.inputs.field_log}: [camera]")
        setup = dataclasses.replace(setup, tracker=tracker)  # the dip width tracked with
        warnings += notes
        with timed(timings, "ray_map_s"):  # what is left of it after tracking
            ray_map = rays.result()
    if tracked.registration is not None:
        registration = tracked.registration
        warnings += registration.warnings()
        if recorder is not None:
            recorder.submit(lambda rec: record_registration(rec, registration))
    with timed(timings, "regions_s", cpu):  # the regions held to their planes, then planes tied at corners
        levels = Levels(tracked)  # each edge's times prepared once, for the regions and the edges
        maps = edge_time_maps(tracked, setup.edge, levels)
        setup = hold_regions(setup, maps, tracked.n_frames, ray_map, warnings, levels.lines)
        setup = tie_planes(setup, maps, tracked.n_frames, warnings, levels.lines)
    check_contrast(tracked.times, tracked.noise_dn, setup.tracker.min_contrast, source.name)
    if tracked.dropped:
        warnings.append(dropped_frames_warning(tracked.dropped))
    warnings += setup.light.after_tracking(tracked.used, tracked.skipped_dips)
    if tracked.levelled:
        more = " …" if len(tracked.levelled) > 8 else ""
        warnings.append(Remark(f"{len(tracked.levelled)} frames of sudden illumination dips (clouds) levelled "
                               f"pixel by pixel and tracked (frames {tracked.levelled[:8]}{more})", tracked.levelled))
    warnings += setup.light.choose_dips(tracked, ray_map, setup.planes, setup.max_depth_jump,
                                        min_contrast_dn(setup.tracker.min_contrast, tracked.noise_dn))
    if setup.light.chooses_dips:  # the times were rewritten: prepared anew
        levels = Levels(tracked)
    # The colours need only the tracked times (final from here on): combined on a thread meanwhile.
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="gnomon-colour") as colour_pool:
        colours = colour_pool.submit(lit_colours, colour, tracked)
        with timed(timings, "planes_and_triangulation_s", cpu), stage("shadow planes and triangulation"):
            edges = reconstruct_edges(setup, tracked, ray_map, warnings, levels)
        with timed(timings, "fusion_and_mesh_s", cpu), stage("fusion and mesh"):
            fused = fuse_edges(edges, tracked, setup.max_depth_jump, levels)
            if setup.light.occluder_hides_light:
                warnings += screen_direct_light(fused, edges, tracked, levels)
            cropped = crop_fused(fused, setup, ray_map)
            # The mesh's faces need only the final maps: built on a thread (the kernel, GIL released) while the
            # points are and their files and recording start (each takes the maps' valid pixels itself).
            with ThreadPoolExecutor(max_workers=1, thread_name_prefix="gnomon-mesh") as mesh_pool:
                faces = mesh_pool.submit(mesh_faces, fused.depth, fused.sigma, fused.keep, setup.max_depth_jump)
                points = surface_points(ray_map, setup.pose, fused.depth, fused.sigma, fused.keep, colours.result(),
                                        setup.max_depth_jump)
                coverage = coverage_map(tracked.times.valid, fused.keep, fused.undersampled, cropped,
                                        ambiguous=tracked.times.ambiguous, conflict=fused.conflict,
                                        unsupported=fused.unsupported, no_direct_light=fused.no_direct_light)
                if on_points is not None:
                    on_points(PointsReady(points, fused.shadow_time, fused.undersampled, coverage,
                                          None if recorder is None
                                          else points_part_recorder(timings, setup, edges, points, fused,
                                                                    frame_stride, tracked.used, coverage)))
                surface = mesh_surface(points, setup.max_depth_jump, faces.result())
            if on_mesh is not None:
                on_mesh(surface)
    warnings += fusion_warnings(fused, setup.light) + grazing_warnings(edges)
    timings["total_s"] = time.perf_counter() - t0
    report = scan_report(setup, source, tracked, edges, fused, surface.mesh, timings, warnings)
    report_outputs(report, setup, cropped, cpu, warnings)
    result = ScanResult(setup, tracked.times, edges, fused.shadow_time, fused.depth, fused.sigma, fused.keep,
                        fused.undersampled, surface, report, [w for w in warnings if not isinstance(w, Remark)],
                        coverage=coverage, notes=[w for w in warnings if isinstance(w, Remark)])
    if recorder is None:
        return result, None

    def record(recorder: ScanRecording) -> None:
        with timed(timings, "recording_s", cpu, time.thread_time):  # this thread's CPU
            if on_points is None:
                record_scan(recorder, setup, edges, surface, fused.shadow_time, warnings, report, frame_stride,
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


def write_scan(folder: Path, result: ScanResult, started: float | None = None,
               before_report: Callable[[], None] | None = None) -> None:
    """The scan's files (points, mesh, maps, report.json) into ``folder``, each atomically.

    ``started``: the ``time.perf_counter()`` when the run began, for the report's total;
    ``before_report``: called before report.json is written (e.g. to wait for the recording,
    whose timing the report gives).
    """
    t, c = time.perf_counter(), time.process_time()
    setup, surface = result.setup, result.surface
    with Writers() as writers:
        write_surface(folder, surface, output_context(setup), writers, setup.mesh_formats, setup.cloud_formats)
        write_maps(folder, surface, result.shadow_time, result.undersampled, result.coverage, result.report["camera"],
                   result.report.get("site"), setup.units, writers)
    write_report(folder, result.report, t, c, started, before_report)


def prepare_scan(field_log: str | Path | FieldLog, mesh_formats: tuple[str, ...] | None = None,
                 cloud_formats: tuple[str, ...] | None = None,
                 crs: str | None = None) -> tuple[ScanSetup, FrameSource]:
    """A field log (a path, or one already read) resolved into the scan's set-up and its frames;
    ``mesh_formats``, ``cloud_formats`` and ``crs`` instead of the field log's ``[output]`` ones."""
    log = field_log if isinstance(field_log, FieldLog) else load_field_log(field_log)
    source = frame_source(log)
    setup = resolve_scan(log, source)
    if crs is not None and setup.georeference() is None:
        raise GnomonError(f"--crs {crs}: {log.path} is not a georeferenced scan (its world frame is the scan's "
                          "own); a CRS needs a sun scan's [site]")
    if mesh_formats is not None:
        setup = dataclasses.replace(setup, mesh_formats=mesh_formats)
    if cloud_formats is not None:
        setup = dataclasses.replace(setup, cloud_formats=cloud_formats)
    if crs is not None:
        setup = dataclasses.replace(setup, crs=crs)
    return setup, source


def run_scan(field_log: str | Path | FieldLog, out_dir: str | Path, options: ScanOptions | None = None) -> ScanResult:
    """Run a scan end to end and write its outputs into ``out_dir`` (nothing there unless it succeeds).

    The recording lives on its own thread (:class:`RecordingWorker`): it is opened there (importing
    rerun) while the frames are decoded and tracked, logs and encodes the frames as they go by, and
    logs and encodes the result while the outputs are written.
    """
    opts = options or ScanOptions()
    t0 = time.perf_counter()
    if opts.rrd or opts.view:
        warm_rerun_import()
    stage = Stages("scan", enabled=opts.progress)
    setup_timing: dict[str, float] = {}
    setup_cpu: dict[str, float] = {}
    with stage("set-up (field log, camera, reference planes)"), timed(setup_timing, "setup_s", setup_cpu):
        setup, source = prepare_scan(field_log, opts.mesh_formats, opts.cloud_formats, opts.crs)
    with staged_outputs(Path(out_dir), opts.rrd_path) as staging:
        full = source.video is not None and (opts.rrd or opts.view) and playable_video(source.video)
        name, scale = f"scan {setup.inputs.field_log.name}", 1.0 if full else 0.5
        with recording(staging, opts, name, image_scale=scale, full=opts.rrd_full) as recorder:
            # The points' files and recording start as soon as the points are final, while the mesh is built.
            with Writers() as writers:
                def mesh_files(surface: Surface) -> None:  # started as soon as the mesh is built
                    write_mesh_files(staging, surface, output_context(setup), writers, setup.mesh_formats)

                result, record = reconstruct(setup, source, recorder, progress=opts.progress,
                                             frame_stride=opts.frame_stride, track=opts.track or track_source,
                                             on_points=_point_outputs(staging, setup, writers, recorder),
                                             on_mesh=mesh_files)
                # the set-up's own stage (reading the field log, the camera, the planes from their marks)
                result.report["timings_s"].update(setup_timing)
                result.report["cpu_timings_s"].update(setup_cpu)
                if recorder is not None and record is not None:
                    recorder.submit(record)
                    recorder.close_soon()  # encoded and written while the mesh files are
                t, c = time.perf_counter(), time.process_time()
                with stage("output files"):  # the mesh's files (started by reconstruct) and the points'
                    writers.wait()
            with stage("recording" if recorder is not None else "report"):
                write_report(staging, result.report, t, c, t0, None if recorder is None else recorder.finish)
    result.out_dir = Path(out_dir)
    return result


def _point_outputs(folder: Path, setup: ScanSetup, writers: Writers,
                   recorder: RecordingWorker | None) -> Callable[[PointsReady], None]:
    """reconstruct's ``on_points`` for run_scan: the points' part of the recording queued, the files
    that need no mesh (all but mesh.ply/.obj/.stl and report.json) handed to ``writers``."""
    def start(ready: PointsReady) -> None:
        if recorder is not None and ready.record is not None:
            recorder.submit(ready.record)
        write_point_files(folder, ready.points, output_context(setup), writers,
                          texture=not writes_texture(setup.mesh_formats), cloud_formats=setup.cloud_formats)
        write_maps(folder, ready.points, ready.shadow_time, ready.undersampled, ready.coverage, camera_report(setup),
                   setup.georeference(), setup.units, writers)
    return start


def output_context(setup: ScanSetup) -> OutputContext:
    """What the writers need to know of a scan besides its surface: units, site, CRS."""
    return OutputContext(setup.units, setup.georeference(), setup.crs)
