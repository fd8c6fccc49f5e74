"""Re-timing a fast sweep's pixels between the isochrones (gnomon.retiming)."""

from __future__ import annotations

import numpy as np

from gnomon.retiming import retime_between_isochrones


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
