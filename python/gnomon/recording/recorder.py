"""The rerun recording of a run: its layout of entities and timelines.

Every scan, calibrate and merge run leaves a ``.rrd`` file that explains itself
in the rerun viewer and can be read back as data (:mod:`gnomon.recording.review`). The
pipeline drives a :class:`ScanRecording`; nothing here touches rerun's global
or thread-local recording: every call goes through one explicit
:class:`rerun.RecordingStream`.

Timelines
    ``frame`` (sequence: the frame index) and ``capture_time`` (timestamp, UTC,
    when the frame's time is known). rerun adds ``log_time`` (wall clock of the
    run) to everything that is not static.

Entities (paths as stored; rerun shows them with a leading ``/``)
    ``world/camera``
        static ``Transform3D`` (camera → world, i.e. the inverse of the
        calibration's world → camera ``X_cam = R·X_world + t``), ``Pinhole``
        (OpenCV RDF view coordinates) and custom ``GnomonCamera:*`` components
        holding the calibration as given: ``K`` (9, row-major, float64),
        ``resolution`` (width, height), ``R`` (9), ``t`` (3), ``units``,
        ``image_scale`` (sx, sy). The pinhole describes the *stored* images:
        its intrinsics are K scaled by ``image_scale`` and shifted by half a
        pixel, because rerun puts pixel centres at +0.5 where OpenCV (and
        Gnomon) put them at integers. The 3D frustum is the calibrated one.
    ``world``
        static ``ViewCoordinates.RIGHT_HAND_Z_UP`` (Gnomon's world frames have
        z up: the desk's normal, or up at the site for sun scans).
    ``world/camera/image``
        every ``frame_stride``-th frame, downscaled by ``image_scale`` and JPEG
        encoded (``EncodedImage``); or, for a video input whose codec rerun
        plays (H.264, H.265, AV1 in MP4), the video itself as a static
        ``AssetVideo`` with a ``VideoFrameReference`` on every frame.
    ``world/camera/depth``
        static ``DepthImage`` of the camera Z per pixel at the stored images'
        size (``meter`` 1: world units), under the pinhole: the 3D view shows
        it back-projected through the camera (lens distortion not applied).
    ``world/camera/image/edges``
        per frame, the shadow edges as ``LineStrips2D`` in the stored image's
        pixel coordinates: ``x = (u + 0.5)·sx``, ``y = (v + 0.5)·sy`` for an
        OpenCV pixel (u, v); :func:`display_to_pixels` undoes it.
    ``world/camera/image/<name>``
        per frame, 2D points such as detected chessboard corners
        (:meth:`ScanRecording.log_image_points`), same coordinates.
    ``world/shadow_plane``
        per frame, the shadow plane as a translucent quad (``Mesh3D``) with
        its outline (``LineStrips3D``), or just a polyline when given points
        on the line.
    ``world/planes/<name>``
        static, each reference plane as a quad and outline.
    ``world/light``
        the lamp as a static ``Points3D``, or the sun as an ``Arrows3D`` per
        frame drawn as the incoming light (from ``anchor + length·d`` to
        ``anchor``; ``d`` points towards the sun) with the unit direction
        in ``GnomonSun:direction``.
    ``world/points``
        static final cloud: ``Points3D`` (float32 positions, colours) plus
        ``GnomonPoints:sigma`` (float32, σ per point) and
        ``GnomonPoints:uv`` (float32 pixel coordinates) when given. Positions
        are the caller's float32 values, unchanged: reading them back gives
        the same bits as ``points.ply``.
    ``world/mesh``
        static ``Mesh3D`` (positions, triangles, vertex colours), in a ``full``
        recording only (a scan's: ``gnomon scan --rrd-full``; by default the
        points show the surface and mesh.ply holds the mesh).
    ``maps/shadow_time``, ``maps/depth``, ``maps/sigma``
        static float32 ``DepthImage`` s with colour maps (turbo, viridis,
        inferno) over the finite range; NaN (no value) is kept as NaN. At the
        stored images' size (``image_scale``, nearest pixel) unless the
        recording is ``full`` (the scan's .npy files hold them at full size).
    ``maps/coverage``
        static ``SegmentationImage`` (uint8 class per pixel) with its
        ``AnnotationContext`` naming the classes (:data:`gnomon.outputs.images.COVERAGE_CLASSES`).
    ``world/live_points/<chunk>``
        ``gnomon live`` only: the points triangulated while the shadow was
        still moving, on the ``frame`` timeline at the frame they were
        found; one entity per chunk of frames (``chunk`` = frame // chunk
        size, zero-padded), each log holding that chunk's points so far, so
        the cloud grows as the time cursor advances. ``Points3D`` coloured by
        σ (green small, red large) with ``GnomonPoints:sigma`` and ``:uv``.
    ``live/shadow_time``
        ``gnomon live`` only: the provisional shadow-time map (leaving edge,
        capture frames) as it fills in, downscaled, every few frames.
    ``log``
        ``TextLog`` of the run's warnings (level WARN) on the ``frame``
        timeline: at the frame they concern, or at frame 0 for the whole run,
        so the default layout's Warnings view lists them at every frame.
    ``metrics/<name>``
        the report's metrics as ``Scalars`` (static, or per frame when given
        an index). Nested names are joined with ``/``.

A default blueprint shows the 3D scene, the camera image with its edges, the
maps (coverage among them), the warnings and the metrics.

The recording is written to a temporary file beside ``path`` and renamed onto
``path`` only by :meth:`ScanRecording.close`: an interrupted run never leaves
a truncated ``.rrd`` that looks whole. Used as a context manager, an exception
inside the block removes the temporary file.

The file is always encoded in memory and written by Gnomon at close (an
``OSError`` naming ``path`` on a full disk or past a file-size limit), never
by rerun's own file writer, which waits forever once its disk is full; a
viewer gets the same messages through a second sink.

No network: a file recording never connects anywhere. ``spawn_viewer=True``
starts a local viewer and streams to it over localhost, only where a display
exists (otherwise it logs why and carries on with the file alone);
``viewer_url`` streams to a viewer (or a rerun gRPC server) already listening
there instead. Closing waits at most :data:`VIEWER_FLUSH_TIMEOUT_S` for the
viewer; one that is gone keeps what it received.
"""

from __future__ import annotations

import logging
import os
import re
import sys
import threading
import uuid
from collections.abc import Callable, Mapping, Sequence
from contextlib import AbstractContextManager
from datetime import UTC, datetime
from pathlib import Path
from types import TracebackType
from typing import Any

import cv2
import numpy as np

from gnomon.errors import GnomonError
from gnomon.util.atomic import atomic_path

__all__ = [
    "ScanRecording",
    "add_recording_arguments",
    "recording_from_args",
    "default_blueprint",
    "display_available",
    "display_to_pixels",
    "playable_video",
    "warm_rerun_import",
    "ENTITY",
]

log = logging.getLogger(__name__)

# Entity paths, in one place so that review.py and the tests agree with the writer.
ENTITY = {
    "camera": "world/camera",
    "image": "world/camera/image",
    "edges": "world/camera/image/edges",
    "shadow_plane": "world/shadow_plane",
    "planes": "world/planes",
    "light": "world/light",
    "points": "world/points",
    "mesh": "world/mesh",
    "shadow_time": "maps/shadow_time",
    "depth": "maps/depth",
    "sigma": "maps/sigma",
    "coverage": "maps/coverage",
    "camera_depth": "world/camera/depth",
    "live_points": "world/live_points",
    "live_shadow_time": "live/shadow_time",
    "log": "log",
    "metrics": "metrics",
    "summary": "summary",
}

TIMELINE_FRAME = "frame"
TIMELINE_CAPTURE = "capture_time"

_PLANE_COLOURS = [
    (80, 160, 255), (120, 220, 120), (230, 140, 60), (200, 110, 220), (240, 220, 90),
]
_SHADOW_PLANE_RGBA = (255, 170, 0, 70)
_LIGHT_RGB = (255, 220, 60)
_EDGE_RGB = (255, 40, 40)

#: How long closing a recording waits for a viewer to take the rest of it (seconds).
VIEWER_FLUSH_TIMEOUT_S = 10.0

_units_per_metre = {"mm": 1000.0, "cm": 100.0, "m": 1.0, "in": 1000.0 / 25.4, "ft": 1000.0 / 304.8}


def display_available() -> bool:
    """Whether a viewer window could open here (X11/Wayland on Linux; assumed elsewhere)."""
    platform: str = sys.platform  # a plain str: mypy would judge the branches for its own platform only
    if platform.startswith("linux") or "bsd" in platform:
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


def display_to_pixels(xy: np.ndarray, image_scale: Sequence[float]) -> np.ndarray:
    """Stored-image coordinates (rerun convention) → OpenCV full-resolution pixels.

    Inverse of the mapping used for ``world/camera/image/*``:
    ``u = x / sx − 0.5``, ``v = y / sy − 0.5``.
    """
    xy = np.asarray(xy, dtype=np.float64)
    sx, sy = float(image_scale[0]), float(image_scale[1])
    return np.stack([xy[..., 0] / sx - 0.5, xy[..., 1] / sy - 0.5], axis=-1)


def _safe_part(name: str) -> str:
    part = re.sub(r"[^A-Za-z0-9_.\-]+", "_", str(name)).strip("_")
    return part or "_"


def _utc(t: datetime | np.datetime64) -> datetime | np.datetime64:
    if isinstance(t, datetime):
        return t.replace(tzinfo=UTC) if t.tzinfo is None else t.astimezone(UTC)
    return t


def _finite_range(a: np.ndarray) -> tuple[float, float] | None:
    finite = a[np.isfinite(a)]
    if finite.size == 0:
        return None
    lo, hi = float(finite.min()), float(finite.max())
    if hi <= lo:
        hi = lo + 1.0
    return lo, hi


def _packed_rgba(rgb: np.ndarray) -> np.ndarray:
    """(N,) uint32 colours packed as rerun stores them (0xRRGGBBAA, opaque) from uint8 (N, 3) RGB.

    rerun packs an (N, 3) uint8 array itself through a (4, N) stack and its transpose (≈ 0.3 s for a
    million colours); the packed values it takes as they are.
    """
    c = np.asarray(rgb, dtype=np.uint8).reshape(-1, 3).astype(np.uint32)
    packed = c[:, 0] << np.uint32(24)
    packed |= c[:, 1] << np.uint32(16)
    packed |= c[:, 2] << np.uint32(8)
    packed |= np.uint32(0xFF)
    return packed


def playable_video(path: str | os.PathLike) -> bool:
    """Whether rerun can store and play this video as an ``AssetVideo`` (codec and container)."""
    try:
        return len(_rr().AssetVideo(path=str(path)).read_frame_timestamps_nanos()) > 0
    except Exception:  # unsupported codec or container, unreadable file
        return False


def _rr():
    import rerun as rr  # imported lazily: a disabled recorder never loads rerun

    return rr


_rerun_warm: threading.Thread | None = None


def warm_rerun_import() -> None:
    """Import rerun (≈ 1 s) on a daemon thread, once, so that a recorder opened later finds it loaded.

    A failed import is left for the recorder's own import to report.
    """
    global _rerun_warm
    if _rerun_warm is None:
        def load() -> None:
            try:
                _rr()
            except Exception:  # pragma: no cover - the recorder's own import reports it
                pass
        _rerun_warm = threading.Thread(target=load, name="gnomon-import-rerun", daemon=True)
        _rerun_warm.start()


def _run_starts(frames: Sequence[int]) -> list[int]:
    """The first frame of each run of consecutive frames, in order."""
    ordered = sorted(set(int(f) for f in frames))
    return [f for i, f in enumerate(ordered) if i == 0 or ordered[i - 1] != f - 1]


def default_blueprint():
    """The default viewer layout: 3D scene | camera image + edges, maps, log and metrics."""
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(name="Scene", origin="world"),
            rrb.Vertical(
                rrb.Spatial2DView(name="Camera", origin=ENTITY["image"]),
                rrb.Tabs(
                    rrb.Spatial2DView(name="Shadow time", origin=ENTITY["shadow_time"]),
                    rrb.Spatial2DView(name="Live shadow time", origin=ENTITY["live_shadow_time"]),
                    rrb.Spatial2DView(name="Depth", origin=ENTITY["depth"]),
                    rrb.Spatial2DView(name="σ", origin=ENTITY["sigma"]),
                    rrb.Spatial2DView(name="Coverage", origin=ENTITY["coverage"]),
                ),
                rrb.Tabs(
                    rrb.TextLogView(name="Warnings", origin=ENTITY["log"]),
                    rrb.TextDocumentView(name="Metrics", origin=ENTITY["summary"]),
                    rrb.DataframeView(name="Metric values", origin=ENTITY["metrics"]),
                ),
                row_shares=[2, 2, 1],
            ),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(timeline=TIMELINE_FRAME),
        collapse_panels=False,
    )


class ScanRecording(AbstractContextManager["ScanRecording"]):
    """One run's rerun recording, driven by the pipeline.

    ``path`` the ``.rrd`` to write (None: no file). ``spawn_viewer`` also
    stream to a local viewer (only where a display exists); ``viewer_url``
    (``rerun+http://host:port/proxy``) to one already running. With neither,
    the recorder is disabled: every method is a no-op and rerun is never loaded.
    Why a viewer asked for did not start is in ``notes`` (and logged as a
    warning unless ``log_notes`` is False: the scan reports it with its warnings).

    ``frame_stride`` store every n-th frame image (index % stride == 0);
    ``image_scale`` (0, 1] downscale of stored images; ``jpeg_quality`` 1..100.
    ``full``: the maps at full size (else at the stored images' size) and the mesh (else none: a
    scan's default, whose points show the surface).
    """

    def __init__(
        self,
        path: Path | str | None,
        *,
        application_id: str = "gnomon",
        recording_name: str,
        spawn_viewer: bool = False,
        frame_stride: int = 10,
        image_scale: float = 0.5,
        jpeg_quality: int = 80,
        viewer_port: int = 9876,
        viewer_url: str | None = None,
        log_notes: bool = True,
        full: bool = True,
    ) -> None:
        if int(frame_stride) < 1:
            raise ValueError(f"frame_stride must be >= 1, got {frame_stride}")
        if not (0.0 < float(image_scale) <= 1.0):
            raise ValueError(f"image_scale must be in (0, 1], got {image_scale}")
        if not (1 <= int(jpeg_quality) <= 100):
            raise ValueError(f"jpeg_quality must be in 1..100, got {jpeg_quality}")
        self.path = Path(path) if path is not None else None
        self.recording_name = recording_name
        self.frame_stride = int(frame_stride)
        self.image_scale = float(image_scale)
        self.jpeg_quality = int(jpeg_quality)
        self.full = bool(full)
        self.viewer_spawned = False
        self.notes: list[str] = []  # why a viewer asked for did not start
        self._summary: dict[str, float] = {}  # the static metrics logged so far (the Metrics view's table)
        self._log_notes = bool(log_notes)
        self.frames_seen = 0
        self.frames_stored = 0

        self._rec: Any = None
        self._atomic: Any = None
        self._tmp: Path | None = None
        self._stream: Any = None  # rerun's in-memory encoder when we write the file ourselves
        self._closed = False
        self._camera_size: tuple[int, int] | None = None
        self._units: str | None = None
        self._u16_shift: int | None = None
        self._capture_times: dict[int, datetime | np.datetime64] = {}
        self._planes_logged = 0
        self._video_ns: np.ndarray | None = None  # frame timestamps of an AssetVideo input

        want_viewer = bool(spawn_viewer) or viewer_url is not None
        if want_viewer and viewer_url is None and not display_available():
            self._note("no display here (DISPLAY and WAYLAND_DISPLAY unset): no rerun viewer started"
                       + ("; the recording goes to its file only" if self.path is not None else ""))
            want_viewer = False
        if self.path is None and not want_viewer:
            return  # disabled

        rr = _rr()
        rec = rr.RecordingStream(application_id, recording_id=uuid.uuid4())
        try:
            if self.path is not None:
                self._atomic = atomic_path(self.path)
                self._tmp = self._atomic.__enter__()
                # Encoded in memory, written by close(), also when a viewer watches: rerun's file writer
                # dies on a full disk or a file-size limit and every later flush then waits forever;
                # our write fails at once with an OSError naming the file.
                self._stream = rr.binary_stream(recording=rec)
            viewer = None
            if want_viewer:
                try:
                    url = viewer_url
                    if url is None:
                        rec.spawn(port=viewer_port, connect=False)
                        url = f"rerun+http://127.0.0.1:{viewer_port}/proxy"
                    viewer = rr.GrpcSink(url)
                except Exception as exc:  # no viewer binary, port in use, a malformed URL, ...
                    self._note(f"could not start the rerun viewer: {exc}")
            if viewer is not None:
                # The viewer's stream beside the in-memory file: both get every message.
                rec.set_sinks(viewer, *([self._stream] if self._stream is not None else []))
                self.viewer_spawned = True
            elif self._stream is None:
                return  # viewer wanted, failed, and no file: disabled
            # active: the file opens in this layout (make_default alone leaves a viewer with the layout of its
            # last recording, or its own heuristic one, until the user resets the blueprint)
            rr.send_blueprint(default_blueprint(), make_active=True, make_default=True, recording=rec)
            rec.send_recording_name(recording_name)
            rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        except BaseException:
            self._rec = rec
            self.abort()
            raise
        self._rec = rec

    def _note(self, text: str) -> None:
        self.notes.append(text)
        if self._log_notes:
            log.warning("%s", text)

    # ------------------------------------------------------------------ state

    @property
    def enabled(self) -> bool:
        """False for the no-op recorder (and after close/abort)."""
        return self._rec is not None and not self._closed

    @property
    def stream(self):
        """The underlying :class:`rerun.RecordingStream` (None when disabled)."""
        return self._rec if self.enabled else None

    def set_time(self, index: int, capture_time: datetime | np.datetime64 | None = None) -> None:
        """Set the ``frame`` (and ``capture_time``) for later logs from this thread.

        A frame's capture time is remembered: later calls for the same index
        without one (``log_edges(i, ...)`` after ``log_frame(i, img, t)``) reuse
        it. A frame whose time was never given gets no ``capture_time`` (never
        the previous frame's).
        """
        if not self.enabled:
            return
        index = int(index)
        self._rec.set_time(TIMELINE_FRAME, sequence=index)
        if capture_time is not None:
            capture_time = _utc(capture_time)
            self._capture_times[index] = capture_time
        else:
            capture_time = self._capture_times.get(index)
        if capture_time is not None:
            self._rec.set_time(TIMELINE_CAPTURE, timestamp=capture_time)
        elif self._capture_times:
            self._rec.disable_timeline(TIMELINE_CAPTURE)

    def _scale_xy(self) -> tuple[float, float]:
        if self._camera_size is None:
            return self.image_scale, self.image_scale
        w, h = self._camera_size
        dw, dh = self._display_size(w, h)
        return dw / w, dh / h

    def _display_size(self, w: int, h: int) -> tuple[int, int]:
        return max(1, int(round(w * self.image_scale))), max(1, int(round(h * self.image_scale)))

    def _to_display_size(self, image: np.ndarray) -> np.ndarray:
        """A per-pixel map (H, W) of the camera's image resampled (nearest) to the stored images' size."""
        h, w = image.shape
        dsize = self._display_size(*(self._camera_size or (w, h)))
        return image if dsize == (w, h) else cv2.resize(image, dsize, interpolation=cv2.INTER_NEAREST)

    # ------------------------------------------------------------------ camera and frames

    def log_camera(
        self,
        K: np.ndarray,
        width: int,
        height: int,
        R: np.ndarray,
        t: np.ndarray,
        units: str,
        *,
        index: int | None = None,
        capture_time: datetime | None = None,
        image_plane_distance: float | None = None,
    ) -> None:
        """The calibrated camera at ``world/camera``.

        ``K`` (3, 3) intrinsics in pixels (OpenCV), ``width``/``height`` the
        full image size, ``R``/``t`` world → camera (``X_cam = R·X_world + t``),
        ``units`` the world units. Static unless ``index`` is given (e.g. one
        pose per chessboard view in a calibrate run). ``image_plane_distance``
        sets the drawn frustum depth (default: a quarter of the camera's
        distance to the world origin).
        """
        if not self.enabled:
            return
        rr = _rr()
        K = np.asarray(K, dtype=np.float64).reshape(3, 3)
        R = np.asarray(R, dtype=np.float64).reshape(3, 3)
        t = np.asarray(t, dtype=np.float64).reshape(3)
        w, h = int(width), int(height)
        self._camera_size = (w, h)
        self._units = str(units)
        sx, sy = self._scale_xy()
        dw, dh = self._display_size(w, h)
        Kd = np.array(
            [
                [K[0, 0] * sx, K[0, 1] * sx, (K[0, 2] + 0.5) * sx],
                [0.0, K[1, 1] * sy, (K[1, 2] + 0.5) * sy],
                [0.0, 0.0, 1.0],
            ]
        )
        centre = -R.T @ t
        if image_plane_distance is None:
            dist = float(np.linalg.norm(centre))
            image_plane_distance = 0.25 * dist if dist > 0 else 1.0
        static = index is None
        if index is not None:
            self.set_time(index, capture_time)
        self._rec.log(
            ENTITY["camera"],
            rr.Transform3D(translation=centre, mat3x3=R.T),
            rr.Pinhole(
                image_from_camera=Kd,
                resolution=[dw, dh],
                camera_xyz=rr.ViewCoordinates.RDF,
                image_plane_distance=float(image_plane_distance),
            ),
            rr.DynamicArchetype(
                "GnomonCamera",
                components={
                    "K": K.ravel(),
                    "resolution": np.array([w, h], dtype=np.int64),
                    "R": R.ravel(),
                    "t": t,
                    "units": str(units),
                    "image_scale": np.array([sx, sy], dtype=np.float64),
                },
            ),
            static=static,
        )

    def _to_u8(self, image: np.ndarray) -> np.ndarray:
        img = np.asarray(image)
        if img.dtype == np.uint8:
            return img
        if img.dtype == np.uint16:
            if self._u16_shift is None:  # fixed per recording: no flicker between frames
                self._u16_shift = max(int(img.max()).bit_length() - 8, 0)
            return np.clip(img >> self._u16_shift, 0, 255).astype(np.uint8)
        if img.dtype == np.bool_:
            return img.astype(np.uint8) * 255
        if np.issubdtype(img.dtype, np.floating):
            return (np.clip(np.nan_to_num(img), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
        raise TypeError(f"unsupported frame dtype {img.dtype}")

    def log_frame(
        self,
        index: int,
        image: np.ndarray | None,
        capture_time: datetime | np.datetime64 | None = None,
    ) -> bool:
        """Set the time to frame ``index``; store the image if ``index % frame_stride == 0``.

        ``image`` (H, W) uint8/uint16 grey or (H, W, 3) RGB uint8; None for a
        frame that is not stored (its time only). uint16 is shifted to 8 bits
        (one shift for the whole recording, from the first uint16 frame).
        Returns whether the image was stored.
        """
        if not self.enabled:
            return False
        self.set_time(index, capture_time)
        self.frames_seen += 1
        if self._video_ns is not None:
            if 0 <= int(index) < len(self._video_ns):
                self._rec.log(ENTITY["image"], _rr().VideoFrameReference(nanoseconds=int(self._video_ns[int(index)])))
                self.frames_stored += 1
                return True
            return False
        if int(index) % self.frame_stride != 0:
            return False
        if image is None:
            raise ValueError(f"frame {index} is stored (frame_stride {self.frame_stride}) but has no image")
        rr = _rr()
        img = self._to_u8(image)
        if img.ndim == 3 and img.shape[2] == 4:
            img = img[:, :, :3]
        if img.ndim == 3 and img.shape[2] == 1:
            img = img[:, :, 0]
        if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3):
            raise ValueError(f"frame must be (H, W) or (H, W, 3), got {img.shape}")
        h, w = img.shape[:2]
        dsize = self._display_size(*(self._camera_size or (w, h)))
        if dsize != (w, h):
            img = cv2.resize(img, dsize, interpolation=cv2.INTER_AREA)
        if img.ndim == 3:
            img = cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, self.jpeg_quality])
        if not ok:  # pragma: no cover - OpenCV always encodes a valid u8 image
            raise RuntimeError("JPEG encoding failed")
        self._rec.log(ENTITY["image"], rr.EncodedImage(contents=buf.tobytes(), media_type="image/jpeg"))
        self.frames_stored += 1
        return True

    def log_video(self, path: str | os.PathLike, frame_count: int) -> bool:
        """Store a video input as it is: a static ``AssetVideo`` at ``world/camera/image``.

        Later :meth:`log_frame` calls then log a ``VideoFrameReference`` to
        their frame instead of a JPEG still. Only where rerun can play the
        video (its codec and container) and it has ``frame_count`` frames;
        otherwise nothing is logged, frames stay JPEG stills, and the reason
        is returned False (and logged at debug level). Call before the first
        frame. The video must have the camera's full size: build the recorder
        with ``image_scale=1``.
        """
        if not self.enabled:
            return False
        rr = _rr()
        try:
            asset = rr.AssetVideo(path=str(path))
            ns = np.asarray(asset.read_frame_timestamps_nanos(), dtype=np.int64)
        except Exception as exc:  # unsupported codec or container: keep JPEG stills
            log.debug("%s: not stored as a video (%s)", path, exc)
            return False
        if len(ns) < int(frame_count):
            log.debug("%s: %d frame timestamps for %d frames", path, len(ns), frame_count)
            return False
        self._rec.log(ENTITY["image"], asset, static=True)
        self._video_ns = ns
        return True

    def _to_display(self, pixels: np.ndarray) -> np.ndarray:
        sx, sy = self._scale_xy()
        p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        return np.stack([(p[:, 0] + 0.5) * sx, (p[:, 1] + 0.5) * sy], axis=1).astype(np.float32)

    def log_edges(
        self,
        index: int,
        polylines: Sequence[np.ndarray],
        capture_time: datetime | np.datetime64 | None = None,
    ) -> None:
        """Shadow edges of frame ``index``: polylines (K, 2) in OpenCV pixels."""
        if not self.enabled:
            return
        rr = _rr()
        self.set_time(index, capture_time)
        strips = [self._to_display(p) for p in polylines if len(p) >= 2]
        self._rec.log(
            ENTITY["edges"],
            rr.LineStrips2D(strips, colors=[_EDGE_RGB], radii=rr.Radius.ui_points(1.5), draw_order=20.0),
        )

    def log_image_points(
        self,
        index: int,
        pixels: np.ndarray,
        name: str = "corners",
        capture_time: datetime | np.datetime64 | None = None,
    ) -> None:
        """2D points of frame ``index`` (e.g. chessboard corners) at ``world/camera/image/<name>``."""
        if not self.enabled:
            return
        rr = _rr()
        self.set_time(index, capture_time)
        self._rec.log(
            f"{ENTITY['image']}/{_safe_part(name)}",
            rr.Points2D(self._to_display(pixels), radii=rr.Radius.ui_points(3.0), colors=[(0, 255, 120)]),
        )

    # ------------------------------------------------------------------ 3D geometry

    def _quad_or_line(self, pts: np.ndarray, rgba: tuple[int, int, int, int]) -> list:
        rr = _rr()
        pts = np.asarray(pts, dtype=np.float32).reshape(-1, 3)
        if len(pts) == 4:
            outline = np.vstack([pts, pts[:1]])
            return [
                rr.Mesh3D(
                    vertex_positions=pts,
                    triangle_indices=np.array([[0, 1, 2], [0, 2, 3]], dtype=np.uint32),
                    albedo_factor=rgba,
                ),
                rr.LineStrips3D([outline], colors=[rgba[:3]], radii=rr.Radius.ui_points(1.0)),
            ]
        return [rr.LineStrips3D([pts], colors=[rgba[:3]], radii=rr.Radius.ui_points(2.0))]

    def log_shadow_plane(
        self,
        index: int,
        corners_world: np.ndarray,
        capture_time: datetime | np.datetime64 | None = None,
    ) -> None:
        """The shadow plane of frame ``index``: 4 corners (a quad) or points on the shadow line."""
        if not self.enabled:
            return
        self.set_time(index, capture_time)
        self._rec.log(ENTITY["shadow_plane"], *self._quad_or_line(corners_world, _SHADOW_PLANE_RGBA))

    def log_reference_plane(self, name: str, corners_world: np.ndarray) -> None:
        """A reference plane at ``world/planes/<name>`` (static), 4 corners in order."""
        if not self.enabled:
            return
        rgb = _PLANE_COLOURS[self._planes_logged % len(_PLANE_COLOURS)]
        self._planes_logged += 1
        self._rec.log(
            f"{ENTITY['planes']}/{_safe_part(name)}",
            *self._quad_or_line(corners_world, (*rgb, 60)),
            static=True,
        )

    def log_lamp(self, position_world: np.ndarray, sigma: float | None = None) -> None:
        """The lamp as a point at ``world/light`` (static); ``sigma`` its position uncertainty."""
        if not self.enabled:
            return
        rr = _rr()
        extra = []
        if sigma is not None:
            extra.append(rr.DynamicArchetype("GnomonLamp", components={"sigma": np.float64(sigma)}))
        self._rec.log(
            ENTITY["light"],
            rr.Points3D(
                np.asarray(position_world, dtype=np.float32).reshape(1, 3),
                colors=[_LIGHT_RGB],
                radii=rr.Radius.ui_points(8.0),
                labels=["lamp"],
            ),
            *extra,
            static=True,
        )

    def log_sun(
        self,
        index: int,
        direction_world: np.ndarray,
        anchor_world: np.ndarray,
        length: float,
        capture_time: datetime | np.datetime64 | None = None,
    ) -> None:
        """The sun at frame ``index``: ``direction_world`` points towards the sun.

        Drawn as the incoming light, an arrow from ``anchor + length·d`` to
        ``anchor``; the unit direction is kept in ``GnomonSun:direction``.
        """
        if not self.enabled:
            return
        rr = _rr()
        d = np.asarray(direction_world, dtype=np.float64).reshape(3)
        d = d / np.linalg.norm(d)
        a = np.asarray(anchor_world, dtype=np.float64).reshape(3)
        self.set_time(index, capture_time)
        self._rec.log(
            ENTITY["light"],
            rr.Arrows3D(
                vectors=[(-d * float(length)).astype(np.float32)],
                origins=[(a + d * float(length)).astype(np.float32)],
                colors=[_LIGHT_RGB],
                labels=["sun"],
            ),
            rr.DynamicArchetype("GnomonSun", components={"direction": d}),
        )

    def log_points(
        self,
        xyz_world: np.ndarray,
        rgb: np.ndarray | None,
        sigma: np.ndarray | None = None,
        *,
        uv: np.ndarray | None = None,
        entity: str = ENTITY["points"],
    ) -> None:
        """The final cloud (static): float32 (N, 3), uint8 (N, 3) colours, σ (N,), pixel uv (N, 2).

        The float32 positions are stored unchanged (read back bit-for-bit).
        """
        if not self.enabled:
            return
        rr = _rr()
        xyz = np.asarray(xyz_world)
        if xyz.dtype != np.float32:
            xyz = xyz.astype(np.float32)
        xyz = np.ascontiguousarray(xyz.reshape(-1, 3))
        n = len(xyz)
        archetypes: list = [
            rr.Points3D(
                xyz,
                colors=None if rgb is None else _packed_rgba(np.asarray(rgb).reshape(n, 3)),
                radii=rr.Radius.ui_points(1.5),
            )
        ]
        extra: dict[str, Any] = {}
        if sigma is not None:
            extra["sigma"] = np.ascontiguousarray(np.asarray(sigma, dtype=np.float32).reshape(n))
        if uv is not None:
            extra["uv"] = np.ascontiguousarray(np.asarray(uv, dtype=np.float32).reshape(n, 2)).ravel()
        if self._units is not None:
            extra["units"] = self._units
        if extra:
            archetypes.append(rr.DynamicArchetype("GnomonPoints", components=extra))
        self._rec.log(entity, *archetypes, static=True)

    def log_mesh(self, vertices: np.ndarray, faces: np.ndarray, rgb: np.ndarray | None = None) -> None:
        """The mesh at ``world/mesh`` (static): float32 (N, 3), int (M, 3) triangles, uint8 (N, 3); nothing
        unless the recording is ``full``."""
        if not self.enabled or not self.full:
            return
        rr = _rr()
        v = np.ascontiguousarray(np.asarray(vertices, dtype=np.float32).reshape(-1, 3))
        f = np.asarray(faces).reshape(-1, 3)
        # int32 indices (the scan's) are reinterpreted, the same bits astype gives, without a copy
        f = np.ascontiguousarray(f).view(np.uint32) if f.dtype == np.int32 else np.ascontiguousarray(
            f.astype(np.uint32))
        colours = None if rgb is None else _packed_rgba(rgb)
        self._rec.log(
            ENTITY["mesh"],
            rr.Mesh3D(vertex_positions=v, triangle_indices=f, vertex_colors=colours),
            static=True,
        )

    # ------------------------------------------------------------------ maps, log, metrics

    def log_maps(
        self,
        shadow_time: np.ndarray | None,
        depth: np.ndarray | None = None,
        sigma: np.ndarray | None = None,
    ) -> None:
        """Per-pixel maps (H, W) float32, NaN = no value, as colour-mapped depth images (static); unless the
        recording is ``full``, resampled (nearest) to the stored images' size."""
        if not self.enabled:
            return
        rr = _rr()
        per_m = _units_per_metre.get(self._units or "", 1.0)
        for key, arr, cmap, meter in (
            ("shadow_time", shadow_time, "turbo", 1.0),
            ("depth", depth, "viridis", per_m),
            ("sigma", sigma, "inferno", per_m),
        ):
            if arr is None:
                continue
            a = np.ascontiguousarray(np.asarray(arr, dtype=np.float32))
            if a.ndim != 2:
                raise ValueError(f"{key} map must be (H, W), got {a.shape}")
            if not self.full:
                a = self._to_display_size(a)
            rng = _finite_range(a)
            self._rec.log(
                ENTITY[key],
                rr.DepthImage(a, meter=meter, colormap=cmap, depth_range=rng),
                static=True,
            )

    def log_camera_depth(self, depth: np.ndarray) -> None:
        """Camera Z per pixel (H, W), world units, NaN = none, under the camera (static).

        Resampled (nearest) to the stored images' size so that it matches the
        pinhole; the 3D view back-projects it through the camera.
        """
        if not self.enabled:
            return
        rr = _rr()
        d: np.ndarray = np.asarray(depth, dtype=np.float32)
        if d.ndim != 2:
            raise ValueError(f"depth must be (H, W), got {d.shape}")
        d = self._to_display_size(d)
        self._rec.log(
            ENTITY["camera_depth"],
            rr.DepthImage(np.ascontiguousarray(d), meter=1.0, colormap="viridis", depth_range=_finite_range(d)),
            static=True,
        )

    def log_coverage(self, classes: np.ndarray) -> None:
        """The coverage map (H, W) uint8 at ``maps/coverage`` with its class names (static)."""
        if not self.enabled:
            return
        rr = _rr()
        from gnomon.outputs.images import COVERAGE_CLASSES

        c = np.ascontiguousarray(np.asarray(classes, dtype=np.uint8))
        if c.ndim != 2:
            raise ValueError(f"coverage must be (H, W), got {c.shape}")
        self._rec.log(
            ENTITY["coverage"],
            rr.AnnotationContext([rr.AnnotationInfo(id=k, label=name, color=rgb)
                                  for k, (name, rgb) in COVERAGE_CLASSES.items()]),
            rr.SegmentationImage(c),
            static=True,
        )

    def log_warning(
        self,
        text: str,
        *,
        index: int | None = None,
        capture_time: datetime | np.datetime64 | None = None,
        level: str = "WARN",
    ) -> None:
        """A warning in ``log`` on the ``frame`` timeline: at frame ``index`` if given; for a
        :class:`~gnomon.errors.FrameNote`, at the first frame of each run of the frames it concerns
        (eight runs at most); else at frame 0 (a run's warning belongs to the whole run: from its
        start it is listed in the Warnings view at every frame)."""
        if not self.enabled:
            return
        rr = _rr()
        frames = [index] if index is not None else _run_starts(getattr(text, "frames", ()))[:8] or [0]
        for frame in frames:
            self.set_time(frame, capture_time)
            self._rec.log(ENTITY["log"], rr.TextLog(str(text), level=level))

    def log_metrics(self, metrics: Mapping[str, Any], *, index: int | None = None) -> None:
        """Numbers of the report as ``metrics/<name>`` Scalars (nested dicts joined with ``/``).

        Static unless ``index`` is given. Non-numeric values are skipped.
        """
        if not self.enabled:
            return
        rr = _rr()
        if index is not None:
            self.set_time(index)
        numbers = list(_flatten_numbers(metrics))
        for name, value in numbers:
            self._rec.log(f"{ENTITY['metrics']}/{name}", rr.Scalars(value), static=index is None)
        if index is None:  # the run's figures, also as a table the Metrics view shows as it is
            self._summary.update(numbers)
            rows = "\n".join(f"| {name} | {value:.6g} |" for name, value in sorted(self._summary.items()))
            self._rec.log(ENTITY["summary"], rr.TextDocument(f"| metric | value |\n|---|---|\n{rows}\n",
                                                             media_type=rr.MediaType.MARKDOWN), static=True)

    # ------------------------------------------------------------------ live view (gnomon live)

    def log_live_points(self, index: int, chunk: int, xyz_world: np.ndarray, rgb: np.ndarray,
                        sigma: np.ndarray, uv: np.ndarray) -> None:
        """At frame ``index``: chunk ``chunk``'s points so far at ``world/live_points/<chunk>``
        (float32 (N, 3) world, uint8 (N, 3), σ (N,), pixel uv (N, 2))."""
        if not self.enabled:
            return
        rr = _rr()
        self.set_time(index)
        xyz = np.ascontiguousarray(np.asarray(xyz_world, dtype=np.float32).reshape(-1, 3))
        n = len(xyz)
        extra: dict[str, Any] = {
            "sigma": np.ascontiguousarray(np.asarray(sigma, dtype=np.float32).reshape(n)),
            "uv": np.ascontiguousarray(np.asarray(uv, dtype=np.float32).reshape(n, 2)).ravel(),
        }
        self._rec.log(f"{ENTITY['live_points']}/{int(chunk):05d}",
                      rr.Points3D(xyz, colors=_packed_rgba(np.asarray(rgb).reshape(n, 3)),
                                  radii=rr.Radius.ui_points(1.5)),
                      rr.DynamicArchetype("GnomonPoints", components=extra))

    def log_live_map(self, index: int, shadow_time: np.ndarray) -> None:
        """At frame ``index``: the provisional shadow-time map (H, W) float32 (NaN = none)."""
        if not self.enabled:
            return
        rr = _rr()
        self.set_time(index)
        a = np.ascontiguousarray(np.asarray(shadow_time, dtype=np.float32))
        self._rec.log(ENTITY["live_shadow_time"],
                      rr.DepthImage(a, meter=1.0, colormap="turbo", depth_range=_finite_range(a)))

    # ------------------------------------------------------------------ closing

    def submit(self, fn: Callable[[ScanRecording], object]) -> None:
        """Run ``fn(self)`` now (:class:`gnomon.recording.worker.Recorder`: a scan's calls)."""
        fn(self)

    def scan_done(self) -> None:
        """Nothing: a recording stays open for whoever opened it (:meth:`close`)."""

    def close(self) -> None:
        """Flush, finish the file and rename it onto ``path``. Idempotent."""
        if self._rec is None or self._closed:
            self._closed = True
            return
        self._closed = True
        rec, self._rec = self._rec, None
        try:
            if self.viewer_spawned:
                # The viewer gets a bounded wait: one that is slow or gone (closed by the user) is left
                # with what it has; the file's bytes are in memory either way.
                try:
                    rec.flush(timeout_sec=VIEWER_FLUSH_TIMEOUT_S)
                except Exception as exc:
                    log.warning("the rerun viewer did not take the whole recording: %s", exc)
            if self._stream is not None:
                # in memory: no disk involved, cannot hang on one
                data = self._stream.read(flush=not self.viewer_spawned)
                rec.disconnect()
                self._write_file(data or b"", self._stream.read(flush=False) or b"")
            else:
                rec.disconnect()
        except BaseException as exc:
            self._finish_file(exc)
            raise
        self._finish_file(None)

    def _write_file(self, *parts: bytes) -> None:
        """The encoded recording into the temporary file; a failed write names ``path``."""
        assert self._tmp is not None
        try:
            with open(self._tmp, "wb") as fh:
                for part in parts:
                    fh.write(part)
        except OSError as exc:
            raise type(exc)(exc.errno, exc.strerror, str(self.path)) from None

    def abort(self) -> None:
        """Stop recording and delete the temporary file; ``path`` is left untouched."""
        if self._closed:
            return
        self._closed = True
        rec, self._rec = self._rec, None
        if rec is not None:
            try:
                rec.disconnect()
            except Exception:  # pragma: no cover - best effort
                pass
        self._finish_file(RuntimeError("recording aborted"))

    def _finish_file(self, exc: BaseException | None) -> None:
        cm, self._atomic = self._atomic, None
        if cm is None:
            return
        if exc is None:
            cm.__exit__(None, None, None)
        else:
            cm.__exit__(type(exc), exc, exc.__traceback__)

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def __del__(self) -> None:
        # Never leave a temporary file behind, never publish an unfinished recording.
        try:
            if not self._closed and self._atomic is not None:
                self.abort()
        except Exception:
            pass


def _flatten_numbers(metrics: Mapping[str, Any], prefix: str = "") -> list[tuple[str, float]]:
    out: list[tuple[str, float]] = []
    for key, value in metrics.items():
        name = f"{prefix}/{_safe_part(key)}" if prefix else _safe_part(key)
        if isinstance(value, Mapping):
            out += _flatten_numbers(value, name)
        elif isinstance(value, (bool, np.bool_)):
            out.append((name, float(value)))
        elif isinstance(value, (int, float, np.integer, np.floating)):
            out.append((name, float(value)))
    return out


# --------------------------------------------------------------------------- command-line glue


def add_recording_arguments(parser, *, what: str = "a rerun recording", default: str = "OUT/scan.rrd",
                            rrd_path: bool = True, view: bool = True, frame_stride: bool = True) -> None:
    """Add a sub-command's rerun-recording options: ``--no-rrd`` (do not write ``what``), and unless
    turned off ``--rrd PATH`` (where to write it instead of ``default``; exclusive with ``--no-rrd``),
    ``--view`` and ``--frame-stride N``. Every command that records takes them from here.
    """
    g = parser.add_argument_group("rerun recording")
    rrd = g.add_mutually_exclusive_group()
    rrd.add_argument("--no-rrd", action="store_true", help=f"do not write {what}")
    if rrd_path:
        rrd.add_argument("--rrd", type=Path, metavar="PATH", default=None,
                         help=f"where to write it (default: {default})")
    if view:
        g.add_argument("--view", action="store_true",
                       help="also stream the run to a rerun viewer (started locally; needs a display)")
    if frame_stride:
        g.add_argument("--frame-stride", type=int, default=10, metavar="N",
                       help="keep every N-th frame image in the recording (default: 10)")


def recording_from_args(
    args,
    out_dir: Path | str,
    *,
    recording_name: str,
    default_filename: str = "scan.rrd",
) -> ScanRecording:
    """The :class:`ScanRecording` asked for by :func:`add_recording_arguments`' options.

    ``--no-rrd`` without ``--view`` gives the disabled recorder. Bad values are
    user errors (:class:`GnomonError`).
    """
    rrd = getattr(args, "rrd", None)
    no_rrd = bool(getattr(args, "no_rrd", False))
    if rrd is not None and no_rrd:
        raise GnomonError("--rrd and --no-rrd exclude each other")
    stride = int(getattr(args, "frame_stride", 10))
    if stride < 1:
        raise GnomonError(f"--frame-stride must be at least 1, got {stride}")
    path = None if no_rrd else Path(rrd) if rrd is not None else Path(out_dir) / default_filename
    if path is not None and path.is_dir():
        raise GnomonError(f"--rrd {path}: is a directory")
    return ScanRecording(
        path,
        recording_name=recording_name,
        spawn_viewer=bool(getattr(args, "view", False)),
        frame_stride=stride,
    )
