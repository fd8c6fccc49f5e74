"""Re-timing a fast sweep's pixels between the isochrones (gnomon.reconstruct.retiming)."""

from __future__ import annotations

import numpy as np
import pytest

from gnomon.reconstruct.retiming import retime_between_isochrones


def _fast_sweep(speed_px: float, penumbra_px: float, width: int = 200, rows: int = 6, frames: int = 60,
                angle: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Temporal threshold crossings (as the tracker interpolates them) of an edge moving ``speed_px`` per frame,
    and the true times. The edge is a line tilted by ``angle`` (radians) from the columns."""
    v, u = np.mgrid[0:rows, 0:width].astype(np.float64)
    pos = u + np.tan(angle) * v  # distance along the sweep (px)
    true = (pos - 10.0) / speed_px
    k = np.arange(frames)[:, None, None]
    # 1 lit ahead of the edge, 0 behind it, a linear penumbra between
    level = np.clip((pos[None] - 10.0 - speed_px * k) / penumbra_px + 0.5, 0.0, 1.0)
    below = level < 0.5
    fall = ~below[:-1] & below[1:]
    j = np.argmax(fall, axis=0)
    a = np.take_along_axis(level, j[None], 0)[0]
    b = np.take_along_axis(level, j[None] + 1, 0)[0]
    with np.errstate(invalid="ignore", divide="ignore"):
        times = np.where(fall.any(axis=0), j + (a - 0.5) / (a - b), np.nan)
    return times, np.where(np.isfinite(times), true, np.nan)


def test_a_staircase_becomes_the_edge_timing() -> None:
    # 6 px per frame with a 1.5 px penumbra: most pixels are lit in one frame and dark in the next
    times, true = _fast_sweep(6.0, 1.5)
    inner = np.isfinite(times) & (true > 2) & (true < 28)
    raw = np.abs(times - true)[inner]
    assert raw.max() > 0.3  # the staircase: the tracker's own times err by up to half a frame
    r = retime_between_isochrones(times, 60)
    fixed, done = r.times, r.retimed
    assert done[inner].mean() > 0.8  # all but those exactly on an isochrone (1 in 6 here)
    err = np.abs(fixed - true)[inner]
    # between two isochrones located to the penumbra's precision, a linear edge motion is exact
    assert err.max() < 0.02, err.max()


def test_a_slow_sweep_keeps_its_times_and_a_tilted_edge_works() -> None:
    times, true = _fast_sweep(0.5, 3.0, rows=4, frames=420)  # well sampled: the tracker's times are right
    inner = np.isfinite(times) & (true > 2) & (true < 300)
    fixed = retime_between_isochrones(times, 420).times
    assert np.abs(fixed - true)[inner].max() < 0.05
    times, true = _fast_sweep(5.0, 1.5, rows=40, angle=np.radians(25))  # along the rows still brackets
    inner = np.isfinite(times) & (true > 2) & (true < 30)
    fixed = retime_between_isochrones(times, 60).times
    assert np.abs(fixed - true)[inner].max() < 0.03


def test_breaks_and_reversed_sweeps_are_respected() -> None:
    times, true = _fast_sweep(6.0, 1.5)
    times[:, 100] = np.nan  # a missing time ends the run: its neighbours up to the next crossings keep theirs
    fixed = retime_between_isochrones(times, 60).times
    assert np.isnan(fixed[:, 100]).all()
    # every pixel is either re-timed exactly or keeps the tracker's time (no crossing across the gap)
    inner = np.isfinite(times) & (true > 2) & (true < 28)
    exact = np.abs(fixed - true) < 0.02
    kept = fixed == times.astype(np.float32)
    assert (exact | kept)[inner].all()
    assert exact[inner].mean() > 0.9  # all but the pixels between the gap and the crossings around it
    flipped = retime_between_isochrones(times[:, ::-1].copy(), 60).times[:, ::-1]  # sweep towards −u
    assert np.allclose(flipped, fixed, equal_nan=True, atol=1e-5)
    transposed = retime_between_isochrones(times.T.copy(), 60).times.T  # sweep along the columns
    assert np.allclose(transposed, fixed, equal_nan=True, atol=1e-5)


def test_the_sigma_of_a_retimed_time_follows_its_crossings() -> None:
    """An error on every pixel's time that its row shares (as a steady sweep's pixels share the sampling
    phase) moves the crossings; the propagated σ predicts the re-timed times' error."""
    times, true = _fast_sweep(6.0, 1.5, rows=400)
    rng = np.random.default_rng(5)
    noise = 0.03  # frames, on each pixel's own time: one draw per row
    noisy = times + rng.normal(0.0, noise, (400, 1))
    r = retime_between_isochrones(noisy, 60)
    sigma = r.sigma(np.full(times.shape, noise))
    inner = r.retimed & (true > 2) & (true < 28)
    err = (r.times - true)[inner]
    predicted = float(np.sqrt(np.mean(sigma[inner] ** 2)))
    observed = float(np.sqrt(np.mean(err ** 2)))
    assert predicted / 1.3 <= observed <= predicted * 1.3, (predicted, observed)
    assert predicted < noise  # between crossings a whole pixel apart in time, the error shrinks


def test_only_the_pixels_asked_for_are_retimed() -> None:
    times, true = _fast_sweep(6.0, 1.5)
    where = np.zeros(times.shape, bool)
    where[:, :100] = True
    r = retime_between_isochrones(times, 60, where=where)
    assert not r.retimed[:, 100:].any() and r.retimed[:, 20:90].mean() > 0.8
    assert np.array_equal(r.times[:, 100:], times[:, 100:].astype(np.float32), equal_nan=True)
    flipped = retime_between_isochrones(times[:, ::-1].copy(), 60, where=where[:, ::-1].copy())
    assert np.array_equal(flipped.retimed[:, ::-1], r.retimed)


def _retime_by_loops(m: np.ndarray, n_frames: int, max_gap: float = 40.0, min_gap: float = 3.0,
                     backstep: float = 0.25) -> tuple[np.ndarray, list[tuple]]:
    """The re-timing of a map whose sweep runs along its rows, times rising to the right, written out
    pixel by pixel: runs of pairs that are finite and never go back by more than ``backstep``, each
    run's first crossing of every integer frame, each non-integer pixel time between its run's
    crossings of ⌊t⌋ and ⌊t⌋ + 1. Returns the new map and (pixel, gap, fraction) per re-timed pixel."""
    h, w = m.shape
    out = m.astype(np.float32)
    retimed = []
    for r in range(h):
        run = [0] * w
        first: dict[tuple[int, int], float] = {}
        for j in range(w - 1):
            a, b = m[r, j], m[r, j + 1]
            ok = np.isfinite(a) and np.isfinite(b) and b >= a - backstep
            run[j + 1] = run[j] + (0 if ok else 1)
            if ok and b > a:
                for k in range(int(np.floor(a)) + 1, int(np.floor(b)) + 1):
                    first.setdefault((run[j], min(max(k, -1), n_frames)), j + (k - a) / (b - a))
        for j in range(w):
            t = m[r, j]
            if not np.isfinite(t) or t == np.floor(t):
                continue
            k = int(np.floor(t))
            u0 = first.get((run[j], min(max(k, -1), n_frames)))
            u1 = first.get((run[j], min(max(k + 1, -1), n_frames)))
            if u0 is None or u1 is None:
                continue
            gap = u1 - u0
            frac = (j - u0) / gap if gap != 0 else np.nan
            if min_gap <= gap <= max_gap and 0 <= frac <= 1:
                out[r, j] = np.float32(k + frac)
                retimed.append((r * w + j, gap, frac))
    return out, retimed


def _ragged_sweep(seed: int, h: int = 14, w: int = 90, frames: int = 30) -> np.ndarray:
    """A fast sweep's staircase with noise, holes, backward steps and depth jumps (float32)."""
    rng = np.random.default_rng(seed)
    u = np.arange(w)[None, :] + 3 * np.sin(np.arange(h)[:, None] / 2)
    t = np.floor(u / rng.uniform(4, 9)) + 0.5 + rng.normal(0, 0.08, (h, w))
    t[:, w // 2:] += rng.integers(-3, 4)  # a depth step shifts the staircase
    t[rng.random((h, w)) < 0.04] = np.nan
    t[rng.random((h, w)) < 0.03] -= 1.0  # steps back
    t[2, 10:13] = np.floor(t[2, 10:13])  # some integer times
    return np.clip(t, -0.5, frames + 1.5).astype(np.float32)


def test_kernel_retiming_equals_a_per_pixel_computation_and_the_numpy_definition() -> None:
    from gnomon.reconstruct.retiming import _retime_numpy

    for seed in range(4):
        m = _ragged_sweep(seed)
        fast = retime_between_isochrones(m, 30)
        slow, retimed = _retime_by_loops(m.astype(np.float64), 30)
        assert len(retimed) > 100  # most plateaus are re-timed
        np.testing.assert_array_equal(fast.times, slow)
        np.testing.assert_array_equal(fast.pixel, [p for p, _, _ in retimed])
        np.testing.assert_allclose(fast.gap, [g for _, g, _ in retimed], rtol=1e-12)
        np.testing.assert_allclose(fast.f, [f for _, _, f in retimed], rtol=1e-12, atol=1e-15)
        # every orientation (sweep along columns, right to left) and a mask: as the numpy definition
        where = np.random.default_rng(seed).random(m.shape) < 0.7
        for mm, mask in ((m, None), (m[:, ::-1], None), (m.T, None), (m.T[::-1], where.T[::-1]), (m, where)):
            a = retime_between_isochrones(mm, 30, where=mask)
            b = _retime_numpy(mm, 30, where=mask)
            for name in ("times", "retimed", "pixel", "left", "right", "phase", "rise", "gap", "f"):
                np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_kernel_retiming_with_sigma_equals_the_definition() -> None:
    """retime_with_sigma (one kernel pass) gives retime_between_isochrones' times and RetimedTimes.sigma's σ,
    in every orientation and with a mask."""
    from gnomon.reconstruct.retiming import retime_with_sigma

    for seed in range(3):
        m = _ragged_sweep(seed)
        rng = np.random.default_rng(seed)
        sigma = rng.uniform(0.02, 0.3, m.shape).astype(np.float32)
        where = rng.random(m.shape) < 0.7
        for mm, ss, mask in ((m, sigma, None), (m[:, ::-1], sigma[:, ::-1], None), (m.T, sigma.T, None),
                             (m.T[::-1], sigma.T[::-1], where.T[::-1]), (m, sigma, where)):
            ref = retime_between_isochrones(mm, 30, where=mask)
            times, s = retime_with_sigma(mm, 30, ss, where=mask)
            assert ref.pixel.size > 100 and times.dtype == s.dtype == np.float32
            np.testing.assert_array_equal(times, ref.times)
            # the same f64 arithmetic, rounded to float32 once
            np.testing.assert_allclose(s, ref.sigma(ss), rtol=2e-7, atol=0)
            np.testing.assert_array_equal(s[~ref.retimed], ss[~ref.retimed])


def test_averaging_across_the_sweep_takes_out_each_rows_own_error_and_keeps_depth_edges() -> None:
    """Every row's times carry their own error (one draw per row, as a row's crossings share it): after
    re-timing, the rows ±2 across the sweep averaged in symmetric pairs take the RMS error down by √5
    (five independent rows); 400 rows give ≈ 80 independent five-row means, so the ratio is known to
    ±8 % (1σ) and is asserted within 3σ of 1/√5. Noise-free, the average changes nothing, also where the
    time changes linearly across the rows (a tilted edge), and a depth edge across the rows (the staircase
    two frames later below it) is not averaged over."""
    from gnomon.reconstruct.retiming import average_across_sweep

    times, true = _fast_sweep(6.0, 1.5, rows=400)
    noisy = times + np.random.default_rng(7).normal(0.0, 0.05, (400, 1))
    r = retime_between_isochrones(noisy, 60)
    inner = r.retimed & (true > 2) & (true < 28)
    inner[:2] = inner[-2:] = False  # rows without both neighbours on either side
    averaged = average_across_sweep(r.times, r.retimed, along_rows=True, half=2)
    before = float(np.sqrt(np.mean((r.times - true)[inner] ** 2)))
    after = float(np.sqrt(np.mean((averaged - true)[inner] ** 2)))
    assert abs(after / before - 1 / np.sqrt(5)) <= 3 * 0.08 / np.sqrt(5), (before, after)

    times, true = _fast_sweep(5.0, 1.5, rows=40, angle=np.radians(25))  # times change across the rows too
    r = retime_between_isochrones(times, 60)
    averaged = average_across_sweep(r.times, r.retimed, along_rows=True, half=2)
    inner = r.retimed & (true > 2) & (true < 30)
    inner[:2] = inner[-2:] = False
    assert np.abs(averaged - true)[inner].max() < 0.03
    # along the columns (the map transposed) the same
    assert np.array_equal(average_across_sweep(r.times.T, r.retimed.T, along_rows=False, half=2), averaged.T,
                          equal_nan=True)

    times, true = _fast_sweep(6.0, 1.5, rows=40)
    r = retime_between_isochrones(times, 60)
    stepped, true = r.times.copy(), true.copy()
    stepped[20:] += 2.0  # below row 20 the shadow arrives two frames later (a nearer surface)
    true[20:] += 2.0
    averaged = average_across_sweep(stepped, r.retimed, along_rows=True, half=2)
    inner = r.retimed & (true > 4) & (true < 28)
    assert inner[18:22].any() and np.abs(averaged - true)[inner].max() < 0.02
    kept = ~r.retimed & np.isfinite(times)
    assert np.array_equal(averaged[kept], stepped[kept])


@pytest.mark.parametrize("along_rows", [True, False])
def test_the_kernels_average_across_the_sweep_is_the_numpy_definition(along_rows: bool) -> None:
    """``_kernel.average_across`` against :func:`_average_across_sweep_numpy` bit for bit: re-timed maps with
    noise, NaN holes, pixels not re-timed, pairs on both sides of the bend limit, short maps."""
    from gnomon.reconstruct.retiming import _average_across_sweep_numpy, average_across_sweep

    rng = np.random.default_rng(11)
    for shape, half in [((60, 70), 2), ((5, 3), 2), ((4, 9), 3), ((1, 8), 2), ((33, 1), 1)]:
        base = np.add.outer(np.arange(shape[0]) * 0.2, np.arange(shape[1]) * 0.35)
        times = (base + rng.normal(0.0, 0.3, shape)).astype(np.float32)  # bends of ≈ 0.5 frame: both sides
        times[rng.random(shape) < 0.08] = np.nan
        retimed = rng.random(shape) < 0.8
        fast = average_across_sweep(times, retimed, along_rows, half)
        ref = _average_across_sweep_numpy(times, retimed, along_rows, half)
        assert fast.dtype == ref.dtype == np.float32
        assert np.array_equal(fast.view(np.uint32), ref.view(np.uint32)), shape
        if shape == (60, 70):
            assert not np.array_equal(fast, times, equal_nan=True)  # it did average
