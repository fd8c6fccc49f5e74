"""Shadow times of compressed video: constant over the codec's blocks, interpolated between their centres.

A video codec codes each frame in blocks (8×8 pixels for JPEG and the
transforms of MPEG-4/H.264 at the quality phone and camera video is kept
at). A shadow edge sweeping a few pixels per frame moves *within* a block
from one frame to the next, but a strongly compressed block keeps little
more than its mean: the whole block darkens together, so every pixel of it
gets the same shadow time and the time map is a staircase of B-pixel steps
aligned with the block grid. Triangulated, a plane becomes a saw-tooth
(on the phone captures of the CMU 15-463 assignment, 8 px period, up to
5 mm peak to peak on the desk).

:func:`block_grid` recognises such a map from the map itself: the time
changes between neighbours almost only across the grid's lines (on those
captures 0.5–0.7 frame across them against 0.01 within a block). Then
:func:`deblock_times` takes each block's time as the time at its centre
(a block's mean level is its centre's when the edge crosses it at constant
speed) and gives each pixel the bilinear interpolation of the four
surrounding block centres, where all four are constant blocks of a smooth
sweep (no object edge between them); other pixels keep their time.
Uncompressed frames (the simulated captures) have no block grid and are
left as they are.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gnomon import _kernel

__all__ = ["BlockGrid", "block_grid", "deblock_times"]

# Codec block sizes looked for (pixels).
BLOCK_SIZES = (8, 16)
# A map is blocky when its mean step across the grid's lines is this many times its mean step within blocks.
MIN_STEP_RATIO = 8.0
# Steps larger than this (frames) between neighbours are object edges, not the sweep: left out of the test.
MAX_STEP = 3.0
# Four block centres are interpolated between when their times span at most this many times the
# median step between neighbouring blocks (else an object edge lies between them).
MAX_SPAN_STEPS = 4.0


@dataclass(frozen=True)
class BlockGrid:
    """The block grid of a time map: ``size`` pixels, the first whole block starting at column ``u0``
    and row ``v0``; ``ratio`` the mean step across the grid's lines over the mean step within blocks."""

    size: int
    u0: int
    v0: int
    ratio: float


def _steps(times: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """|step| between neighbours along ``axis`` (frames), 0 where there is none or it exceeds ``MAX_STEP``,
    and where there is one."""
    with np.errstate(invalid="ignore"):
        d = np.diff(times, axis=axis)
        np.abs(d, out=d)
        counted = d <= MAX_STEP
    np.copyto(d, 0.0, where=~counted)  # in place: the values np.where(counted, d, 0.0) gives
    return d, counted


def _step_profile(steps: tuple[np.ndarray, np.ndarray], axis: int, size: int) -> np.ndarray:
    """Mean step (:func:`_steps` along ``axis``) by the position of the step modulo ``size``: ``np.nanmean`` of
    the steps at each position (the same sum, over the same contiguous copy, over the same count)."""
    value, counted = steps
    out = np.full(size, np.nan)
    for k in range(size):
        part = (slice(None), slice(k, None, size)) if axis == 1 else (slice(k, None, size),)
        n = np.count_nonzero(counted[part])
        if n:
            out[k] = float(np.sum(np.array(value[part], copy=True)) / n)
    return out


def block_grid(times: np.ndarray) -> BlockGrid | None:
    """The codec block grid a shadow-time map (H, W; frames, NaN = none) is constant over, or None."""
    t = np.asarray(times, dtype=np.float64)
    if np.isfinite(t).sum() < 1000:
        return None
    steps: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # per axis, computed when first needed
    for size in BLOCK_SIZES:
        starts, ratios = [], []
        for axis in (1, 0):
            if axis not in steps:
                steps[axis] = _steps(t, axis)
            prof = _step_profile(steps[axis], axis, size)
            if not np.isfinite(prof).all():
                break
            k = int(np.argmax(prof))
            within = np.delete(prof, k)
            ratio = float(prof[k] / max(float(within.mean()), 1e-9))
            starts.append((k + 1) % size)
            ratios.append(ratio)
            if ratio < MIN_STEP_RATIO:  # not this grid whatever the other axis gives
                break
        if len(ratios) == 2 and min(ratios) >= MIN_STEP_RATIO:
            return BlockGrid(size, starts[0], starts[1], min(ratios))
    return None


def deblock_times(times: np.ndarray, grid: BlockGrid) -> np.ndarray:
    """The time map (H, W; frames) interpolated bilinearly between its blocks' centres (see the module).

    A block counts when all its pixels have a time and they agree within a
    tenth of a frame; a pixel is interpolated when the four block centres
    around it count and span at most :data:`MAX_SPAN_STEPS` times the median
    step between neighbouring blocks. Other pixels keep their times (float32).
    """
    t = np.asarray(times, dtype=np.float64)
    h, w = t.shape
    b = grid.size
    nby, nbx = (h - grid.v0) // b, (w - grid.u0) // b
    if nby < 2 or nbx < 2:
        return t.astype(np.float32)
    blocks = t[grid.v0:grid.v0 + nby * b, grid.u0:grid.u0 + nbx * b].reshape(nby, b, nbx, b)
    lo, hi = _block_min_max(blocks)
    mean = blocks.mean(axis=(1, 3))
    good = np.isfinite(lo) & np.isfinite(hi) & (hi - lo <= 0.1)
    value = np.where(good, mean, np.nan)
    steps = np.concatenate([np.abs(np.diff(value, axis=0)).ravel(), np.abs(np.diff(value, axis=1)).ravel()])
    steps = steps[np.isfinite(steps) & (steps > 0)]
    if steps.size == 0:
        return t.astype(np.float32)
    span_max = MAX_SPAN_STEPS * float(np.median(steps))
    if isinstance(times, np.ndarray) and times.dtype == np.float32:  # the kernel: rows in parallel, the same values
        return _kernel.deblock_interpolate(np.ascontiguousarray(times), np.ascontiguousarray(value), b, grid.u0,
                                           grid.v0, span_max)
    return _interpolate_numpy(t, value, grid, span_max)


def _block_min_max(blocks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each block's least and greatest time (NaN when any is NaN) of ``blocks`` (blocks down, size, blocks
    across, size): ``blocks.min(axis=(1, 3))`` and ``.max`` in one walk over the blocks' pixel offsets, each an
    element-wise minimum and maximum over all blocks at once (the strided whole-axis reductions cost twice as
    much; the order changes no minimum or maximum but the sign of a zero, which the blocks' spread does not
    see; NaN wins either way)."""
    lo = blocks[:, 0, :, 0].copy()
    hi = lo.copy()
    with np.errstate(invalid="ignore"):
        for i in range(blocks.shape[1]):
            for j in range(blocks.shape[3]):
                if i or j:
                    np.minimum(lo, blocks[:, i, :, j], out=lo)
                    np.maximum(hi, blocks[:, i, :, j], out=hi)
    return lo, hi


def _interpolate_numpy(t: np.ndarray, value: np.ndarray, grid: BlockGrid, span_max: float) -> np.ndarray:
    """:func:`deblock_times`' interpolation in numpy (the definition; the kernel's ``deblock_interpolate`` gives
    the same on float32 maps): ``t`` (H, W) float64 times, ``value`` (blocks down, blocks across) each block's
    time (NaN: it does not count), ``span_max`` the largest spread of four centres interpolated between."""
    h, w = t.shape
    b = grid.size
    nby, nbx = value.shape
    out = t.astype(np.float32)
    # Pixel → position in block-centre units: centre of block j at u0 + j·b + (b − 1)/2.
    u = (np.arange(w) - grid.u0 - (b - 1) / 2.0) / b
    v = (np.arange(h) - grid.v0 - (b - 1) / 2.0) / b
    j0 = np.floor(u).astype(int)
    i0 = np.floor(v).astype(int)
    fu, fv = u - j0, v - i0
    inside_u = (j0 >= 0) & (j0 + 1 < nbx)
    inside_v = (i0 >= 0) & (i0 + 1 < nby)
    jj = np.clip(j0, 0, nbx - 2)
    ii = np.clip(i0, 0, nby - 2)
    c00 = value[ii][:, jj]
    c01 = value[ii][:, jj + 1]
    c10 = value[ii + 1][:, jj]
    c11 = value[ii + 1][:, jj + 1]
    corners = np.stack([c00, c01, c10, c11])
    with np.errstate(invalid="ignore"):
        span = corners.max(axis=0) - corners.min(axis=0)
    ok = (inside_v[:, None] & inside_u[None, :] & np.isfinite(corners).all(axis=0) & (span <= span_max)
          & np.isfinite(t))
    fu2, fv2 = fu[None, :], fv[:, None]
    interp = (c00 * (1 - fu2) * (1 - fv2) + c01 * fu2 * (1 - fv2) + c10 * (1 - fu2) * fv2 + c11 * fu2 * fv2)
    out[ok] = interp[ok].astype(np.float32)
    return out
