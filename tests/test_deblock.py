"""Shadow times of compressed video (constant over the codec's 8×8 blocks) interpolated between block centres."""

from __future__ import annotations

import numpy as np

from gnomon.capture.deblock import block_grid, deblock_times


def _sweep(h: int = 240, w: int = 320) -> tuple[np.ndarray, np.ndarray]:
    """Shadow times (frames) of a plane swept left to right at 5 px/frame, tilted 10°, with a disc (an object,
    radius 30 px) whose times are 6 frames later."""
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    t = (u + np.tan(np.radians(10.0)) * v) / 5.0
    disc = (u - 200.0) ** 2 + (v - 120.0) ** 2 <= 30.0**2
    return np.where(disc, t + 6.0, t), disc


def _coded(truth: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The map a codec makes of ``truth``: each 8×8 block (the grid starting at column 3, row 5) takes its
    mean time, as a strongly compressed block darkens as a whole, plus 0.005 frame of noise."""
    h, w = truth.shape
    blocky = truth.copy()
    for r in range(5, h - 7, 8):
        for c in range(3, w - 7, 8):
            blocky[r:r + 8, c:c + 8] = truth[r:r + 8, c:c + 8].mean()
    return blocky + rng.normal(0.0, 0.005, blocky.shape)


def test_block_constant_times_are_interpolated_between_block_centres() -> None:
    """The map a codec makes of that sweep: each 8×8 block (grid starting at column 3, row 5) takes its mean
    time, as a strongly compressed block darkens as a whole, with 0.005 frame of noise. The grid is found
    (size, phase); on the plane away from the disc and the image's border the times come back to the true
    sweep within 0.03 frame (from a staircase of up to ±0.8 frame: 8 px at 5 px/frame), inside the disc
    likewise, and no pixel is pulled across the disc's 6-frame edge. A smooth map (the sweep itself,
    noisy) has no grid."""
    rng = np.random.default_rng(5)
    truth, disc = _sweep()
    h, w = truth.shape
    blocky = _coded(truth, rng)
    grid = block_grid(blocky)
    assert grid is not None and (grid.size, grid.u0, grid.v0) == (8, 3, 5)
    out = deblock_times(blocky, grid)
    v, u = np.mgrid[0:h, 0:w]
    near_disc = (u - 200.0) ** 2 + (v - 120.0) ** 2 <= 50.0**2
    plane = ~near_disc & (u >= 3 + 8) & (u < w - 16) & (v >= 5 + 8) & (v < h - 16)
    assert np.abs(blocky - truth)[plane].max() > 0.7
    assert np.abs(out - truth)[plane].max() < 0.03
    inner = (u - 200.0) ** 2 + (v - 120.0) ** 2 <= 12.0**2
    assert np.abs(out - truth)[inner].max() < 0.03  # the disc is swept smoothly too
    # No pixel a block away from the disc's 6-frame edge is pulled across it (the blocks straddling the
    # edge are mixed by the codec itself, and are not interpolated from).
    r = np.hypot(u - 200.0, v - 120.0)
    plane_time = truth - np.where(disc, 6.0, 0.0)
    assert (out - plane_time)[r <= 22.0].min() > 5.0 and (out - plane_time)[r >= 38.0].max() < 1.0
    assert block_grid(truth + rng.normal(0.0, 0.02, truth.shape)) is None


def test_the_kernel_interpolates_float32_maps_as_numpy_does_bit_for_bit() -> None:
    """A float32 map (the tracker's) is interpolated by the kernel (``_kernel.deblock_interpolate``): the same
    float32 values as the numpy definition on the same times as float64, holes (no time) and the disc's
    mixed blocks included; and, like it, the sweep comes back within 0.03 frame away from the disc."""
    rng = np.random.default_rng(8)
    truth, _ = _sweep()
    h, w = truth.shape
    blocky = _coded(truth, rng)
    blocky[rng.random(blocky.shape) < 0.002] = np.nan  # pixels without a time
    blocky32 = blocky.astype(np.float32)
    grid = block_grid(blocky32)
    assert grid is not None and (grid.size, grid.u0, grid.v0) == (8, 3, 5)
    kernel = deblock_times(blocky32, grid)
    numpy = deblock_times(blocky32.astype(np.float64), grid)
    assert kernel.dtype == np.float32 and kernel.tobytes() == numpy.tobytes()
    v, u = np.mgrid[0:h, 0:w]
    plane = ((u - 200.0) ** 2 + (v - 120.0) ** 2 > 50.0**2) & (u >= 11) & (u < w - 16) & (v >= 13) & (v < h - 16)
    # a block with a hole does not count (12 % of them), so a pixel has its four blocks with 0.88⁴ ≈ 60 %
    changed = np.isfinite(kernel) & (kernel != blocky32)
    assert 0.5 < changed[plane].mean() < 0.8
    assert np.nanmax(np.abs(kernel - truth)[plane & changed]) < 0.03


def test_block_min_max_are_numpys_whole_axis_reductions() -> None:
    """deblock_times' blocks' least and greatest times (deblock._block_min_max, one walk over the blocks'
    pixel offsets) equal blocks.min/max(axis=(1, 3)) bit for bit, NaN where a block has one, for 8 and 16
    pixel blocks."""
    from gnomon.capture.deblock import _block_min_max

    rng = np.random.default_rng(5)
    for b in (8, 16):
        t = rng.uniform(0.0, 90.0, (9 * b, 13 * b))
        t[rng.random(t.shape) < 0.002] = np.nan
        blocks = t.reshape(9, b, 13, b)
        lo, hi = _block_min_max(blocks)
        with np.errstate(invalid="ignore"):
            assert np.array_equal(lo, blocks.min(axis=(1, 3)), equal_nan=True)
            assert np.array_equal(hi, blocks.max(axis=(1, 3)), equal_nan=True)
        assert 0 < np.isnan(lo).sum() < lo.size
