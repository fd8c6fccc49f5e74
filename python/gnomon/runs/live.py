"""`gnomon live`: depth appears while the shadow is still moving.

The streaming tracker (:class:`gnomon.capture.tracking.ShadowTracker`) already keeps
O(pixels) state; its kernel's *live watch* (:meth:`gnomon._kernel.TemporalTracker.watch`)
reports each pixel as soon as the shadow has left it (its intensity back above
the mid-level between the lit level seen before the dip and the dip's minimum
for ``recover`` frames), with provisional enter and leave times. Per frame,
:class:`LiveView`:

1. puts the newly finished pixels' times into provisional shadow-time maps;
2. re-measures the shadow line on each reference plane for the frames those
   times touch, once no later pixel can add crossings to them: the isochrone
   crossings of the batch scan (:func:`gnomon.geometry.reference_lines.mask_crossings`,
   on a small box around the pixels concerned) fitted per frame with its
   robust line fit (a short line takes the direction of the nearest measured
   frame; the batch pass smooths directions over the whole sweep), and turns
   the lines into shadow planes with the scan's own light model
   (:meth:`gnomon.light.LightModel.planes_from_lines`);
3. triangulates the finished pixels whose planes are known (the kernel's
   triangulation, σZ by :func:`gnomon.geometry.uncertainty.depth_sigma`, the edges
   fused by :func:`gnomon.reconstruct.fusion.fuse_depths`), and logs the new points, the
   frame's edges, the map filling in and the coverage on the ``frame``
   timeline of the recording.

When the source ends (or on Ctrl-C, or when the sweep is complete) the tracker
is finished as in ``gnomon scan`` and the same post-processing runs on its
final state (:func:`gnomon.runs.scan.scan` with this pass as its ``track``), so
the outputs are ``gnomon scan``'s, published atomically (:mod:`gnomon.outputs.publish`).
The live points are provisional: the final pass refines every time with the
lit level on both sides of the dip and the deepest dip of the whole capture.

Frames come from the field log's capture, a video file, a camera index or a
stream URL (OpenCV ``VideoCapture``); ``realtime`` paces a file at its frame
rate like a camera: a frame not taken within the buffer's time is dropped, and
counted (the tracker then skips it, as it skips a sun scan's night frames).

Lights whose planes come from reference lines (lamp, two planes, sun with
lines) get live points; a sun scan with a pole gets the live shadow-time map
and coverage, and its points at the end.
"""

from __future__ import annotations

import hashlib
import queue
import signal
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Self

import cv2
import numpy as np

from gnomon.capture.frames import Frame, FrameSource, to_grey, video_fps
from gnomon.capture.noise import image_noise_dn
from gnomon.capture.tracking import (
    NOISE_PAIRS,
    ShadowTracker,
    TrackedSequence,
    TrackerSettings,
    contrast_floor,
    linear,
    track_source,
)
from gnomon.config.fieldlog import load_field_log
from gnomon.config.setup import ScanSetup, frame_source, resolve_scan
from gnomon.errors import FrameError
from gnomon.geometry.reference_lines import (
    MIN_EXTENT_FRACTION,
    MIN_EXTENT_TO_RMS,
    MIN_POINTS,
    ReferenceLines,
    ReferencePlane,
    along_extent,
    mask_crossings,
)
from gnomon.geometry.triangulation import triangulate
from gnomon.geometry.uncertainty import (
    depth_sigma,
    interpolation_time_sigma,
    linear_noise_at_threshold,
)
from gnomon.outputs.publish import staged_outputs
from gnomon.reconstruct.fusion import fuse_depths
from gnomon.recording.recorder import ScanRecording, display_available, playable_video
from gnomon.runs.scan import ScanResult, scan, write_scan
from gnomon.util.fitting import fit_line_robust
from gnomon.util.threads import received

__all__ = ["CaptureSource", "LiveFrames", "LiveOptions", "LiveStats", "LiveView", "open_source", "run_live"]

# Frames after a line's frame before it is measured: the pixels crossing it must have finished.
LINE_MARGIN = 1
# Frames of shadow time on either side of the frames measured that the box around them keeps.
BAND_FRAMES = 2.0
# A finished pixel whose planes have not come this many frames after its time gets no live point.
GIVE_UP_FRAMES = 12
# Frames the lines and points may wait while frames are queued behind a paced source.
MAX_DEFER = 8
# Frames per entity of live points in the recording.
POINT_CHUNK = 4
# Longest side of the live shadow-time map in the recording (pixels).
LIVE_MAP_SIZE = 480
# The live watch's contrast floor (DN) where the scan's is 0 (noiseless frames, no min_contrast).
WATCH_FLOOR_DN = 20.0


@dataclass
class LiveOptions:
    """How ``gnomon live`` runs.

    ``source``: None (the field log's frames), a camera index (``"0"``), a video
    file or a stream URL. ``realtime``: pace a file at ``fps`` (its own rate, or
    the field log's, else 30) and drop frames not taken within ``buffer`` frames
    (a capture thread's queue, one second at 30 fps).
    ``recover``: frames back above the mid-level that end a pixel's dip.
    ``stop_when_complete``: end when the sweep is over (default: for cameras and
    streams only; a file is read to its end). ``max_frames``: a camera's or
    stream's longest run. ``view`` spawn a viewer (where a display exists),
    ``connect`` a running viewer's URL, ``rrd`` write ``OUT/scan.rrd``.
    """

    source: str | None = None
    realtime: bool = False
    fps: float | None = None
    buffer: int = 30
    recover: int = 3
    stop_when_complete: bool | None = None
    max_frames: int = 100000
    view: bool = False
    connect: str | None = None
    rrd: bool = True
    frame_stride: int = 10
    map_stride: int = 5
    progress: bool = False
    update_every: int = 1


# --------------------------------------------------------------------------- sources


class CaptureSource(FrameSource):
    """Frames from an OpenCV ``VideoCapture`` of a camera index or a stream URL.

    ``count`` is ``max_frames`` (the capture's length is not known beforehand);
    the frames digest is the sha256 of the decoded frames' bytes.
    """

    def __init__(self, target: int | str, max_frames: int, size: tuple[int, int] | None = None):
        self.target = target
        self.image_files = ()
        self.video = None
        self.expected_count = None
        self.color_frames = frozenset({0})
        self._digest = None
        self.count = int(max_frames)
        self.size = size
        cap = self._open()
        self.fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0) or None
        cap.release()

    @property
    def name(self) -> str:
        return f"camera {self.target}" if isinstance(self.target, int) else str(self.target)

    def _open(self) -> cv2.VideoCapture:
        cap = cv2.VideoCapture(self.target)
        if not cap.isOpened():
            raise FrameError(f"{self.name}: cannot be opened as a camera or stream")
        if self.size is not None and isinstance(self.target, int):
            cap.set(cv2.CAP_PROP_FRAME_WIDTH, self.size[0])
            cap.set(cv2.CAP_PROP_FRAME_HEIGHT, self.size[1])
        return cap

    def frames_digest(self) -> str:
        return self._digest or hashlib.sha256().hexdigest()

    def _decode(self) -> Iterator[Frame]:
        cap = self._open()
        digest = hashlib.sha256()
        first: np.ndarray | None = None
        try:
            for i in range(self.count):
                ok, image = cap.read()
                if not ok or image is None:
                    break
                self._check_size(i, f"{self.name} frame {i}", image, first)
                if first is None:
                    first = image
                digest.update(np.ascontiguousarray(image).tobytes())
                color = image[:, :, :3] if (i in self.color_frames and image.ndim == 3) else None
                yield Frame(i, to_grey(image), color, f"{self.name} frame {i}")
        finally:
            cap.release()
            self._digest = digest.hexdigest()


def open_source(spec: str | None, field_log_source: FrameSource, max_frames: int,
                size: tuple[int, int]) -> FrameSource:
    """The frames of a run: the field log's (``spec`` None), a video file, a camera index or a URL."""
    if spec is None:
        return field_log_source
    if spec.isdigit():
        return CaptureSource(int(spec), max_frames, size)
    path = Path(spec)
    if path.is_file():
        return FrameSource(video=path)
    if "://" in spec:
        return CaptureSource(spec, max_frames)
    raise FrameError(f"--source {spec}: not a camera index, a video file or a stream URL")


def source_fps(source: FrameSource, fallback: float | None) -> float:
    """Frames per second of a source: its own (video, camera), else ``fallback``, else 30."""
    fps: float | None = None
    if isinstance(source, CaptureSource):
        fps = source.fps
    elif source.video is not None:
        fps = video_fps(source.video)
    if fps is None or not np.isfinite(fps) or fps <= 0:
        fps = fallback
    return float(fps) if fps else 30.0


class LiveFrames:
    """A source as ``track_source`` sees it during a live run: paced, stoppable, with drops counted.

    Without pacing, frames are delivered as fast as they are taken. With
    ``fps``, frame i is due at ``start + i / fps`` (the first frame's arrival
    is the start), as from a camera; a frame that finds ``buffer`` frames
    still waiting, or that the decoder delivers more than ``buffer`` frame
    periods late, is dropped (``dropped``). ``stop()`` (Ctrl-C, the sweep is
    complete) ends the stream after the current frame.
    """

    def __init__(self, inner: FrameSource, fps: float | None = None, buffer: int = 30):
        self.inner = inner
        self.fps = fps
        self.buffer = max(int(buffer), 1)
        self.dropped: list[int] = []
        self.delivered = 0
        self.stopped_early = False
        self._stop = threading.Event()
        self._queue: queue.Queue[object] | None = None
        self.start: float | None = None  # when the first frame arrived (paced)

    def arriving(self) -> int | None:
        """The capture frame a camera would be delivering now (paced sources), else None."""
        if self.fps is None or self.start is None:
            return None
        return int((time.perf_counter() - self.start) * self.fps)

    def backlog(self) -> int:
        """Frames taken from the source and waiting (0 unless paced)."""
        return self._queue.qsize() if self._queue is not None else 0

    # FrameSource's interface, delegated
    @property
    def count(self) -> int:
        return self.inner.count

    @property
    def video(self) -> Path | None:
        return self.inner.video

    @property
    def name(self) -> str:
        return self.inner.name

    @property
    def expected_count(self) -> int | None:
        # a run cut short (stopped, frames dropped) is not a truncated file
        if self.stopped_early or self.dropped:
            return None
        return self.inner.expected_count

    @property
    def color_frames(self) -> frozenset[int]:
        return self.inner.color_frames

    @color_frames.setter
    def color_frames(self, value: frozenset[int]) -> None:
        self.inner.color_frames = value

    def frames_digest(self) -> str:
        return self.inner.frames_digest()

    def stop(self) -> None:
        self.stopped_early = True
        self._stop.set()

    def __iter__(self) -> Iterator[Frame]:
        if self.fps is None:
            for frame in self.inner:
                if self._stop.is_set():
                    return
                self.delivered += 1
                yield frame
            return
        yield from self._paced(self.fps)

    def _paced(self, fps: float) -> Iterator[Frame]:
        out: queue.Queue[object] = queue.Queue(maxsize=self.buffer)
        self._queue = out
        done = object()
        period = 1.0 / fps
        halt = threading.Event()

        def produce() -> None:
            start: float | None = None
            try:
                for k, frame in enumerate(self.inner):
                    if halt.is_set() or self._stop.is_set():
                        break
                    now = time.perf_counter()
                    if start is None:
                        start = self.start = now
                    due = start + k * period
                    if now < due:
                        time.sleep(due - now)
                    elif now > due + self.buffer * period:
                        self.dropped.append(frame.index)  # the camera's buffer overflowed meanwhile
                        continue
                    try:
                        out.put_nowait(frame)
                    except queue.Full:
                        self.dropped.append(frame.index)
                out.put(done)
            except BaseException as exc:  # noqa: BLE001 - forwarded to the consumer, re-raised there
                out.put(exc)

        worker = threading.Thread(target=produce, name="gnomon-live-pacer", daemon=True)
        worker.start()
        try:
            for item in received(out, done):
                assert isinstance(item, Frame)
                self.delivered += 1
                yield item
                if self._stop.is_set():
                    return
        finally:
            halt.set()
            while worker.is_alive():
                try:
                    out.get_nowait()
                except queue.Empty:
                    worker.join(timeout=0.05)


# --------------------------------------------------------------------------- the live view


@dataclass
class LiveStats:
    """What a live run measured.

    ``logged_at`` (H, W) int32: capture frame at which each pixel's live point was
    logged (−1 = none); ``finished_at`` (H, W) int32: capture frame at which the
    watch finished it (−1 = never); ``logged_wall`` (H, W) int32: with a paced
    source, the frame the camera was delivering when the point was logged (the
    wall-clock view of the latency; −1 = none); ``step_s``, ``step_cpu_s``: wall-clock and
    CPU seconds (this thread) of live work per frame; ``pass_wall_s``,
    ``pass_cpu_s``: the whole live pass (decoding, tracking, live work,
    recording; CPU time of all threads).
    """

    frames: int = 0
    dropped: list[int] = field(default_factory=list)
    stopped: str = "source ended"
    points_logged: int = 0
    logged_at: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), dtype=np.int32))
    finished_at: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), dtype=np.int32))
    logged_wall: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), dtype=np.int32))
    step_s: list[float] = field(default_factory=list)
    step_cpu_s: list[float] = field(default_factory=list)
    pass_wall_s: float = 0.0
    pass_cpu_s: float = 0.0
    fps: float | None = None

    def summary(self) -> dict[str, Any]:
        steps = np.asarray(self.step_s) if self.step_s else np.zeros(1)
        cpu = np.asarray(self.step_cpu_s) if self.step_cpu_s else np.zeros(1)
        return {"frames": self.frames, "dropped_frames": len(self.dropped), "dropped": self.dropped[:50],
                "stopped": self.stopped, "points_logged": self.points_logged, "realtime_fps": self.fps,
                "live_step_ms_median": float(np.median(steps) * 1e3),
                "live_step_ms_p95": float(np.percentile(steps, 95) * 1e3),
                "live_step_cpu_ms_median": float(np.median(cpu) * 1e3),
                "pass_wall_s": self.pass_wall_s, "pass_cpu_s": self.pass_cpu_s}


class _PlaneLines:
    """One reference plane's live shadow lines for one edge, rows 0 … capacity−1."""

    def __init__(self, ref: ReferencePlane, capacity: int):
        self.ref = ref
        self.longest = 0.0  # the longest line seen on this plane (world units along it)
        rows, cols = np.nonzero(ref.mask)
        self.box = (int(rows.min()), int(rows.max()) + 1, int(cols.min()), int(cols.max()) + 1) if rows.size else None
        n = capacity
        self.point = np.full((n, 3), np.nan)
        self.direction = np.full((n, 3), np.nan)
        self.rms = np.full(n, np.nan)
        self.count = np.zeros(n, dtype=np.int64)
        self.extent = np.zeros(n)
        self.extrapolated = np.zeros(n, dtype=bool)
        self.pixels: list[np.ndarray] = [np.zeros((0, 2)) for _ in range(n)]
        self.points: list[np.ndarray] = [np.zeros((0, 3)) for _ in range(n)]

    def grow(self, n: int) -> None:
        old = len(self.rms)
        if n <= old:
            return
        n = max(n, 2 * old)
        pad = n - old
        self.point = np.vstack([self.point, np.full((pad, 3), np.nan)])
        self.direction = np.vstack([self.direction, np.full((pad, 3), np.nan)])
        self.rms = np.concatenate([self.rms, np.full(pad, np.nan)])
        self.count = np.concatenate([self.count, np.zeros(pad, dtype=np.int64)])
        self.extent = np.concatenate([self.extent, np.zeros(pad)])
        self.extrapolated = np.concatenate([self.extrapolated, np.zeros(pad, dtype=bool)])
        self.pixels += [np.zeros((0, 2)) for _ in range(pad)]
        self.points += [np.zeros((0, 3)) for _ in range(pad)]

    def measure(self, times: np.ndarray, frames: np.ndarray, n_frames: int, camera: Any,
                candidates: np.ndarray) -> None:
        """Re-measure the lines of ``frames`` from the map ``times`` (H, W), looking only at a box
        around ``candidates`` (flat indices of this plane's pixels with times near those frames)."""
        if self.box is None or not candidates.size:
            return
        h, w = times.shape
        lo, hi = float(frames.min()) - BAND_FRAMES, float(frames.max()) + BAND_FRAMES
        near = candidates[(times.flat[candidates] >= lo) & (times.flat[candidates] <= hi)]
        if not near.size:
            return
        rows, cols = np.divmod(near, w)
        v0, v1 = max(int(rows.min()) - 1, 0), min(int(rows.max()) + 2, h)
        u0, u1 = max(int(cols.min()) - 1, 0), min(int(cols.max()) + 2, w)
        sub = times[v0:v1, u0:u1]
        band = np.where((sub >= lo) & (sub <= hi), sub, np.nan)
        # frames after the last one wanted are not looked at
        last = min(int(frames.max()) + 1, n_frames)
        frame, pix = mask_crossings(band, self.ref.mask[v0:v1, u0:u1], last)
        wanted = np.isin(frame, frames)
        frame, pix = frame[wanted], pix[wanted] + np.array([u0, v0], dtype=np.float64)
        if not frame.size:
            return
        plane = self.ref.plane
        on_plane = plane.intersect(camera.rays(pix))
        good = np.isfinite(on_plane[:, 0])
        frame, pix, on_plane = frame[good], pix[good], on_plane[good]
        xy = plane.to_plane_coords(on_plane)
        for t in np.unique(frame):
            self._fit(int(t), frame == t, xy, pix, on_plane)

    def _fit(self, t: int, sel: np.ndarray, xy: np.ndarray, pix: np.ndarray, on_plane: np.ndarray) -> None:
        """Frame t's line from its crossings (plane coordinates ``xy``), as the batch scan fits it
        (:func:`gnomon.util.fitting.fit_line_robust`); a line shorter than half the longest seen keeps
        the direction of the nearest measured frame and fits only its offset."""
        plane = self.ref.plane
        pts = xy[sel]
        self.point[t] = np.nan
        if len(pts) < MIN_POINTS:
            return
        centre, d2, inl = fit_line_robust(pts)
        if inl.sum() < MIN_POINTS:
            return
        normal2 = np.array([-d2[1], d2[0]])
        ext = along_extent(pts[inl] @ d2)
        spread = float(np.sqrt(np.mean(((pts[inl] - centre) @ normal2) ** 2)))
        if ext < MIN_EXTENT_TO_RMS * spread:
            return
        self.longest = max(self.longest, ext)
        extrapolated = False
        if ext < MIN_EXTENT_FRACTION * self.longest:
            measured = np.flatnonzero(np.isfinite(self.point[:, 0]) & ~self.extrapolated)
            if not measured.size:
                return
            near = measured[np.argmin(np.abs(measured - t))]
            d3 = self.direction[near]
            d2 = np.array([d3 @ plane.e1, d3 @ plane.e2])
            d2 /= np.linalg.norm(d2)
            normal2 = np.array([-d2[1], d2[0]])
            offsets = pts @ normal2
            med = np.median(offsets)
            mad = 1.4826 * np.median(np.abs(offsets - med))
            inl = np.abs(offsets - med) <= 3.0 * max(mad, 1e-9 * (1.0 + abs(med)))
            if inl.sum() < MIN_POINTS:
                return
            centre = np.mean(offsets[inl]) * normal2 + np.mean(pts[inl] @ d2) * d2
            extrapolated = True
        res = (pts[inl] - centre) @ normal2
        d3 = d2[0] * plane.e1 + d2[1] * plane.e2
        self.point[t], self.direction[t] = plane.from_plane_coords(centre), d3 / np.linalg.norm(d3)
        self.rms[t] = float(np.sqrt(np.mean(res**2)))
        self.count[t] = int(inl.sum())
        chosen = pix[sel][inl]
        self.pixels[t] = chosen[np.argsort(chosen[:, 1])]
        self.points[t] = on_plane[sel][inl]
        self.extent[t] = along_extent(pts[inl] @ d2)
        self.extrapolated[t] = extrapolated

    def lines(self, n: int) -> ReferenceLines:
        return ReferenceLines(self.ref.name, self.ref.plane, self.point[:n], self.direction[:n], self.rms[:n],
                              self.count[:n], self.pixels[:n], self.extrapolated[:n], self.points[:n],
                              self.extent[:n])


class _EdgeState:
    """One edge's provisional times, lines and planes."""

    def __init__(self, name: str, shape: tuple[int, int], refs: tuple[ReferencePlane, ...], capacity: int):
        self.name = name
        self.times = np.full(shape, np.nan, dtype=np.float32)
        self.slope = np.full(shape, np.nan, dtype=np.float32)
        self.lines = [_PlaneLines(r, capacity) for r in refs]
        self.planes = np.full((0, 4), np.nan)
        self.dirty: set[int] = set()
        # finished reference-region pixels by the integer part of this edge's time
        self.by_frame: dict[int, list[np.ndarray]] = {}

    def grow(self, n: int) -> None:
        for ln in self.lines:
            ln.grow(n)


def _sigma_colours(sigma: np.ndarray, scale: float) -> np.ndarray:
    """uint8 RGB from green (σ ≤ scale / 3) through yellow to red (σ ≥ scale)."""
    x = np.clip(np.nan_to_num(sigma / max(scale, 1e-12), nan=1.0), 0.0, 1.0)
    r = np.clip(2.0 * x, 0, 1)
    g = np.clip(2.0 * (1.0 - x), 0, 1)
    return (np.stack([r, g, 0.15 * np.ones_like(x)], axis=1) * 255).astype(np.uint8)


class LiveView:
    """The incremental part of a live run, fed by ``track_source``'s ``on_update`` (see the module docs).

    ``setup``: the resolved scan; ``recorder``: where to log (None = nowhere);
    ``frames``: the stream, stopped when the sweep is complete if ``stop_when_complete``.
    """

    def __init__(self, setup: ScanSetup, recorder: ScanRecording | None, frames: LiveFrames, *,
                 recover: int = 3, stop_when_complete: bool = False, map_stride: int = 5,
                 update_every: int = 1):
        self.setup, self.recorder, self.frames = setup, recorder, frames
        self.recover = int(recover)
        self.stop_when_complete = stop_when_complete
        self.map_stride = max(int(map_stride), 1)
        self.update_every = max(int(update_every), 1)
        cam = setup.camera
        self.shape = (cam.height, cam.width)
        self.ray_map = cam.ray_map()
        self.lines_light = setup.light.planes_from_reference_lines
        wanted = [e for e in ("enter", "leave") if setup.edge in (e, "both")]
        capacity = 256
        self.edges = [_EdgeState(name, self.shape, setup.planes, capacity) for name in wanted]
        self.leave = np.full(self.shape, np.nan, dtype=np.float32)  # capture frames, for display
        n_pixels = self.shape[0] * self.shape[1]
        region = np.zeros(n_pixels, dtype=bool)
        for ref in setup.planes:
            region |= ref.mask.ravel()
        self.region = region
        self.plane_masks = [ref.mask.ravel() for ref in setup.planes]
        self.pending = np.zeros(0, dtype=np.int64)
        self.threshold = np.zeros(n_pixels, dtype=np.float32)
        self.contrast_lin = np.zeros(n_pixels, dtype=np.float32)
        self.used: list[int] = []
        self.tracker: ShadowTracker | None = None
        self.watching = False  # the kernel's live watch has started (once the noise is known)
        self.noise_dn: float | None = None
        self._previous: np.ndarray | None = None
        self._noise: list[float] = []
        self.finished = 0
        self.idle = 0
        self.stats = LiveStats(logged_at=np.full(self.shape, -1, dtype=np.int32),
                               finished_at=np.full(self.shape, -1, dtype=np.int32),
                               logged_wall=np.full(self.shape, -1, dtype=np.int32))
        self._chunk: dict[int, list[np.ndarray]] = {}
        self._sigma_scale: float | None = None
        self._last_lines_frame = -1
        self._last_work = -1

    # ------------------------------------------------------------------ per frame

    def on_update(self, frame: Frame, tracker: ShadowTracker) -> None:
        """After the tracker took ``frame``: finished pixels → maps → lines → planes → points → log."""
        t0, c0 = time.perf_counter(), time.thread_time()
        self.tracker = tracker
        self.used.append(frame.index)
        k = len(self.used) - 1  # tracker frame
        self._estimate_noise(frame.grey)
        if not self.watching and self.noise_dn is not None:
            # The scan's own contrast floor (the field log's min_contrast and MIN_CONTRAST_SIGMAS σ of the
            # noise, whichever is higher), so the watch opens the dips the final pass keeps: with a fixed
            # 20 DN it missed the low-contrast half of a phone video's points. The watch starts with the
            # frame after the noise is known (its first pairs of frames).
            floor = contrast_floor(self.setup.tracker.min_contrast, self.noise_dn)
            tracker.watch(floor if floor > 0 else WATCH_FLOOR_DN, self.recover)
            self.watching = True
        fin = tracker.take_finished() if self.watching else None
        if fin is not None and len(fin):
            self._add_finished(fin, k, frame.index)
            self.idle = 0
        else:
            self.idle += 1
        # Behind a paced source, the lines and points wait for a frame with nothing queued (at most
        # MAX_DEFER frames): the work is batched instead of frames being dropped.
        due = k - self._last_work >= self.update_every
        if self.lines_light and due and (self.frames.backlog() == 0 or k - self._last_work > MAX_DEFER):
            self._measure_lines(k)
            self._triangulate(k, frame.index)
            self._last_work = k
        self._log(k, frame.index)
        self.stats.step_s.append(time.perf_counter() - t0)
        self.stats.step_cpu_s.append(time.thread_time() - c0)
        if self.stop_when_complete and self._complete(tracker):
            self.stats.stopped = "sweep complete"
            self.frames.stop()

    def _estimate_noise(self, grey: np.ndarray) -> None:
        if self.noise_dn is not None:
            return
        if self._previous is not None:
            self._noise.append(image_noise_dn(self._previous, grey))
        self._previous = grey
        if len(self._noise) >= min(NOISE_PAIRS, 2):
            self.noise_dn = float(np.median(self._noise))
            self._previous = None

    def _add_finished(self, fin: Any, k: int, capture_frame: int) -> None:
        idx = np.asarray(fin.index, dtype=np.int64)
        assert self.tracker is not None
        self.threshold[idx] = fin.threshold
        self.contrast_lin[idx] = 2.0 * (linear(fin.imax, self.tracker.lut) - np.asarray(fin.threshold))
        times = {"enter": (np.asarray(fin.enter), np.asarray(fin.enter_slope)),
                 "leave": (np.asarray(fin.leave), np.asarray(fin.leave_slope))}
        for e in self.edges:
            t, slope = times[e.name]
            e.times.flat[idx] = t
            e.slope.flat[idx] = slope
        used = np.asarray(self.used, dtype=np.float64)
        leave = np.asarray(fin.leave, dtype=np.float64)
        ok = np.isfinite(leave)
        self.leave.flat[idx[ok]] = np.interp(leave[ok], np.arange(len(used)), used)
        self.stats.finished_at.flat[idx] = capture_frame
        self.finished += len(idx)
        in_region = idx[self.region[idx]]
        if in_region.size:
            for e in self.edges:
                te = e.times.flat[in_region]
                finite = np.isfinite(te)
                if not finite.any():
                    continue
                px, frame = in_region[finite], np.floor(te[finite]).astype(np.int64)
                order = np.argsort(frame, kind="stable")
                px, frame = px[order], frame[order]
                cuts = np.flatnonzero(np.diff(frame)) + 1
                for part, f in zip(np.split(px, cuts), frame[np.r_[0, cuts]], strict=True):
                    e.by_frame.setdefault(int(f), []).append(part)
                first, last = int(frame[0]), int(np.ceil(te[finite].max()))
                e.dirty.update(range(max(first, 0), last + 1))
        self.pending = np.concatenate([self.pending, idx])

    def _measure_lines(self, k: int) -> None:
        """Lines of the dirty frames no later pixel can change any more, then every edge's planes."""
        n = k + 1
        ready_until = k - self.recover - LINE_MARGIN
        changed = False
        measured: dict[_EdgeState, np.ndarray] = {}
        for e in self.edges:
            e.grow(n)
            ready = np.array(sorted(t for t in e.dirty if t <= ready_until), dtype=np.int64)
            if not ready.size:
                continue
            e.dirty.difference_update(ready.tolist())
            # the region pixels whose time lies near the frames measured, from the edge's buckets
            lo, hi = int(ready.min() - BAND_FRAMES) - 1, int(ready.max() + BAND_FRAMES) + 1
            parts = [p for f in range(lo, hi + 1) for p in e.by_frame.get(f, ())]
            near = np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)
            for ln, members in zip(e.lines, self.plane_masks, strict=True):
                ln.measure(e.times, ready, n, self.setup.camera, near[members[near]])
            self._last_lines_frame = max(self._last_lines_frame, int(ready.max()))
            measured[e] = ready
            changed = True
        if not changed:
            return
        light = self.setup.light
        light.after_tracking(np.asarray(self.used), [])  # the sun's timeline for the frames so far
        for e, rows in measured.items():
            self._update_planes(e, rows, n)

    def _update_planes(self, e: _EdgeState, rows: np.ndarray, n: int) -> None:
        """The light's planes for the re-measured ``rows`` (only those: the lines elsewhere are
        blanked), each oriented like the nearest earlier plane of the edge's table."""
        if len(e.planes) < n:
            e.planes = np.vstack([e.planes, np.full((n - len(e.planes), 4), np.nan)])
        lines = [ln.lines(n) for ln in e.lines]
        keep = np.zeros(n, dtype=bool)
        keep[rows] = True
        window = [replace(ln, point=np.where(keep[:, None], ln.point, np.nan),
                          direction=np.where(keep[:, None], ln.direction, np.nan)) for ln in lines]
        planes, _ = self.setup.light.planes_from_lines(window)
        for t in rows:
            t = int(t)
            row = planes[t]
            if np.isfinite(row[0]):
                before = np.flatnonzero(np.isfinite(e.planes[:t, 0]))
                after = np.flatnonzero(np.isfinite(e.planes[t + 1:, 0]))
                near = e.planes[before[-1]] if before.size else (e.planes[t + 1 + after[0]] if after.size else None)
                if near is not None and row[:3] @ near[:3] < 0:
                    row = -row
            e.planes[t] = row

    def _triangulate(self, k: int, capture_frame: int) -> None:
        if not self.pending.size or not self.edges:
            return
        # only pixels whose every edge has its planes (or has given up waiting for them)
        ready = np.ones(self.pending.size, dtype=bool)
        for e in self.edges:
            t = e.times.flat[self.pending]
            n = len(e.planes)
            if n == 0:
                ready &= ~np.isfinite(t) | (np.ceil(t) + GIVE_UP_FRAMES <= k)
                continue
            with np.errstate(invalid="ignore"):
                r0 = np.clip(np.nan_to_num(np.floor(t), nan=0).astype(np.int64), 0, n - 1)
                r1 = np.clip(np.nan_to_num(np.ceil(t), nan=0).astype(np.int64), 0, n - 1)
                inside = (t >= 0) & (np.ceil(t) < n)
                have = inside & np.isfinite(e.planes[r0, 0]) & np.isfinite(e.planes[r1, 0])
            ready &= ~np.isfinite(t) | have | (np.ceil(t) + GIVE_UP_FRAMES <= k)
        if not ready.any():
            return
        px = self.pending[ready]
        later = self.pending[~ready]
        rays = self.ray_map.reshape(-1, 3)[px][None, :, :]
        depths, sigmas, decided = [], [], np.ones(px.size, dtype=bool)
        for e in self.edges:
            t = e.times.flat[px].astype(np.float32)
            depth = np.full(px.size, np.nan, dtype=np.float32)
            sigma = np.full(px.size, np.nan, dtype=np.float32)
            if len(e.planes):
                tri = triangulate(rays, t[None, :], e.planes)
                depth = tri.depth[0]
                ok = np.isfinite(depth)
                if ok.any():
                    st = self._time_sigma(px[ok], e.slope.flat[px[ok]])
                    unc = depth_sigma(rays[:, ok], t[None, ok], e.planes, depth[None, ok], st[None, :],
                                      np.zeros(len(e.planes)))
                    sigma[ok] = unc.sigma_z[0]
            # undecided: a time whose planes may still come
            waiting = np.isfinite(t) & ~np.isfinite(depth) & (np.ceil(t) + GIVE_UP_FRAMES > k)
            decided &= ~waiting
            depths.append(depth)
            sigmas.append(np.where(np.isfinite(depth) & ~(sigma > 0), np.nanmedian(sigma) if np.isfinite(sigma).any()
                                   else 1.0, sigma).astype(np.float32))
        fused, fused_sigma, _ = fuse_depths([d[None, :] for d in depths], [s[None, :] for s in sigmas],
                                            self.setup.max_depth_jump)
        z, s = fused[0], fused_sigma[0]
        done = decided
        good = done & np.isfinite(z)
        self.pending = np.concatenate([later, px[~done]])
        if good.any():
            self._log_points(px[good], z[good], s[good], capture_frame)

    def _time_sigma(self, px: np.ndarray, slope: np.ndarray) -> np.ndarray:
        """σ of the pixels' times (frames): image noise over the slope, and the edge's sampling."""
        assert self.tracker is not None
        noise = self.noise_dn if self.noise_dn is not None else 1.0
        sigma_lin = linear_noise_at_threshold(noise, self.threshold[px], self.tracker.lut)
        with np.errstate(invalid="ignore", divide="ignore"):
            st = np.where(slope > 0, sigma_lin / slope, np.nan)
        return np.hypot(st, interpolation_time_sigma(self.contrast_lin[px], slope)).astype(np.float32)

    def _log_points(self, px: np.ndarray, z: np.ndarray, sigma: np.ndarray, capture_frame: int) -> None:
        rays = self.ray_map.reshape(-1, 3)[px]
        cam_pts = rays * (z / rays[:, 2])[:, None]
        world = self.setup.pose.camera_to_world(cam_pts.astype(np.float64)).astype(np.float32)
        self.stats.logged_at.flat[px] = capture_frame
        arriving = self.frames.arriving()
        if arriving is not None:
            self.stats.logged_wall.flat[px] = max(arriving, capture_frame)
        self.stats.points_logged += int(px.size)
        rec = self.recorder
        if rec is None or not rec.enabled:
            return
        if self._sigma_scale is None:
            self._sigma_scale = 3.0 * float(np.nanmedian(sigma)) if np.isfinite(sigma).any() else 1.0
        v, u = np.divmod(px, self.shape[1])
        chunk = capture_frame // POINT_CHUNK
        parts = self._chunk.setdefault(chunk, [])
        parts.append(np.column_stack([world, sigma, u, v]).astype(np.float32))
        for old in [c for c in self._chunk if c < chunk]:
            del self._chunk[old]  # a finished chunk stays in the recording as logged
        data = np.concatenate(parts)
        rec.log_live_points(capture_frame, chunk, data[:, :3], _sigma_colours(data[:, 3], self._sigma_scale),
                            data[:, 3], data[:, 4:6])

    def _log(self, k: int, capture_frame: int) -> None:
        rec = self.recorder
        if rec is None or not rec.enabled:
            return
        n_pixels = self.shape[0] * self.shape[1]
        rec.log_metrics({"live": {"finished_pct": 100.0 * self.finished / n_pixels,
                                  "points_pct": 100.0 * self.stats.points_logged / n_pixels,
                                  "dropped_frames": len(self.frames.dropped)}}, index=capture_frame)
        if self.lines_light and self._last_lines_frame >= 0 and self.edges:
            t = self._last_lines_frame
            e = self.edges[-1]
            polylines = [ln.pixels[t] for ln in e.lines if len(ln.pixels[t]) >= 2]
            if polylines:
                rec.log_edges(capture_frame, polylines)
        if k % self.map_stride == 0:
            h, w = self.shape
            scale = min(1.0, LIVE_MAP_SIZE / max(h, w))
            m = self.leave if scale >= 1.0 else cv2.resize(self.leave, (max(int(w * scale), 1), max(int(h * scale), 1)),
                                                          interpolation=cv2.INTER_NEAREST)
            rec.log_live_map(capture_frame, m)

    def _complete(self, tracker: ShadowTracker) -> bool:
        """The sweep is over: a share of the image finished, nothing in a dip, nothing new for a while."""
        counts = tracker.watch_counts
        if counts is None:
            return False
        lit, in_dip, done = counts
        total = lit + in_dip + done
        idle_frames = 2 * self.setup.tracker.max_width
        return done >= 0.01 * total and in_dip <= 0.0005 * total and self.idle >= idle_frames


# --------------------------------------------------------------------------- the run


def _live_track(view: LiveView) -> Callable[..., TrackedSequence]:
    """A drop-in for :func:`gnomon.capture.tracking.track_source` that runs ``view`` on every frame."""

    def track(source: Any, settings: TrackerSettings, shape: tuple[int, int], **kwargs: Any) -> TrackedSequence:
        frames = view.frames
        wall, cpu = time.perf_counter(), time.process_time()
        try:
            tracked = track_source(source, settings, shape, on_update=view.on_update, **kwargs)
        except FrameError as exc:
            if frames.dropped:
                raise FrameError(f"{exc} ({_dropped_note(frames)})") from None
            raise
        if len(frames.dropped) > frames.delivered:
            raise FrameError(_dropped_note(frames))
        view.stats.pass_wall_s = time.perf_counter() - wall
        view.stats.pass_cpu_s = time.process_time() - cpu
        view.stats.frames = len(view.used)
        view.stats.dropped = list(frames.dropped)
        tracked.info = {**tracked.info, "live": view.stats.summary()}
        return tracked

    return track


def _dropped_note(frames: LiveFrames) -> str:
    total = frames.delivered + len(frames.dropped)
    return (f"{frames.name}: {len(frames.dropped)} of {total} frames dropped: this machine did not keep up "
            f"with {frames.fps:g} fps (decoding and tracking); run without --realtime, or at a lower --fps")


class _StopOnInterrupt:
    """Ctrl-C during the live pass ends the stream (the outputs are still written);
    a second Ctrl-C interrupts as usual."""

    def __init__(self, frames: LiveFrames, stats: LiveStats):
        self.frames, self.stats = frames, stats
        self.previous: Any = None

    def __enter__(self) -> Self:
        try:
            self.previous = signal.signal(signal.SIGINT, self._handler)
        except ValueError:  # not the main thread
            self.previous = None
        return self

    def _handler(self, signum: int, frame: Any) -> None:
        self.stats.stopped = "interrupted"
        self.frames.stop()
        signal.signal(signal.SIGINT, signal.default_int_handler)

    def __exit__(self, *exc: object) -> None:
        if self.previous is not None:
            signal.signal(signal.SIGINT, self.previous)


def run_live(field_log: str | Path, out_dir: str | Path, options: LiveOptions | None = None
             ) -> tuple[ScanResult, LiveStats]:
    """Run ``gnomon live``: the live pass, then ``gnomon scan``'s outputs into ``out_dir`` (atomically)."""
    opts = options or LiveOptions()
    started = time.perf_counter()
    log = load_field_log(field_log)
    base = frame_source(log)
    size = (log.camera.width, log.camera.height)
    source = open_source(opts.source, base, opts.max_frames, size)
    # A live pass is not read twice: its dips keep the field log's width (a warning says when they reach it).
    setup = resolve_scan(log, base)
    if setup.dip_width == "auto":
        setup = replace(setup, dip_width="live")
    if setup.untied:  # measured where its shadow meets the first plane's once the pass is over
        names = ", ".join(name for name, _ in setup.untied)
        setup = replace(setup, warnings=(*setup.warnings, f"live points: plane(s) {names} at a first-guess distance "
                                         "(marks without plane_xy) until the sweep ends; the final points use the "
                                         "distance their shadow lines measure"))
    if isinstance(source, CaptureSource):
        stop_when_complete = True if opts.stop_when_complete is None else opts.stop_when_complete
    else:
        stop_when_complete = bool(opts.stop_when_complete)
    fps = None
    if opts.realtime:
        fps = opts.fps or source_fps(source, log.capture.fps)
    frames = LiveFrames(source, fps, opts.buffer)
    with staged_outputs(Path(out_dir)) as staging:
        full = source.video is not None and playable_video(source.video)
        recorder = ScanRecording(staging / "scan.rrd" if opts.rrd else None, recording_name=f"live {log.path.name}",
                                 spawn_viewer=opts.view and display_available(), frame_stride=opts.frame_stride,
                                 image_scale=1.0 if full else 0.5, viewer_url=opts.connect)
        try:
            view = LiveView(setup, recorder, frames, recover=opts.recover, stop_when_complete=stop_when_complete,
                            map_stride=opts.map_stride, update_every=opts.update_every)
            view.stats.fps = fps
            with _StopOnInterrupt(frames, view.stats):
                # LiveFrames stands in for a FrameSource by duck typing (no Protocol of the two yet).
                result = scan(setup, frames, recorder, progress=opts.progress,  # type: ignore[arg-type]
                              frame_stride=opts.frame_stride, track=_live_track(view))
            write_scan(staging, result, started)
        except BaseException:
            recorder.abort()
            raise
        recorder.close()
    result.out_dir = Path(out_dir)
    return result, view.stats
