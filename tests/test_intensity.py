"""One intensity representation: frames reach the kernel as their DN, with the capture's
one decoding table; with illumination normalisation each frame comes with its gain, and
``min_contrast`` (DN of the input) is applied by the kernel in every mode."""

from __future__ import annotations

import numpy as np
import pytest

from gnomon import _kernel
from gnomon.capture.tracking import (
    MIN_CONTRAST_SIGMAS,
    ShadowTimes,
    ShadowTracker,
    TrackerSettings,
    contrast_floor,
    decoding_lut,
    linear,
)


def encode(linear_irradiance: np.ndarray, gamma: float, dtype) -> np.ndarray:
    """DN of ``dtype`` whose decoding (``decoding_lut(gamma, dtype)``) is nearest the irradiance."""
    top = np.iinfo(dtype).max
    return np.rint(top * np.clip(linear_irradiance, 0, 1) ** (1 / gamma)).astype(dtype)


def run(frames: np.ndarray, lut: np.ndarray, min_contrast: float, gains=None, max_width: int = 16) -> ShadowTimes:
    """The kernel on (N, H, W) frames: plain, or normalised with one gain per frame."""
    t = _kernel.TemporalTracker(*frames.shape[1:], frames.dtype.name, max_width=max_width, lut=lut,
                                normalise=gains is not None)
    for k, f in enumerate(frames):
        t.update(f, None if gains is None else float(gains[k]))
    return ShadowTimes.from_kernel(t.finish(min_contrast))


def _dip_row(lit_dn: int, contrasts: np.ndarray, n: int = 40) -> np.ndarray:
    """(n, 1, P) uint8 frames: pixel p lit at ``lit_dn`` with a 5-frame dip ``contrasts[p]`` DN deep
    (its edges one frame on a mid-level sample, so the crossings are sub-frame)."""
    p = len(contrasts)
    frames = np.full((n, 1, p), lit_dn, np.uint8)
    start = 12 + np.arange(p) % 7
    for i in range(p):
        k, lo = start[i], lit_dn - contrasts[i]
        frames[k, 0, i] = lit_dn - contrasts[i] // 3
        frames[k + 1:k + 5, 0, i] = lo
        frames[k + 5, 0, i] = lo + (2 * contrasts[i]) // 3
    return frames


@pytest.mark.parametrize("gamma", ["srgb", 2.2])
def test_min_contrast_is_dn_of_the_input_in_both_modes(gamma) -> None:
    """The same frames, plain or normalised with any (constant) gain: the same contrast in DN of
    the frames, so ``min_contrast`` keeps the same pixels. The old design measured the normalised
    contrast in Python, through a second table and a search back into DN."""
    contrasts = np.arange(8, 41)  # DN; the floor below is 20
    frames = _dip_row(170, contrasts)
    lut = decoding_lut(gamma, np.uint8)
    plain = run(frames, lut, 20.0)
    assert np.array_equal(plain.contrast[0], contrasts.astype(np.float32))
    assert np.array_equal(plain.valid[0], contrasts >= 20)
    for gain in (1.0, 0.8, 1.7):  # (the light the frames were taken in, relative to the first frame's)
        norm = run(frames, lut, 20.0, gains=np.full(len(frames), gain))
        # Reported back in the frames' own light: their DN, to the normalised codes' step
        # (1/32768 of the first frame's full scale: ≤ 0.03 DN here).
        np.testing.assert_allclose(norm.imax, plain.imax, atol=0.03)
        np.testing.assert_allclose(norm.imin, plain.imin, atol=0.03)
        np.testing.assert_allclose(norm.contrast, plain.contrast, atol=0.05)
        np.testing.assert_allclose(norm.threshold, plain.threshold, rtol=2e-4)
        # the floor in DN keeps the same pixels (20 DN exactly is on the quantisation's edge)
        away = contrasts != 20
        assert np.array_equal(norm.valid[0][away], plain.valid[0][away]), gain
        ok = plain.valid & norm.valid
        np.testing.assert_allclose(norm.enter[ok], plain.enter[ok], atol=0.01)
        np.testing.assert_allclose(norm.leave[ok], plain.leave[ok], atol=0.01)
        np.testing.assert_allclose(norm.enter_slope[ok], plain.enter_slope[ok], rtol=2e-3)


@pytest.mark.parametrize("normalise", [False, True])
def test_the_contrast_floor_is_applied_by_the_tracker(normalise) -> None:
    """The floor in force is the field log's ``min_contrast`` or MIN_CONTRAST_SIGMAS σ of the image
    noise, whichever is higher, and the tracker applies it (times NaN below it) in both modes."""
    contrasts = np.arange(8, 41)
    frames = _dip_row(170, contrasts)
    noise = 2.05  # DN: a floor of 16.4 DN
    for min_contrast, floor in ((None, 16.4), (10.0, 16.4), (20.5, 20.5), (30.5, 30.5)):
        assert contrast_floor(min_contrast, noise) == pytest.approx(floor)
        assert floor == pytest.approx(max(min_contrast or 0, MIN_CONTRAST_SIGMAS * noise))
        settings = TrackerSettings(gamma="srgb", min_contrast=min_contrast, normalize_illumination=normalise,
                                   max_width=16)
        tracker = ShadowTracker(settings, frames.shape[1:], np.dtype(np.uint8))
        for f in frames:
            assert tracker.update(f)
        times = tracker.finish(noise)
        # (normalised: fractional DN, within 0.05 DN of the plain ones, none near a floor)
        keep = contrasts > floor
        assert np.array_equal(times.valid[0], keep), (min_contrast, normalise)
        assert np.isfinite(times.enter[0][keep]).all() and np.isnan(times.enter[0][~keep]).all()
        assert not times.ambiguous.any()


def test_frames_reach_the_kernel_as_their_dn() -> None:
    """ShadowTracker hands the kernel the frames' own dtype and the capture's table in both modes."""
    for normalise in (False, True):
        settings = TrackerSettings(gamma="srgb", min_contrast=20.0, normalize_illumination=normalise)
        tracker = ShadowTracker(settings, (4, 6), np.dtype(np.uint8))
        assert (tracker._tracker.dtype, tracker._tracker.normalised) == ("uint8", normalise)
        assert np.array_equal(tracker.lut, decoding_lut("srgb", np.uint8))


def _sweep(n: int, p: int, gamma: float, rng: np.random.Generator):
    """A shadow band sweeping a row of ``p`` pixels under a changing light: irradiance (n, p) in the
    first frame's light, the light's gain per frame, and the frames' uint16 DN."""
    albedo = rng.uniform(0.2, 0.5, p)  # (lit × the brightest light < 1: no frame clipped)
    # the shadow's edges move 0.35 px per frame: each pixel's edge falls at a fraction of a frame
    x = np.arange(p)[None, :]
    t = np.arange(n)[:, None]
    enter_at, leave_at = 4 + x / 0.35, 10 + x / 0.35
    inside = np.clip(t - enter_at + 0.5, 0, 1) * np.clip(leave_at - t + 0.5, 0, 1)
    irradiance = albedo * (1.0 - 0.85 * inside)
    gains = 1.0 + 0.35 * np.sin(np.arange(n) / 9.0) + 0.004 * np.arange(n)  # a fast-changing light
    frames = encode(irradiance * gains[:, None], gamma, np.uint16)
    return irradiance, gains, frames


def test_a_gain_per_frame_gives_the_crossings_of_prenormalised_frames() -> None:
    """DN taken in a changing light, with each frame's gain, give the crossings the same scene gives
    in a constant light (pre-normalised frames), to the quantisation; without the gains they do not."""
    gamma = 2.2
    irradiance, gains, frames = _sweep(140, 40, gamma, np.random.default_rng(3))
    lut = decoding_lut(gamma, np.uint16)
    steady = run(encode(irradiance, gamma, np.uint16)[:, None, :], lut, 1000.0)
    norm = run(frames[:, None, :], lut, 1000.0, gains=gains)
    raw = run(frames[:, None, :], lut, 1000.0)
    assert steady.valid.all() and norm.valid.all()
    # 16-bit DN and 1/32768 codes: the crossings agree to a few thousandths of a frame
    np.testing.assert_allclose(norm.enter, steady.enter, atol=0.005)
    np.testing.assert_allclose(norm.leave, steady.leave, atol=0.005)
    assert np.nanmax(np.abs(raw.enter - steady.enter)) > 0.05  # the light's change matters
    # Each dip is reported in its own light: the lit level's irradiance times the gain at the dip.
    centre = 0.5 * (norm.enter + norm.leave)
    light = np.interp(centre, np.arange(len(gains)), gains)
    np.testing.assert_allclose(linear(norm.imax, lut), linear(steady.imax, lut) * light, rtol=2e-3)
    np.testing.assert_allclose(norm.threshold, steady.threshold * light, rtol=2e-3)
    # and min_contrast is DN of the input in that light: a floor between the dips' contrasts keeps
    # exactly the deeper ones
    floor = float(np.median(norm.contrast))
    cut = run(frames[:, None, :], lut, floor, gains=gains)
    assert np.array_equal(cut.valid, norm.contrast >= floor) and 0 < cut.valid.sum() < cut.valid.size
    assert np.isnan(cut.enter[~cut.valid]).all()


def test_the_live_watch_reports_in_finish_units_when_normalised() -> None:
    """The live watch of a normalised tracker: levels in DN of the input and the threshold in the
    light of the dip, as ``finish`` reports them."""
    gamma = 2.2
    irradiance, gains, frames = _sweep(140, 40, gamma, np.random.default_rng(4))
    lut = decoding_lut(gamma, np.uint16)
    t = _kernel.TemporalTracker(1, 40, "uint16", max_width=16, lut=lut, normalise=True)
    t.watch(1000.0, 3)
    index, imax, threshold, enter = [], [], [], []
    for k, f in enumerate(frames):
        t.update(f[None, :], float(gains[k]))
        fin = t.take_finished()
        index += list(fin.index)
        imax += list(fin.imax)
        threshold += list(fin.threshold)
        enter += list(fin.enter)
    final = t.finish(1000.0)
    assert sorted(index) == list(range(40))
    px = np.asarray(index)
    np.testing.assert_allclose(np.asarray(enter), np.asarray(final.enter)[0, px], atol=1e-4)
    np.testing.assert_allclose(np.asarray(threshold), np.asarray(final.threshold)[0, px], rtol=1e-3)
    # the watch's lit level is the brightest sample before the dip, finish's the lower of both sides
    np.testing.assert_allclose(np.asarray(imax), np.asarray(final.imax)[0, px], rtol=0.01)


def test_linear_levels_are_the_tables_interpolation() -> None:
    """tracking.linear looks whole codes up directly: the same float32 values as np.interp over the decoding
    table, bit for bit, for whole codes, fractional levels, NaN (→ code 0) and levels beyond the table."""
    from gnomon.capture.tracking import linear

    rng = np.random.default_rng(2)
    lut = (np.linspace(0.0, 1.0, 256) ** 2.2).astype(np.float32)

    def reference(v: np.ndarray) -> np.ndarray:
        dn = np.nan_to_num(np.asarray(v, dtype=np.float64))
        return np.interp(dn, np.arange(256, dtype=np.float64), lut.astype(np.float64)).astype(np.float32)

    whole = rng.integers(0, 256, (50, 60)).astype(np.float32)
    whole[0, :2] = (0.0, 255.0)
    fractional = whole + rng.uniform(0.0, 1.0, whole.shape).astype(np.float32)
    with_nan = whole.copy()
    with_nan[3, 4] = np.nan
    beyond = whole.copy()
    beyond[5, 5] = 300.0
    below = whole.copy()
    below[6, 6] = -2.0
    for v in (whole, fractional, with_nan, beyond, below, whole.astype(np.float64)):
        out = linear(v, lut)
        assert out.dtype == np.float32
        assert np.array_equal(out.view(np.uint32), reference(v).view(np.uint32))
