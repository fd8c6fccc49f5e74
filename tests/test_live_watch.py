"""The kernel's live watch (TemporalTracker.watch / take_finished) through the binding:
pixels are reported once the shadow has left them, with the final pass's times for a
clean sweep, and never twice."""

from __future__ import annotations

import numpy as np
import pytest

from gnomon import _kernel
from gnomon.capture.tracking import decoding_lut
from gnomon.errors import KernelParameterError

LIT, DARK = 200.0, 40.0


def sweep(height: int = 12, width: int = 40, frames: int = 90, speed: float = 0.7, band: float = 9.0,
          penumbra: float = 2.0) -> np.ndarray:
    """(frames, H, W) uint8: a dark band ``band`` px wide moving right at ``speed`` px/frame,
    edges ramped over ``penumbra`` px; the shadow's leading edge is at u = speed·t − 5."""
    u = np.arange(width, dtype=np.float64)[None, :]
    out = np.empty((frames, height, width), np.uint8)
    for t in range(frames):
        lead = speed * t - 5.0
        into = np.clip((lead - u) / penumbra, 0, 1) * np.clip((u - (lead - band)) / penumbra, 0, 1)
        out[t] = np.round(LIT - (LIT - DARK) * into).astype(np.uint8)
    return out


def run(frames: np.ndarray, recover: int = 3, lut: np.ndarray | None = None):
    t = _kernel.TemporalTracker(*frames.shape[1:], window=4, max_width=32, lut=lut)
    t.watch(20.0, recover)
    batches = []
    for f in frames:
        t.update(np.ascontiguousarray(f))
        batches.append(t.take_finished())
    return t, batches


def test_finished_pixels_carry_the_final_times_of_a_clean_sweep():
    frames = sweep()
    lut = decoding_lut("srgb", np.uint8)
    tracker, batches = run(frames, 3, lut)
    index = np.concatenate([b.index for b in batches])
    assert len(np.unique(index)) == len(index)  # never twice
    final = tracker.finish(20.0)
    valid = np.asarray(final.valid).ravel()
    # every pixel the final pass finds was finished by the watch, and nothing else
    assert set(index.tolist()) == set(np.flatnonzero(valid).tolist())
    enter = np.concatenate([b.enter for b in batches])
    leave = np.concatenate([b.leave for b in batches])
    np.testing.assert_array_equal(enter, np.asarray(final.enter).ravel()[index])
    np.testing.assert_array_equal(leave, np.asarray(final.leave).ravel()[index])
    threshold = np.concatenate([b.threshold for b in batches])
    np.testing.assert_array_equal(threshold, np.asarray(final.threshold).ravel()[index])
    assert tracker.watch_counts == (frames[0].size - len(index), 0, len(index))


@pytest.mark.parametrize("recover", [1, 3, 5])
def test_a_pixel_is_finished_recover_frames_after_it_is_lit_again(recover):
    frames = sweep()
    _, batches = run(frames, recover)
    for k, b in enumerate(batches):
        assert np.all(b.frame == k)
        # the first frame at or above the DN mid-level after the dip is ceil(leave) for a
        # linear ramp; the pixel is finished `recover − 1` frames later
        np.testing.assert_array_equal(np.ceil(b.leave).astype(np.int64) + recover - 1, b.frame)


def test_the_watch_is_checked():
    t = _kernel.TemporalTracker(4, 5)
    assert t.watch_counts is None
    with pytest.raises(KernelParameterError, match="watch"):
        t.take_finished()
    with pytest.raises(KernelParameterError, match="recover"):
        t.watch(20.0, 0)
    with pytest.raises(KernelParameterError, match="min_contrast"):
        t.watch(-1.0)
    t.watch(20.0)
    assert len(t.take_finished()) == 0
    assert t.watch_counts == (20, 0, 0)
