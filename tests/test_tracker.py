"""The streaming shadow tracker: accuracy on synthetic edges, kernel vs numpy,
decoding LUTs, and input errors."""

from __future__ import annotations

from dataclasses import fields, replace

import numpy as np
import pytest

from gnomon import _kernel
from gnomon.capture.tracking import NumpyTracker, ShadowTimes, decoding_lut, track
from gnomon.errors import (
    FrameError,
    GnomonError,
    KernelArrayError,
    KernelFramesError,
    KernelLutError,
    KernelParameterError,
)

KEYS = tuple(f.name for f in fields(ShadowTimes))

LIT, SHADOW = 200.0, 40.0


def logistic(z):
    return 0.5 * (1 + np.tanh(0.5 * z))


def edge_profiles(n_pixels: int, n_frames: int, rng, *, scale: float = 1.0):
    """Per-pixel shadow occupancy (1 = in shadow), (n_frames, n_pixels), with a
    logistic enter edge at a random fractional time and a leave edge later.

    The plateaus are long enough (≥ 7 scales each side) for the profile to
    reach its lit and shadow levels, so the mid-level is crossed exactly at
    ``enter`` and ``leave``."""
    enter = rng.uniform(8, 14, n_pixels)
    leave = enter + rng.uniform(14, 20, n_pixels)
    t = np.arange(n_frames, dtype=np.float64)[:, None]
    inside = logistic((t - enter) / scale) * logistic((leave - t) / scale)
    return inside, enter, leave


def to_frames(values: np.ndarray, shape, dtype) -> list[np.ndarray]:
    top = np.iinfo(dtype).max
    q = np.clip(np.round(values), 0, top).astype(dtype)
    return [f.reshape(shape) for f in q]


def run_kernel(frames, *, min_contrast=20.0, lut=None, window=4, max_width=32):
    h, w = frames[0].shape
    tracker = _kernel.TemporalTracker(h, w, frames[0].dtype.name, window=window, max_width=max_width, lut=lut)
    for f in frames:
        tracker.update(f)
    return ShadowTimes.from_kernel(tracker.finish(min_contrast))


def rms(a):
    return float(np.sqrt(np.mean(np.square(a))))


def test_sub_frame_accuracy_on_noisy_edges():
    rng = np.random.default_rng(0)
    shape = (100, 200)
    inside, enter, leave = edge_profiles(shape[0] * shape[1], 48, rng)
    values = LIT - (LIT - SHADOW) * inside + rng.normal(0, 1.0, inside.shape)
    times = run_kernel(to_frames(values, shape, np.uint8))
    assert times.valid.all()
    err_enter = times.enter.ravel() - enter
    err_leave = times.leave.ravel() - leave
    assert np.isfinite(err_enter).all() and np.isfinite(err_leave).all()
    assert np.mean(np.abs(err_enter)) <= 0.05 and np.mean(np.abs(err_leave)) <= 0.05
    assert rms(err_enter) <= 0.05, rms(err_enter)
    assert rms(err_leave) <= 0.05, rms(err_leave)
    # Steepest steps of a unit-scale logistic of 160 DN: about 40 DN per frame.
    assert 30 < np.median(times.enter_slope) < 45
    assert 30 < np.median(times.leave_slope) < 45
    assert np.allclose(times.threshold, 120, atol=3)


def test_ramp_has_the_exact_crossings():
    # Frames 0-9: 200; 180 140 100 60; 10 × 40; 70 110 150 190; 10 × 200.
    profile = [200] * 10 + [180, 140, 100, 60] + [40] * 10 + [70, 110, 150, 190] + [200] * 10
    frames = [np.full((2, 3), v, np.uint8) for v in profile]
    for max_width in (8, 16, 32):
        times = run_kernel(frames, max_width=max_width)
        assert np.all(times.enter == 11.5) and np.all(times.leave == 25.25)
        assert np.all(times.threshold == 120) and np.all(times.contrast == 160)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_kernel_and_numpy_tracker_agree(dtype):
    rng = np.random.default_rng(1)
    top = np.iinfo(dtype).max
    shape = (23, 37)
    inside, _, _ = edge_profiles(shape[0] * shape[1], 41, rng, scale=0.7)
    values = top * (0.8 - 0.6 * inside) + rng.normal(0, top / 150, inside.shape)
    frames = to_frames(values, shape, dtype)
    for lut in (None, decoding_lut(2.2, dtype), decoding_lut("srgb", dtype)):
        for window, max_width in ((4, 32), (2, 2), (6, 7)):
            h, w = shape
            kernel = _kernel.TemporalTracker(h, w, np.dtype(dtype).name, window=window, max_width=max_width,
                                             lut=lut)
            reference = NumpyTracker(h, w, np.dtype(dtype).name, window=window, max_width=max_width, lut=lut)
            for f in frames:
                kernel.update(f)
                reference.update(f)
            assert kernel.frames_seen == reference.frames_seen == len(frames)
            got = kernel.finish(top / 10)
            want = reference.finish(top / 10)
            assert isinstance(got, _kernel.ShadowTimes) and got.shape == shape
            for key in KEYS:
                g, w = getattr(got, key), getattr(want, key)
                assert g.shape == shape and g.dtype == w.dtype, key
                if g.dtype == bool:
                    assert np.array_equal(g, w), key
                else:
                    np.testing.assert_allclose(g, w, rtol=0, atol=1e-5, err_msg=key)
                    assert np.array_equal(np.isnan(g), np.isnan(w)), key


def test_finish_is_a_preview():
    rng = np.random.default_rng(2)
    shape = (8, 9)
    inside, _, _ = edge_profiles(72, 40, rng)
    frames = to_frames(LIT - (LIT - SHADOW) * inside + rng.normal(0, 1, inside.shape), shape, np.uint8)
    streaming = _kernel.TemporalTracker(*shape, max_width=7)
    for i, f in enumerate(frames):
        streaming.update(f)
        if i in (3, 17, 30):
            preview = streaming.finish(20.0)
            expect = run_kernel(frames[: i + 1], max_width=7)
            np.testing.assert_array_equal(preview.enter, expect.enter)
            np.testing.assert_array_equal(preview.leave, expect.leave)
    final = ShadowTimes.from_kernel(streaming.finish(20.0))
    np.testing.assert_array_equal(final.enter, run_kernel(frames, max_width=7).enter)


def test_gamma_lut_puts_the_crossing_at_mid_irradiance():
    gamma, lit, shadow = 2.2, 0.8, 0.05  # linear irradiance levels
    rng = np.random.default_rng(3)
    shape = (50, 80)
    inside, enter, leave = edge_profiles(shape[0] * shape[1], 48, rng)
    irradiance = lit - (lit - shadow) * inside
    dn = 255 * irradiance ** (1 / gamma) + rng.normal(0, 0.5, inside.shape)
    frames = to_frames(dn, shape, np.uint8)
    lut = decoding_lut(gamma, np.uint8)

    # Decoded: the threshold is the mid-irradiance, crossed at enter / leave.
    decoded = run_kernel(frames, lut=lut)
    assert rms(decoded.enter.ravel() - enter) <= 0.05
    assert rms(decoded.leave.ravel() - leave) <= 0.05
    np.testing.assert_allclose(
        decoded.threshold, (lut[decoded.imax.astype(int)] + lut[decoded.imin.astype(int)]) / 2, rtol=1e-6
    )

    # Thresholding the encoded values instead: the DN mid-level is a lower
    # irradiance E*, reached at occupancy f = (lit − E*) / (lit − shadow) of the
    # logistic, i.e. logit(f) frames after `enter` and before `leave`.
    dn_mid = 255 * (lit ** (1 / gamma) + shadow ** (1 / gamma)) / 2
    f = (lit - (dn_mid / 255) ** gamma) / (lit - shadow)
    offset = np.log(f / (1 - f))
    assert offset > 0.6
    encoded = run_kernel(frames)
    assert abs(np.mean(encoded.enter.ravel() - enter) - offset) < 0.05
    assert abs(np.mean(encoded.leave.ravel() - leave) + offset) < 0.05


def test_low_contrast_pixels_are_invalid():
    frames = [np.full((2, 2), v, np.uint8) for v in (100, 100, 90, 80, 80, 95, 100)]
    times = run_kernel(frames, min_contrast=21)
    assert not times.valid.any()
    assert np.isnan(times.enter).all() and np.isnan(times.leave).all()
    assert np.isnan(times.enter_slope).all()
    np.testing.assert_array_equal(times.contrast, 20)
    times = run_kernel(frames, min_contrast=20)
    assert times.valid.all() and np.isfinite(times.enter).all()


def test_decoding_lut():
    lin = decoding_lut(1.0, np.uint8)
    assert lin.dtype == np.float32 and lin.shape == (256,)
    np.testing.assert_allclose(lin, np.arange(256) / 255, rtol=1e-6)
    g = decoding_lut(2.2, "uint16")
    assert g.shape == (65536,) and g[0] == 0 and g[-1] == 1
    np.testing.assert_allclose(g[32768], (32768 / 65535) ** 2.2, rtol=1e-6)
    s = decoding_lut("srgb", np.uint8)
    assert s[0] == 0 and s[-1] == pytest.approx(1.0)
    assert s[10] == pytest.approx(10 / 255 / 12.92, rel=1e-6)  # linear toe
    assert s[128] == pytest.approx(((128 / 255 + 0.055) / 1.055) ** 2.4, rel=1e-6)
    assert np.all(np.diff(s) > 0)
    for bad in (0, -1.0, float("nan"), "rec709"):
        with pytest.raises(ValueError):
            decoding_lut(bad, np.uint8)
    with pytest.raises(ValueError):
        decoding_lut(2.2, np.float32)


def test_track_feeds_the_kernel_and_reports_progress():
    rng = np.random.default_rng(4)
    shape = (6, 7)
    inside, _, _ = edge_profiles(42, 40, rng)
    frames = to_frames(LIT - (LIT - SHADOW) * inside, shape, np.uint8)
    seen = []
    times = track(iter(frames), min_contrast=20, gamma=2.2, progress=seen.append)
    assert seen == list(range(len(frames)))
    expect = run_kernel(frames, lut=decoding_lut(2.2, np.uint8))
    np.testing.assert_array_equal(times.enter, expect.enter)
    assert times.shape == shape and times.valid.dtype == bool
    with pytest.raises(FrameError, match="frame 3"):
        track(frames[:3] + [frames[3][:, :5]], min_contrast=20, gamma=1.0)
    with pytest.raises(FrameError):
        track([], min_contrast=20, gamma=1.0)
    with pytest.raises(FrameError):
        track([np.zeros((4, 4), np.float32)], min_contrast=20, gamma=1.0)


@pytest.mark.parametrize("make", [_kernel.TemporalTracker, NumpyTracker])
def test_wrong_frames_raise_gnomon_errors(make):
    """Each kernel error variant is its own GnomonError (and ValueError) subclass."""
    tracker = make(4, 5, "uint8")
    with pytest.raises(KernelArrayError, match="uint8.*uint16"):
        tracker.update(np.zeros((4, 5), np.uint16))
    with pytest.raises(KernelArrayError, match=r"\(4, 5\).*\(5, 4\)"):
        tracker.update(np.zeros((5, 4), np.uint8))
    with pytest.raises(KernelArrayError):
        tracker.update(np.zeros((4, 5, 1), np.uint8))
    assert tracker.frames_seen == 0
    with pytest.raises(KernelFramesError):
        tracker.finish(10.0)  # no frames yet
    with pytest.raises(KernelArrayError, match="256"):
        make(4, 5, "uint8", lut=np.zeros(255, np.float32))
    with pytest.raises(KernelArrayError, match="float32"):
        make(4, 5, "uint8", lut=np.zeros(256, np.float64))
    with pytest.raises(KernelLutError):
        make(4, 5, "uint8", lut=np.linspace(1, 0, 256, dtype=np.float32))  # decreasing
    for cls in (KernelArrayError, KernelFramesError, KernelLutError, KernelParameterError):
        assert issubclass(cls, GnomonError) and issubclass(cls, ValueError)
    assert issubclass(KernelFramesError, FrameError)


def test_kernel_tracker_arguments():
    with pytest.raises(KernelParameterError, match="uint8"):
        _kernel.TemporalTracker(4, 5, "float32")
    with pytest.raises(KernelParameterError, match="window"):
        _kernel.TemporalTracker(4, 5, window=0)
    with pytest.raises(KernelParameterError, match="max_width"):
        _kernel.TemporalTracker(4, 5, max_width=1)
    with pytest.raises(KernelParameterError, match="window"):
        _kernel.TemporalTracker(4, 5, window=9, max_width=8)
    with pytest.raises(KernelParameterError, match="ambiguity"):
        _kernel.TemporalTracker(4, 5, ambiguity=0.0)
    with pytest.raises(KernelParameterError):
        _kernel.TemporalTracker(0, 5)
    t = _kernel.TemporalTracker(4, 5, "uint16", window=3, max_width=8, ambiguity=0.5)
    assert (t.shape, t.dtype, t.window, t.max_width, t.frames_seen) == ((4, 5), "uint16", 3, 8, 0)
    assert t.ambiguity == 0.5 and t.simd_path == _kernel.simd_path()
    with pytest.raises(ValueError, match="uint16"):
        t.update(np.zeros((4, 5), np.uint8))
    # Non-contiguous frames are accepted (copied).
    t.update(np.zeros((5, 4), np.uint16).T)
    assert t.frames_seen == 1
    assert t.finish(1.0).valid.dtype == bool and not t.normalised
    with pytest.raises(ValueError, match="65536"):
        _kernel.TemporalTracker(4, 5, "uint16", lut=decoding_lut(2.2, np.uint8))
    with pytest.raises(KernelParameterError, match="gain"):
        t.update(np.zeros((4, 5), np.uint16), 1.0)  # a plain tracker takes no gain
    n = _kernel.TemporalTracker(4, 5, "uint8", lut=decoding_lut(2.2, np.uint8), normalise=True)
    assert n.normalised and n.dtype == "uint8"
    with pytest.raises(KernelParameterError, match="gain"):
        n.update(np.zeros((4, 5), np.uint8))  # a normalised tracker needs it
    with pytest.raises(KernelParameterError, match="gain"):
        n.update(np.zeros((4, 5), np.uint8), -1.0)
    with pytest.raises(KernelArrayError, match="uint8"):
        n.update(np.zeros((4, 5), np.uint16), 1.0)
    n.update(np.zeros((4, 5), np.uint8), 0.5)
    assert n.frames_seen == 1
    with pytest.raises(KernelParameterError, match="lut"):
        _kernel.TemporalTracker(4, 5, normalise=True)


_PATH_SCRIPT = """
import sys, numpy as np
from gnomon import _kernel
frames = np.load(sys.argv[1])
t = _kernel.TemporalTracker(*frames.shape[1:], "uint8", window=3, max_width=5)
for f in frames:
    t.update(f)
r = t.finish(10.0)
names = ("imax", "imin", "contrast", "threshold", "enter", "leave", "enter_slope", "leave_slope", "rival",
         "valid", "ambiguous", "clipped")
np.savez(sys.argv[2], path=_kernel.simd_path(), **{k: np.asarray(getattr(r, k)) for k in names})
"""


def test_every_simd_path_gives_identical_results(tmp_path):
    """Each instruction set this CPU supports, forced with GNOMON_SIMD in a fresh
    process (the path is chosen once per process), tracks a noisy sweep to the
    same bits as the default path in this process."""
    import os
    import subprocess
    import sys

    paths = _kernel.simd_paths()
    assert _kernel.simd_path() in paths and paths[-1] == "portable"
    rng = np.random.default_rng(5)
    shape = (7, 75)  # a width that is no multiple of any vector's lanes: tails too
    inside, _, _ = edge_profiles(shape[0] * shape[1], 45, rng, scale=0.8)
    frames = np.stack(to_frames(200 - 160 * inside + rng.normal(0, 2, inside.shape), shape, np.uint8))
    np.save(tmp_path / "frames.npy", frames)
    here = run_kernel(list(frames), min_contrast=10.0, window=3, max_width=5)
    for path in paths:
        out = tmp_path / f"{path}.npz"
        env = {**os.environ, "GNOMON_SIMD": path, "PYTHONPATH": os.pathsep.join(sys.path)}
        subprocess.run([sys.executable, "-c", _PATH_SCRIPT, str(tmp_path / "frames.npy"), str(out)],
                       check=True, env=env)
        got = np.load(out)
        assert str(got["path"]) == path
        for key in ("imax", "imin", "threshold", "enter", "leave", "enter_slope", "leave_slope", "rival",
                    "valid", "ambiguous", "clipped"):
            np.testing.assert_array_equal(got[key], getattr(here, key), err_msg=f"{path}: {key}")


def test_version_names_the_simd_path():
    from gnomon.cli import version_text

    text = version_text()
    assert text.startswith("gnomon ") and text.endswith(f"SIMD {_kernel.simd_path()})")


# ---- One dip per pixel: several darkening events ---------------------------


def dips_profile(n_frames: int, dips, *, lit: float = LIT) -> np.ndarray:
    """A lit level with dips ``(enter, leave, level)``: logistic edges of scale
    0.6 frame at fractional times (so the mid-level is crossed at ``enter`` and
    ``leave``), each dip at its own level; overlapping dips take the darker."""
    t = np.arange(n_frames, dtype=np.float64)
    value = np.full(n_frames, lit)
    for enter, leave, level in dips:
        inside = logistic((t - enter) / 0.6) * logistic((leave - t) / 0.6)
        value = np.minimum(value, lit - (lit - level) * inside)
    return value


def track_both(values: np.ndarray, *, min_contrast=20.0, max_width=16, ambiguity=0.6):
    """Kernel and numpy reference on (frames, pixels) values, as one row of pixels;
    they must agree on every output; returns the kernel's ShadowTimes."""
    frames = to_frames(values, (1, values.shape[1]), np.uint8)
    kernel = _kernel.TemporalTracker(1, values.shape[1], max_width=max_width, ambiguity=ambiguity)
    reference = NumpyTracker(1, values.shape[1], max_width=max_width, ambiguity=ambiguity)
    for f in frames:
        kernel.update(f)
        reference.update(f)
    got, want = kernel.finish(min_contrast), reference.finish(min_contrast)
    for key in KEYS:
        np.testing.assert_array_equal(getattr(got, key), getattr(want, key), err_msg=key)
    return ShadowTimes.from_kernel(got)


def test_a_wide_cloud_dip_and_the_shadow_dip():
    """A cloud: a slow dip (raised cosine, 60 frames, 70 DN deep) then the sharp
    shadow; noise σ = 1 DN. Every pixel's times are the shadow's, sub-frame, with
    leave after enter; the cloud is a weak rival, not an ambiguity."""
    rng = np.random.default_rng(11)
    n, pixels = 200, 400
    t = np.arange(n)[:, None]
    cloud = np.where(np.abs(t - 70) < 30, 35 * (1 + np.cos(np.pi * (t - 70) / 30)), 0)
    enter = rng.uniform(130, 140, pixels)
    leave = enter + rng.uniform(5, 12, pixels)
    shadow = np.stack([dips_profile(n, [(e, lv, SHADOW)]) for e, lv in zip(enter, leave, strict=True)], axis=1)
    values = shadow - cloud + rng.normal(0, 1.0, (n, pixels))
    times = track_both(values)
    assert times.valid.all() and not times.ambiguous.any()
    assert np.all(times.leave > times.enter)
    assert rms(times.enter.ravel() - enter) <= 0.05 and rms(times.leave.ravel() - leave) <= 0.05
    assert np.all(times.rival < 0.5 * times.contrast)


def test_cloud_flanks_steeper_than_the_shadow_edges():
    """A short cloud (15 frames at 70 % of the lit level, instant 60 DN flanks) and a
    shadow with soft edges (scale 2 frames, about 30 DN per frame at most): the
    steepest fall and rise of the capture are the cloud's, the deepest dip is the
    shadow's (about 140 DN deep, so the cloud is a rival below the ambiguity)."""
    rng = np.random.default_rng(12)
    n, pixels = 160, 200
    t = np.arange(n)[:, None]
    cloud = np.where((t >= 40) & (t < 55), 0.3 * LIT, 0.0)
    enter = rng.uniform(100, 110, pixels)
    leave = enter + 20  # long enough for the soft edges to reach the shadow level
    inside = logistic((t - enter) / 2.0) * logistic((leave - t) / 2.0)
    values = LIT - (LIT - SHADOW) * inside - cloud + rng.normal(0, 1.0, (n, pixels))
    steepest_fall = np.argmax(-np.diff(values, axis=0), axis=0) + 1
    assert np.mean(steepest_fall == 40) > 0.9  # what the old tracker would have taken
    times = track_both(values, max_width=32)
    assert times.valid.all()
    assert rms(times.enter.ravel() - enter) <= 0.1 and rms(times.leave.ravel() - leave) <= 0.1
    np.testing.assert_allclose(times.rival, 0.3 * LIT, atol=6)


def test_a_second_comparable_sharp_dip_is_ambiguous():
    """The stick seen directly or an interreflection: a second sharp dip 90 % as deep
    makes the pixel ambiguous (no times); at 30 % it is only a rival."""
    rng = np.random.default_rng(13)
    n, pixels = 150, 100
    comparable = np.stack([dips_profile(n, [(30.3, 36.8, SHADOW), (100.5, 104.1, LIT - 0.9 * (LIT - SHADOW))])
                           for _ in range(pixels)], axis=1)
    times = track_both(comparable + rng.normal(0, 1.0, (n, pixels)))
    assert times.ambiguous.all() and not times.valid.any()
    assert np.isnan(times.enter).all() and np.isnan(times.leave).all()
    weak = np.stack([dips_profile(n, [(30.3, 36.8, SHADOW), (100.5, 104.1, LIT - 0.3 * (LIT - SHADOW))])
                     for _ in range(pixels)], axis=1)
    times = track_both(weak + rng.normal(0, 1.0, (n, pixels)))
    assert times.valid.all() and not times.ambiguous.any()
    assert rms(times.enter - 30.3) <= 0.05 and rms(times.leave - 36.8) <= 0.05


def test_a_dip_whose_fall_comes_late_after_a_rise():
    """Dawn (dark, then a rise at frame 10 steeper than any edge after), the
    shadow late in the capture, dusk (a fall that never comes back): enter and
    leave bound the shadow, leave after enter."""
    rng = np.random.default_rng(14)
    n, pixels = 180, 150
    t = np.arange(n)[:, None]
    enter = rng.uniform(120, 130, pixels)
    leave = enter + rng.uniform(4, 9, pixels)
    light = logistic((t - 10) / 0.3) * logistic((165 - t) / 3.0)  # dawn and dusk
    inside = logistic((t - enter) / 0.6) * logistic((leave - t) / 0.6)
    values = 20 + (LIT - 20) * light * (1 - 0.8 * inside) + rng.normal(0, 1.0, (n, pixels))
    times = track_both(values)
    assert times.valid.all() and np.all(times.leave > times.enter)
    assert rms(times.enter.ravel() - enter) <= 0.1 and rms(times.leave.ravel() - leave) <= 0.1


def test_saturated_lit_level_flags_the_pixel():
    rng = np.random.default_rng(15)
    n, pixels = 60, 50
    base = np.stack([dips_profile(n, [(20.4, 27.9, SHADOW)]) for _ in range(pixels)], axis=1)
    times = track_both(base + rng.normal(0, 1.0, (n, pixels)))
    assert not times.clipped.any()
    times = track_both(base + 80 + rng.normal(0, 1.0, (n, pixels)))  # lit at 280 DN: clipped to 255
    assert times.clipped.all()


def test_numpy_tracker_captures_in_chunks(monkeypatch):
    """The numpy reference captures windows a chunk of pixels at a time: the
    result does not depend on the chunk."""
    import gnomon.capture.tracking as tracking

    rng = np.random.default_rng(16)
    n, pixels = 120, 90
    enter = rng.uniform(10, 100, pixels)
    values = np.stack([dips_profile(n, [(e, e + rng.uniform(3, 12), SHADOW)]) for e in enter], axis=1)
    values[:, ::3] = np.stack([dips_profile(n, [(20.5, 27.25, SHADOW), (70.25, 75.5, 60.0)])
                               for _ in range(pixels // 3)], axis=1)
    monkeypatch.setattr(tracking, "_CAPTURE_CHUNK", 7)
    times = track_both(values + rng.normal(0, 1.0, (n, pixels)))
    assert times.ambiguous[0, ::3].all() and times.valid.sum() > pixels // 2


@pytest.mark.parametrize("normalize", [False, True])
def test_the_second_candidate_dip_has_its_own_times(normalize):
    """Two comparable sharp dips (the pole's and a lamp post's): the pixel is ambiguous, but
    ShadowTracker.second_dips keeps both candidates' times (sub-frame, noise σ = 1 DN), the
    second's contrast is the rival's depth in DN of the input (also through the normaliser), and a pixel
    with one dip has no second above the contrast floor. Without ``second_dips`` the kernel keeps
    no second candidates (its best dips and rivals unchanged) and refuses to report them."""
    from gnomon.capture.tracking import ShadowTracker, TrackerSettings

    rng = np.random.default_rng(14)
    n, pixels = 150, 40
    first, second = (30.3, 36.8), (100.5, 107.1)
    two = np.stack([dips_profile(n, [(*first, SHADOW), (*second, LIT - 0.9 * (LIT - SHADOW))])
                    for _ in range(pixels)], axis=1)
    one = np.stack([dips_profile(n, [(*first, SHADOW)]) for _ in range(pixels)], axis=1)
    # (and lit pixels, most of the image, that set the normaliser's gain)
    values = np.concatenate([two, one, np.full((n, 10 * pixels), LIT)], axis=1) + rng.normal(0, 1.0, (n, 12 * pixels))
    frames = to_frames(values, (1, 12 * pixels), np.uint8)
    settings = TrackerSettings(gamma=1.0, min_contrast=20.0, normalize_illumination=normalize, max_width=16,
                               second_dips=True)
    tracker = ShadowTracker(settings, (1, 12 * pixels), np.dtype(np.uint8))
    plain = ShadowTracker(replace(settings, second_dips=False), (1, 12 * pixels), np.dtype(np.uint8))
    for f in frames:
        assert tracker.update(f) and plain.update(f)
    times = tracker.finish()
    dips = tracker.second_dips()
    without = plain.finish()
    for field in fields(times):
        np.testing.assert_array_equal(getattr(without, field.name), getattr(times, field.name), err_msg=field.name)
    with pytest.raises(KernelParameterError, match="second_dips"):
        plain.second_dips()
    both, alone = np.s_[0, :pixels], np.s_[0, pixels:2 * pixels]
    assert times.ambiguous[both].all() and times.valid[alone].all()
    assert rms(dips.best_enter[both] - first[0]) <= 0.05 and rms(dips.best_leave[both] - first[1]) <= 0.05
    assert rms(dips.enter[both] - second[0]) <= 0.05 and rms(dips.leave[both] - second[1]) <= 0.05
    np.testing.assert_allclose(dips.contrast[both], 0.9 * (LIT - SHADOW), atol=4)
    if not normalize:
        np.testing.assert_array_equal(dips.contrast[both], times.rival[both])
    else:  # both in DN of the input, each in its own dip's light (the gains the normaliser measured
        # at the two dips differ by a few tenths of a percent)
        np.testing.assert_allclose(dips.contrast[both], times.rival[both], rtol=0.01)
    np.testing.assert_array_equal(dips.best_enter[alone], times.enter[alone])
    assert np.all(dips.contrast[alone] < 20)  # only the noise's wiggles, below the floor
