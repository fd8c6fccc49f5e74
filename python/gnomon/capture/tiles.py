"""Tiled scans: each image tile tracked on a Dask worker, the shadow-time maps stitched.

The tracker is per pixel: a pixel's shadow times depend on its own samples
only, once every frame has been decoded and (with ``normalize_illumination``)
divided by the frame's global gain. So a capture can be cut into R×C tiles,
each tracked on its own worker from the same frames, and the tiles' maps
pasted together are the untiled scan's maps, bit for bit. Everything global
is computed on the whole frame by every tile task alike: the illumination
gain and dip detection, the image noise, which frames the light skips. The
reference lines, shadow planes, triangulation, fusion and mesh then run once
on the stitched maps, exactly as in an untiled scan (so the reference regions
need no overlap between tiles).

A tile task streams the frames from storage itself (tasks carry paths, not
pixels; see docs/batch.md): each decodes every frame once and keeps only its
tile in the tracker, so a worker's memory is the tracker state of its tile
plus one decoded frame, not the whole image's per-pixel state.

Dask is needed only here (``pip install "gnomon[dask]"``) and imported lazily.
"""

from __future__ import annotations

import os
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from gnomon.capture.frames import Frame, FrameSource, decode_frame_file
from gnomon.capture.tracking import SecondDips, ShadowTimes, TrackedSequence, TrackerSettings, track_source
from gnomon.errors import CorruptFrameError, GnomonError

__all__ = ["TileGrid", "TileResult", "TiledTracker", "current_rss_bytes", "peak_rss_bytes", "reset_peak_rss", "stitch",
           "track_tile"]


@dataclass(frozen=True)
class TileGrid:
    """``rows`` × ``cols`` tiles of near-equal size (the remainder goes to the last row/column)."""

    rows: int
    cols: int

    @classmethod
    def parse(cls, text: str) -> TileGrid:
        """``"RxC"``, e.g. ``"2x2"``."""
        m = re.fullmatch(r"\s*(\d+)\s*[xX×]\s*(\d+)\s*", text)
        if not m or int(m[1]) < 1 or int(m[2]) < 1:
            raise GnomonError(f"--tiles {text!r}: expected ROWSxCOLS, e.g. 2x2")
        return cls(int(m[1]), int(m[2]))

    def bounds(self, shape: tuple[int, int]) -> list[tuple[int, int, int, int]]:
        """``(row0, row1, col0, col1)`` of each tile of an (H, W) image, row-major."""
        h, w = shape
        if self.rows > h or self.cols > w:
            raise GnomonError(f"--tiles {self.rows}x{self.cols}: more tiles than pixels in a {w}x{h} image")
        r = np.linspace(0, h, self.rows + 1).astype(int)
        c = np.linspace(0, w, self.cols + 1).astype(int)
        return [(int(r[i]), int(r[i + 1]), int(c[j]), int(c[j + 1]))
                for i in range(self.rows) for j in range(self.cols)]

    def __str__(self) -> str:
        return f"{self.rows}x{self.cols}"


def reset_peak_rss() -> bool:
    """Reset this process's peak resident set (Linux ``/proc/self/clear_refs``); False if unsupported."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def _status_bytes(key: str) -> int | None:
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def peak_rss_bytes() -> int | None:
    """This process's peak resident set since start or the last :func:`reset_peak_rss` (bytes; Linux)."""
    return _status_bytes("VmHWM")


def current_rss_bytes() -> int | None:
    """This process's resident set now (bytes; Linux)."""
    return _status_bytes("VmRSS")


@dataclass
class TileResult:
    """One tile's tracking: ``tracked`` (maps of the tile only), where and at what cost it ran.

    ``peak_rss_bytes``: the worker process's peak resident memory during the task;
    ``rss_start_bytes``: its resident memory when the task started.
    """

    bounds: tuple[int, int, int, int]
    tracked: TrackedSequence
    frames_digest: str | None
    worker: str | None
    peak_rss_bytes: int | None
    rss_start_bytes: int | None
    time_s: float


def track_tile(image_files: tuple[Path, ...], video: Path | None, expected_count: int | None,
               settings: TrackerSettings,
               shape: tuple[int, int], bounds: tuple[int, int, int, int], skip: np.ndarray | None,
               keep_first_frame: bool, on_corrupt: str = "error") -> TileResult:
    """Track one tile of a capture (runs on a worker; reads the frames itself).

    ``settings``: :class:`gnomon.capture.tracking.TrackerSettings`; ``shape``: the
    full image (H, W); ``bounds``: the tile's ``(row0, row1, col0, col1)``;
    ``skip``: capture frames the light excludes. The first frame is returned
    only with ``keep_first_frame`` (one tile is enough); ``on_corrupt``: as :class:`FrameSource`'s.
    """
    t0 = time.perf_counter()
    reset_peak_rss()
    rss_start = current_rss_bytes()
    source = FrameSource(tuple(image_files), video, expected_count, on_corrupt)
    r0, r1, c0, c1 = bounds
    tracked = track_source(source, settings, shape, skip=skip, crop=(slice(r0, r1), slice(c0, c1)),
                           where=f"{source.name}: tile rows {r0}:{r1}, columns {c0}:{c1}")
    if not keep_first_frame:
        tracked = replace(tracked, first_grey=tracked.first_grey[:0, :0], first_color=None)  # not sent back
    try:
        from distributed import get_worker

        worker = str(get_worker().address)
    except (ImportError, ValueError):
        worker = None
    return TileResult(bounds, tracked, source.frames_digest() if video is None else None, worker,
                      peak_rss_bytes(), rss_start, time.perf_counter() - t0)


def stitch(tiles: list[TileResult], shape: tuple[int, int]) -> TrackedSequence:
    """The whole image's :class:`~gnomon.capture.tracking.TrackedSequence` from its tiles' (each tile's
    per-pixel arrays pasted in place; the per-capture values, equal in every tile, from the first)."""
    first = next(t for t in tiles if t.tracked.first_grey.size).tracked
    for t in tiles:
        if (not np.array_equal(t.tracked.used, first.used) or t.tracked.skipped_dips != first.skipped_dips
                or t.frames_digest != tiles[0].frames_digest):
            raise GnomonError(f"tile {t.bounds}: the frames it tracked differ from the other tiles' "
                              "(did the frames change during the scan?)")
    def pasted(part: Callable[[TrackedSequence], Any], kind: type) -> Any:
        maps = {}
        for f in fields(kind):
            sample = getattr(part(tiles[0].tracked), f.name)
            maps[f.name] = np.empty(shape, dtype=sample.dtype)
        for t in tiles:
            r0, r1, c0, c1 = t.bounds
            for name, full in maps.items():
                full[r0:r1, c0:c1] = getattr(part(t.tracked), name)
        return kind(**maps)

    second = (pasted(lambda tr: tr.second, SecondDips) if all(t.tracked.second is not None for t in tiles)
              else None)
    return replace(first, times=pasted(lambda tr: tr.times, ShadowTimes), second=second)


@dataclass
class TiledTracker:
    """A drop-in for :func:`gnomon.capture.tracking.track_source` that tracks tiles on a Dask cluster.

    ``client``: a ``distributed.Client``; ``grid``: the tiles; ``frame_stride``:
    which frames the recording keeps (the client decodes only those, for it).
    After a call, ``tiles`` holds each tile's :class:`TileResult` (without its
    maps, which are in the stitched result) and ``info`` a summary for the report.
    """

    client: Any
    grid: TileGrid
    frame_stride: int = 10
    retries: int = 2
    tiles: list[TileResult] = field(default_factory=list)
    info: dict = field(default_factory=dict)

    def __call__(self, source, settings, shape: tuple[int, int], *, skip: np.ndarray | None = None,
                 on_frame=None, progress: bool = False, where: str = "[camera]"):
        from gnomon.util.dask_wait import completed
        from gnomon.util.progress import Progress

        t0 = time.perf_counter()
        bounds = self.grid.bounds(shape)
        futures = [
            self.client.submit(track_tile, source.image_files, source.video, source.expected_count, settings,
                               shape, b, skip, i == 0, getattr(source, "on_corrupt", "error"), pure=False,
                               retries=self.retries,
                               key=f"gnomon-tile-{b[0]}-{b[2]}-{os.getpid()}-{time.time_ns()}")
            for i, b in enumerate(bounds)
        ]
        if on_frame is not None and not settings.register:  # meanwhile; registered frames once their motion is known
            self._record_frames(source, on_frame)
        done = []
        with Progress("tiles", len(futures), enabled=progress) as bar:
            for fut in completed(self.client, futures, what=f"{source.name}: the tiles"):
                done.append(fut.result())  # a GnomonError on a worker is raised here, as in an untiled scan
                bar.update(len(done))
        del futures  # the workers may forget the tiles' maps now
        done.sort(key=lambda t: (t.bounds[0], t.bounds[2]))
        tracked = stitch(done, shape)
        if on_frame is not None and settings.register:
            registration = tracked.registration
            self._record_frames(source, on_frame if registration is None
                                else lambda frame: on_frame(registration.moved(frame)))
        for t in done:  # keep where and how each tile ran, not a second copy of its maps
            t.tracked = replace(t.tracked, times=None)
        self.tiles = done
        self.info = {
            "tiles": str(self.grid),
            "tile_bounds": [list(t.bounds) for t in done],
            "workers": [t.worker for t in done],
            "worker_peak_rss_bytes": [t.peak_rss_bytes for t in done],
            "worker_rss_at_start_bytes": [t.rss_start_bytes for t in done],
            "tile_time_s": [t.time_s for t in done],
            "wall_time_s": time.perf_counter() - t0,
        }
        return replace(tracked, info=self.info)

    def _record_frames(self, source, on_frame) -> None:
        """Decode, on the client, only the frames the recording and the colours keep (image files; a
        video's are skipped)."""
        n = len(source.image_files)
        wanted = set(range(0, n, max(self.frame_stride, 1))) | {i for i in source.color_frames if i < n}
        for i in sorted(wanted):
            path = source.image_files[i]
            try:
                grey, color, _ = decode_frame_file(path, i in source.color_frames)
            except CorruptFrameError:
                if getattr(source, "on_corrupt", "error") == "drop":
                    continue  # the tiles leave it out too, and the scan names it
                raise
            on_frame(Frame(i, grey, color, path.name))
