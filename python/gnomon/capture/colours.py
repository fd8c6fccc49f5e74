"""The scan's colours while tracking: a few frames kept, each pixel's colour from those it is lit in.

:class:`gnomon.capture.texture.LitColour` combines them; :func:`frame_hook` keeps the samples as the
frames stream by, :func:`lit_colours` gives the (H, W, 3) image once the shadow times are known.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gnomon.capture.frames import Frame
from gnomon.capture.texture import LitColour
from gnomon.capture.tracking import (
    TrackedSequence,
)

# Colour frames kept during tracking for the scan's colours (gnomon.capture.texture).
COLOUR_SAMPLES = 5


def first_frame_colours(first_color: np.ndarray | None, first_grey: np.ndarray) -> np.ndarray:
    """Per-pixel RGB uint8 (H, W, 3) from the first frame (when no other frame was kept)."""
    rgb = first_color[:, :, ::-1] if first_color is not None else np.repeat(first_grey[:, :, None], 3, axis=2)
    if rgb.dtype == np.uint16:
        rgb = (rgb >> 8).astype(np.uint8)
    return np.ascontiguousarray(rgb, dtype=np.uint8)


def frame_hook(colour: LitColour, record: Any) -> Any:
    """on_frame for the tracker: keep the colour samples, and record the frame."""
    def on_frame(frame: Frame) -> None:
        if colour.wants(frame.index):
            colour.add(frame.index, frame.color[:, :, ::-1] if frame.color is not None else frame.grey)
        if record is not None:
            record(frame)
    return on_frame


def lit_colours(colour: LitColour, tracked: TrackedSequence) -> np.ndarray:
    """(H, W, 3) uint8: each pixel's colour from the kept frames it is lit in."""
    if not colour.indices.size or not colour.wants(int(colour.indices[0])):
        return first_frame_colours(tracked.first_color, tracked.first_grey)
    used = tracked.used
    try:
        return colour.finish(capture_frames(tracked.times.enter, used), capture_frames(tracked.times.leave, used))
    except ValueError:  # no kept frame arrived (a video shorter than announced)
        return first_frame_colours(tracked.first_color, tracked.first_grey)


def capture_frames(times: np.ndarray, used: np.ndarray) -> np.ndarray:
    """(H, W) float64 capture frame of each time in kept frames (NaN = none): linear between the kept
    frames' capture indices ``used`` (``np.interp``, clamped at both ends). With no frame skipped that is
    the time itself within ``[0, n − 1]`` (``np.interp`` is exact on the identity), without a search per pixel."""
    used = np.asarray(used).astype(np.float64)
    n = len(used)
    if n and np.array_equal(used, np.arange(n)):
        return np.where(np.isfinite(times), np.clip(np.asarray(times, dtype=np.float64), 0.0, n - 1.0), np.nan)
    steps = np.arange(n, dtype=np.float64)
    return np.where(np.isfinite(times), np.interp(np.nan_to_num(times), steps, used), np.nan)
